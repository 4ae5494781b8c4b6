"""Exact-area rasterisation: area and centroid of filled polygons."""

from __future__ import annotations

import numpy as np
import pytest

from triaxtrack.raster import circle_polygon, paint, polygon_coverage


def _moments(cov):
    ys, xs = np.mgrid[: cov.shape[0], : cov.shape[1]]
    s = cov.sum()
    return s, (cov * xs).sum() / s, (cov * ys).sum() / s


def test_square_area_and_centroid():
    sq = np.array([[10.3, 10.2], [20.3, 10.2], [20.3, 20.2], [10.3, 20.2]])
    s, cx, cy = _moments(polygon_coverage([sq], 40, 40))
    assert s == pytest.approx(100.0, abs=1e-9)  # x exact; y sampled at 16 sub-rows
    assert cx == pytest.approx(15.3, abs=1e-9)
    assert cy == pytest.approx(15.2, abs=1 / 16)


def test_small_disc_centroid_within_0p008_px():
    rng = np.random.default_rng(0)
    errs = []
    for i in range(100):
        c = rng.uniform(8, 24, 2)
        poly = circle_polygon(c, 3.0, 16)
        s, cx, cy = _moments(polygon_coverage([poly if i % 2 else poly[::-1]], 32, 32))
        assert s == pytest.approx(np.pi * 9, rel=1e-3)  # equal-area polygon
        errs.append(np.hypot(cx - c[0], cy - c[1]))
    assert max(errs) < 0.008


def test_adjacent_polygons_tile_without_seams():
    a = np.array([[2.0, 2.0], [7.37, 2.0], [7.37, 9.0], [2.0, 9.0]])
    b = np.array([[7.37, 2.0], [12.0, 2.0], [12.0, 9.0], [7.37, 9.0]])
    cov = polygon_coverage([a, b], 12, 14)
    assert cov[3:8, 3:11].min() == pytest.approx(1.0)
    assert cov.max() <= 1.0


def test_paint_returns_new_image():
    img = np.full((20, 20), 100.0)
    out, cov = paint(img, circle_polygon([10, 10], 4, 16), [16], 0.0)
    assert (img == 100.0).all()
    assert out[10, 10] == pytest.approx(0.0) and cov.sum() == pytest.approx(np.pi * 16, rel=1e-3)


def test_counts_must_match_vertices():
    with pytest.raises(ValueError, match="counts"):
        paint(np.zeros((10, 10)), circle_polygon([5, 5], 2, 16), [12], 1.0)
