"""Horizontal sections of the measured soil surface (mm^2): the area at mid-height and the
smallest section, per frame (:func:`section_areas`)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from triaxtrack.kit_design import KitDesign
from triaxtrack.volume.grid import MAX_MISSING_SHARE, MembraneGrid
from triaxtrack.volume.mesh import closed_mesh, membrane_thickness
from triaxtrack.volume.series import FAILURES, frame_grid

SECTION_MARGIN = 0.1  # share of the height left out at each end when looking for the smallest
# section: the pedestals restrain the ends, so the lab's "smallest section" (a neck, a shear
# band) is sought away from them
SECTION_LEVELS = 41  # heights sampled between the margins for the smallest section
SECTION_REFINE = 4  # columns of the smooth surface per membrane column (a 256-gon per section)


def section_heights(
    z_bottom: float, z_top: float, levels: int = SECTION_LEVELS, margin: float = SECTION_MARGIN
) -> np.ndarray:
    """(levels,) heights (mm) evenly between ``margin`` of the height above the bottom and below
    the top."""
    h = z_top - z_bottom
    return z_bottom + h * np.linspace(margin, 1 - margin, levels)


def polygon_area(xy: np.ndarray) -> float:
    """Area (mm^2) of a closed polygon (N, 2) (shoelace; either orientation)."""
    x, y = xy[:, 0], xy[:, 1]
    return float(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def ring_sections(rings: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Areas (mm^2) of the horizontal sections at heights ``z`` (mm) of a surface given as rings
    (Nz, Nc, 3) (bottom up; each column's height increasing), by linear interpolation along each
    column; NaN where a column does not reach the height. A polygon inscribed in a smooth, nearly
    circular section at n even angles is short of its area by the factor ``sin(h) / h``,
    ``h = 2 pi / n`` (exact for a circle; 1e-4 for n = 256): the areas are divided by it."""
    z = np.asarray(z, float)
    n_z, n_c, _ = rings.shape
    xy = np.empty((len(z), n_c, 2))
    reach = np.ones(len(z), bool)
    for j in range(n_c):
        col = rings[:, j]
        k = np.clip(np.searchsorted(col[:, 2], z) - 1, 0, n_z - 2)
        w = (z - col[k, 2]) / (col[k + 1, 2] - col[k, 2])
        xy[:, j] = col[k, :2] + w[:, None] * (col[k + 1, :2] - col[k, :2])
        reach &= (col[0, 2] <= z) & (z <= col[-1, 2])
    x, y = xy[..., 0], xy[..., 1]
    area = 0.5 * np.abs(np.sum(x * np.roll(y, -1, axis=1) - y * np.roll(x, -1, axis=1), axis=1))
    h = 2 * np.pi / n_c
    return np.where(reach, area * h / np.sin(h), np.nan)


def soil_rings(
    grid: MembraneGrid, cap, thickness_mm: float | np.ndarray, refine: int = SECTION_REFINE
) -> np.ndarray:
    """(Nz, Nc, 3) rings of the soil surface (the membrane's inner surface) between the faces."""
    vertices, _ = closed_mesh(grid, cap, refine, thickness_mm, inner=True)
    n_c = len(grid.theta) * refine
    return vertices[:-2].reshape(-1, n_c, 3)


def section_areas(
    points: pd.DataFrame,
    table: pd.DataFrame,
    design: KitDesign,
    reference_frame: int,
    t0: float | None = None,
    thickness_model: str = "area",
    margin: float = SECTION_MARGIN,
    levels: int = SECTION_LEVELS,
    max_missing_share: float = MAX_MISSING_SHARE,
) -> pd.DataFrame:
    """Per frame of ``points`` (points.parquet's columns): ``area_mid_mm2`` the horizontal soil
    section at half the top face centre's height and ``area_min_mm2`` the smallest of ``levels``
    sections between ``margin`` of the height from each face, with ``z_min_mm`` its height; the
    membrane's thinning is relative to ``reference_frame`` (volume.parquet's). A frame that
    fails has NaN and its ``section_reason``. Never raises for a frame's data."""
    if t0 is None:
        t0 = float(design.specimen.membrane_thickness)
    rows = []
    grid0 = None
    try:
        grid0 = frame_grid(points[points["frame"] == reference_frame], table, design, t0, max_missing_share)[
            0
        ]
    except FAILURES:
        grid0 = None
    for frame, pf in points.groupby("frame", sort=True):
        row = {"frame": int(frame), "area_mid_mm2": np.nan, "area_min_mm2": np.nan, "z_min_mm": np.nan,
               "section_reason": ""}  # fmt: skip
        if grid0 is None:
            rows.append(row | {"section_reason": f"reference frame {reference_frame} failed"})
            continue
        try:
            grid, cap, _ = frame_grid(pf, table, design, t0, max_missing_share)
            thickness = membrane_thickness(grid, grid0, t0, model=thickness_model)
            rings = soil_rings(grid, cap, thickness)
        except FAILURES as err:
            rows.append(row | {"section_reason": str(err)})
            continue
        h = float(cap.height_mm)
        z = section_heights(0.0, h, levels, margin)
        areas = ring_sections(rings, np.r_[h / 2, z])
        k = int(np.nanargmin(areas[1:])) if np.isfinite(areas[1:]).any() else -1
        rows.append(row | {
            "area_mid_mm2": areas[0],
            "area_min_mm2": areas[1 + k] if k >= 0 else np.nan,
            "z_min_mm": z[k] if k >= 0 else np.nan,
        })  # fmt: skip
    return pd.DataFrame(rows)
