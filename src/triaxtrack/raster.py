"""Exact-area polygon rasterisation, used for textures, sheets and simulated images.

Pixels follow OpenCV: pixel ``(i, j)`` (column ``i``, row ``j``) is the unit square centred on
``(i, j)``. :func:`polygon_coverage` returns, for every pixel, the fraction of its area covered by
a set of non-overlapping simple polygons. Coverage is exact along x (analytic span ends) and
sampled along y at ``subrows`` evenly spaced rows per pixel, so a polygon's total coverage equals
its area and its coverage-weighted centroid equals its area centroid to O(1 / subrows^2).

The method is the signed-area accumulation used by font rasterisers: every edge adds its winding
(+1 or -1) to a per-row difference buffer at each sub-row it crosses, with the fractional part
split between the two pixels around the crossing; a cumulative sum along each row then gives
the covered length of every pixel. There is no sorting and no per-polygon Python loop.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

DEFAULT_SUBROWS = 16  # y sampling: centroid error under 0.008 px for 6 px dots


def polygon_coverage(
    polygons: Sequence[np.ndarray],
    height: int,
    width: int,
    subrows: int = DEFAULT_SUBROWS,
) -> np.ndarray:
    """Area coverage of ``polygons`` on a ``height`` x ``width`` pixel grid.

    Parameters
    ----------
    polygons : sequence of (N_k, 2) float arrays
        Vertices in pixel coordinates (x right, y down, OpenCV centres), any orientation.
        Polygons must be simple; overlapping polygons add up and are clipped at 1.
    height, width : int
        Grid size in pixels.
    subrows : int
        Sub-rows sampled per pixel row.

    Returns
    -------
    (height, width) float64 array in [0, 1].
    """
    polys = [np.asarray(p, dtype=np.float64) for p in polygons if len(p) >= 3]
    if not polys:
        return np.zeros((height, width))
    counts = np.array([len(p) for p in polys])
    return packed_polygon_coverage(np.concatenate(polys), counts, height, width, subrows)


def packed_polygon_coverage(
    vertices: np.ndarray,
    counts: np.ndarray | Sequence[int],
    height: int,
    width: int,
    subrows: int = DEFAULT_SUBROWS,
) -> np.ndarray:
    """:func:`polygon_coverage` for polygons packed as (M, 2) ``vertices`` and (P,) ``counts``.

    Polygon k is ``vertices[sum(counts[:k]) : sum(counts[:k + 1])]``; rows with non-finite
    coordinates drop their whole polygon.
    """
    v0 = np.asarray(vertices, np.float64)
    counts = np.asarray(counts, np.int64)
    if len(counts) == 0:
        return np.zeros((height, width))
    if counts.sum() != len(v0):
        raise ValueError(f"polygon counts add up to {counts.sum()}, but there are {len(v0)} vertices")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    nxt = np.arange(len(v0)) + 1
    ends = starts + counts
    nxt[ends - 1] = starts
    v1 = v0[nxt]
    x, y = v0[:, 0], v0[:, 1]
    xn, yn = v1[:, 0], v1[:, 1]
    cross = x * yn - xn * y
    area2 = np.add.reduceat(cross, starts)
    # orientation so that every polygon adds winding +1 inside; NaN polygons get 0
    orient = np.repeat(np.nan_to_num(-np.sign(area2)), counts)

    s = subrows
    with np.errstate(invalid="ignore"):
        ymin = np.nan_to_num(np.minimum(y, yn), nan=-1.0)
        ymax = np.nan_to_num(np.maximum(y, yn), nan=-1.0)
    k_lo = np.clip(np.ceil((ymin + 0.5) * s - 0.5), 0, height * s).astype(np.int64)
    k_hi = np.clip(np.ceil((ymax + 0.5) * s - 0.5), 0, height * s).astype(np.int64)
    n_cross = np.maximum(k_hi - k_lo, 0)
    n_cross[(yn == y) | (orient == 0)] = 0
    edge = np.repeat(np.arange(len(v0)), n_cross)
    if edge.size == 0:
        return np.zeros((height, width))
    offsets = np.arange(edge.size) - np.repeat(np.cumsum(n_cross) - n_cross, n_cross)
    k = k_lo[edge] + offsets
    yk = (k + 0.5) / s - 0.5
    x0, y0, x1, y1 = x[edge], y[edge], xn[edge], yn[edge]
    xc = x0 + (yk - y0) * (x1 - x0) / (y1 - y0)
    w = orient[edge] * np.where(y1 > y0, 1.0, -1.0)
    row = k // s
    j = np.floor(xc + 0.5)
    frac = j + 0.5 - xc
    left = j < -1
    j = np.where(left, -1.0, j)
    frac = np.where(left, 1.0, frac)
    j = np.minimum(j, width).astype(np.int64)
    stride = width + 3
    idx_a = row * stride + (j + 1)
    idx_b = row * stride + np.minimum(j + 2, width + 2)
    acc = np.bincount(idx_a, weights=w * frac, minlength=height * stride)
    acc += np.bincount(idx_b, weights=w * (1.0 - frac), minlength=height * stride)
    cov = np.cumsum(acc.reshape(height, stride), axis=1)[:, 1 : width + 1] / s
    return np.clip(cov, 0.0, 1.0)


def paint(
    image: np.ndarray,
    vertices: np.ndarray,
    counts: np.ndarray | Sequence[int],
    value: float,
    subrows: int = DEFAULT_SUBROWS,
) -> tuple[np.ndarray, np.ndarray]:
    """Paint packed polygons of grey ``value`` over ``image`` with exact area coverage.

    Only the band of rows the polygons touch is rasterised. Returns the new image and the
    (height, width) coverage (zero outside the band).
    """
    out = image.copy()
    r0, band = paint_into(out, vertices, counts, value, subrows)
    cov = np.zeros(image.shape)
    cov[r0 : r0 + len(band)] = band
    return out, cov


def paint_into(
    image: np.ndarray,
    vertices: np.ndarray,
    counts: np.ndarray | Sequence[int],
    value: float,
    subrows: int = DEFAULT_SUBROWS,
) -> tuple[int, np.ndarray]:
    """In-place :func:`paint` for a renderer's own frame buffer.

    Returns ``(r0, band)``: the coverage of rows ``r0 : r0 + len(band)`` (the rows the polygons
    touch); ``image`` is updated there.
    """
    h, w = image.shape
    v = np.asarray(vertices, np.float64)
    fin = v[np.isfinite(v).all(axis=1)]
    if len(fin) == 0:
        return 0, np.zeros((0, w))
    r0 = int(np.clip(np.floor(fin[:, 1].min()) - 1, 0, h))
    r1 = int(np.clip(np.ceil(fin[:, 1].max()) + 2, 0, h))
    if r1 <= r0:
        return 0, np.zeros((0, w))
    band = packed_polygon_coverage(v - [0.0, r0], counts, r1 - r0, w, subrows)
    sub = image[r0:r1]
    sub += band * (value - sub)
    return r0, band


def equal_area_radius(radius: float, n: int) -> float:
    """Circumradius of the regular n-gon whose area equals that of a circle of ``radius``."""
    return radius * np.sqrt(2 * np.pi / (n * np.sin(2 * np.pi / n)))


def circle_polygon(center: np.ndarray, radius: float, n: int = 32) -> np.ndarray:
    """(n, 2) vertices, counter-clockwise, of the regular n-gon with the circle's area."""
    a = 2 * np.pi * np.arange(n) / n
    r = equal_area_radius(radius, n)
    return np.asarray(center, float) + r * np.c_[np.cos(a), np.sin(a)]
