"""Pictures for a person to check, drawn with OpenCV (no plotting library is a dependency).

:func:`draw_reconstruction` is the paper's Figs. 5 and 6 in one image: the cameras around the
cell, the cell-wall and specimen points, and the traced rays of one membrane dot, seen from
above (left), from the side (middle) and from above again, close up on the cell, where the rays
bend at the two walls (right). Orthographic views of the cell frame, millimetres.
"""

from __future__ import annotations

import cv2
import numpy as np
import pandas as pd

from triaxtrack.optics import Camera, CellOptics, pixels_to_normalized, trace_into_water

PANEL_PX = 720  # each view is PANEL_PX x PANEL_PX
MARGIN_MM = 40.0
WHITE = (255, 255, 255)
GREY = (150, 150, 150)
CELL = (200, 160, 90)  # BGR
CAMERA = (40, 40, 220)
RAY = (0, 170, 255)
TEXT = (30, 30, 30)


class _View:
    """Maps two cell-frame coordinates (mm) to pixels of one panel (y of the image downwards)."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray):
        self.scale = (PANEL_PX - 40) / float(np.max(hi - lo))
        self.lo = lo

    def __call__(self, ab: np.ndarray) -> np.ndarray:
        ab = np.atleast_2d(ab)
        x = 20 + (ab[:, 0] - self.lo[0]) * self.scale
        y = PANEL_PX - 20 - (ab[:, 1] - self.lo[1]) * self.scale
        return np.c_[x, y].round().astype(np.int32)


def _pt(p: np.ndarray) -> tuple[int, int]:
    return int(p[0]), int(p[1])


def _z_colour(z: np.ndarray, z0: float, z1: float) -> np.ndarray:
    """BGR colours of heights: blue at z0 to red at z1."""
    f = np.clip((z - z0) / max(z1 - z0, 1e-9), 0, 1)
    return np.c_[255 * (1 - f), 60 + 80 * np.sin(np.pi * f), 255 * f].astype(int)


def traced_rays(
    cameras: dict[str, Camera], observations: pd.DataFrame, point_id: int, cell: CellOptics
) -> list[np.ndarray]:
    """The refracted paths of one target's observations: per camera a (3, 3) polyline (camera
    centre, outer-wall and inner-wall crossings; the water leg ends at the point).
    ``observations``: rows ``camera, id, u_px, v_px`` (the used ones)."""
    obs = observations[observations["id"] == point_id]
    paths = []
    for row in obs.itertuples(index=False):
        cam = cameras[row.camera]
        xy = pixels_to_normalized(cam, np.array([[row.u_px, row.v_px]]))
        p = trace_into_water(cam, xy, cell)
        paths.append(np.vstack([cam.center, p.outer_hit[0], p.inner_hit[0]]))
    return paths


def draw_reconstruction(
    cameras: dict[str, Camera],
    points: pd.DataFrame,
    cell: CellOptics,
    rays: list[np.ndarray],
    point_mm: np.ndarray | None,
    title: str = "",
) -> np.ndarray:
    """A BGR image: top view (x, y), side view (x, z) and a close top view of the cell.

    ``points``: ``id, x_mm, y_mm, z_mm`` (cell-wall targets grey, the others coloured by
    height); ``rays``: from :func:`traced_rays`, each drawn on to ``point_mm``.
    """
    centres = np.array([c.center for c in cameras.values()]).reshape(-1, 3)
    xyz = points[["x_mm", "y_mm", "z_mm"]].to_numpy(float)
    reach = max(np.abs(centres[:, :2]).max(initial=0), cell.outer_radius) + MARGIN_MM
    zlo = min(xyz[:, 2].min(initial=0), centres[:, 2].min(initial=0)) - MARGIN_MM
    near = cell.outer_radius + MARGIN_MM / 4
    wide = _View(np.array([-reach, -reach]), np.array([reach, reach]))
    side = _View(np.array([-reach, zlo]), np.array([reach, zlo + 2 * reach]))
    close = _View(np.array([-near, -near]), np.array([near, near]))
    panels = [
        ("top view (x right, y up)", wide, [0, 1]),
        ("side view (x right, z up)", side, [0, 2]),
        ("the cell from above: rays refract at both walls", close, [0, 1]),
    ]
    is_cell = np.hypot(xyz[:, 0], xyz[:, 1]) > (cell.inner_radius + cell.outer_radius) / 2
    zin = xyz[~is_cell, 2]
    colours = _z_colour(zin, zin.min(initial=0), zin.max(initial=1))
    images = []
    for label, view, cols in panels:
        img = np.full((PANEL_PX, PANEL_PX, 3), 255, np.uint8)
        for r in (cell.outer_radius, cell.inner_radius):
            if cols == [0, 1]:
                cv2.circle(img, _pt(view(np.zeros(2))[0]), int(round(r * view.scale)), CELL, 1, cv2.LINE_AA)
            else:
                for x in (-r, r):
                    a, b = view(np.array([[x, cell.z_min], [x, cell.z_max]]))
                    cv2.line(img, _pt(a), _pt(b), CELL, 1, cv2.LINE_AA)
        for p in view(xyz[is_cell][:, cols]):
            cv2.circle(img, _pt(p), 1, GREY, -1)
        for p, c in zip(view(xyz[~is_cell][:, cols]), colours, strict=True):
            cv2.circle(img, _pt(p), 1, tuple(int(v) for v in c), -1)
        for cam in cameras.values():
            tip = cam.center + 40.0 * cam.R[2]  # the optical axis, 40 mm
            a, b = view(np.array([cam.center[cols], tip[cols]]))
            cv2.arrowedLine(img, _pt(a), _pt(b), CAMERA, 2, cv2.LINE_AA)
            cv2.putText(img, cam.name, _pt(a + 6), cv2.FONT_HERSHEY_SIMPLEX, 0.35, TEXT, 1)
        if point_mm is not None:
            for path in rays:
                poly = np.vstack([path, np.asarray(point_mm, float)])
                cv2.polylines(img, [view(poly[:, cols])], False, RAY, 1, cv2.LINE_AA)
        cv2.putText(img, label, (10, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, TEXT, 1)
        cv2.line(img, (PANEL_PX - 1, 0), (PANEL_PX - 1, PANEL_PX), GREY, 1)
        images.append(img)
    out = np.hstack(images)
    if title:
        cv2.putText(out, title, (10, PANEL_PX - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.45, TEXT, 1)
    return out


def reconstruction_picture(
    cameras: dict[str, Camera],
    points: pd.DataFrame,
    cell: CellOptics,
    observations: pd.DataFrame,
    candidates: np.ndarray,
    mean_reprojection_px: float,
) -> np.ndarray:
    """:func:`draw_reconstruction` with the traced rays of the candidate (e.g. membrane dot) seen
    by the most cameras, the one nearest mid-height among them. ``observations``: the used
    observations in the water, rows ``camera, id, u_px, v_px``."""
    pool = points[points["id"].isin(candidates)]
    if pool.empty:
        return draw_reconstruction(
            cameras, points, cell, [], None, f"{len(cameras)} cameras, {len(points)} targets"
        )
    pool = pool.assign(dz=(pool["z_mm"] - pool["z_mm"].median()).abs())
    best = pool.sort_values(["n_rays", "dz"], ascending=[False, True]).iloc[0]
    rays = traced_rays(cameras, observations, int(best["id"]), cell)
    title = (
        f"{len(cameras)} cameras, {len(points)} targets; dot {int(best['id'])}: "
        f"{int(best['n_rays'])} rays; mean reprojection {mean_reprojection_px:.3f} px"
    )
    return draw_reconstruction(
        cameras, points, cell, rays, best[["x_mm", "y_mm", "z_mm"]].to_numpy(float), title
    )
