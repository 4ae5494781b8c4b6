"""Pictures for a person to check, drawn with matplotlib (Agg, never pyplot).

:func:`draw_reconstruction` is the paper's Figs. 5 and 6 in one image: the cameras around the
cell, the cell-wall and specimen points, and the traced rays of one membrane dot, seen from
above (left), from the side (middle) and from above again, close up on the cell, where the rays
bend at the two walls (right). Orthographic views of the cell frame, millimetres, equal scales
on both axes of a view.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.collections import PathCollection
from matplotlib.patches import Circle

from triaxtrack.optics import Camera, CellOptics, pixels_to_normalized, trace_into_water

PANEL_PX = 720  # each view is about PANEL_PX x PANEL_PX
TITLE_PX = 40
MARGIN_MM = 40.0
AXIS_ARROW_MM = 40.0  # the drawn length of a camera's optical axis
CELL = "#5aa0c8"
CELL_TARGETS = "#969696"
CAMERA = "#dc2828"
RAY = "#ff9f00"
HEIGHTS_CMAP = "viridis"  # the specimen's points by height


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


def _draw_view(
    ax: Axes,
    cols: list[int],
    cameras: dict[str, Camera],
    xyz: np.ndarray,
    is_cell: np.ndarray,
    cell: CellOptics,
    rays: list[np.ndarray],
    point_mm: np.ndarray | None,
    z_range: tuple[float, float],
) -> PathCollection:
    """One orthographic view of the cell frame's axes ``cols`` ([0, 1] from above, [0, 2] from
    the side) into ``ax``: walls, cell-wall targets, specimen points by height, cameras, rays."""
    top = cols == [0, 1]
    for r in (cell.outer_radius, cell.inner_radius):
        if top:
            ax.add_patch(Circle((0.0, 0.0), r, fill=False, color=CELL, lw=1.0))
        else:
            for x in (-r, r):
                ax.plot([x, x], [cell.z_min, cell.z_max], color=CELL, lw=1.0)
    wall, inside = xyz[is_cell][:, cols], xyz[~is_cell][:, cols]
    ax.scatter(wall[:, 0], wall[:, 1], s=2, color=CELL_TARGETS, label="cell-wall targets")
    dots = ax.scatter(inside[:, 0], inside[:, 1], s=2, c=xyz[~is_cell, 2], cmap=HEIGHTS_CMAP,
                      vmin=z_range[0], vmax=z_range[1], label="specimen and pedestal targets")  # fmt: skip
    for k, cam in enumerate(cameras.values()):
        tip = cam.center + AXIS_ARROW_MM * cam.R[2]  # the optical axis
        a, b = tuple(cam.center[cols]), tuple(tip[cols])
        ax.annotate("", xy=b, xytext=a, arrowprops={"arrowstyle": "->", "color": CAMERA, "lw": 1.5})
        ax.plot(*a, "o", color=CAMERA, ms=3, label="cameras (optical axis)" if k == 0 else None)
        ax.annotate(cam.name, a, xytext=(4, 4), textcoords="offset points", fontsize=7)
    if point_mm is not None:
        for k, path in enumerate(rays):
            poly = np.vstack([path, np.asarray(point_mm, float)])
            ax.plot(*poly[:, cols].T, color=RAY, lw=0.8, label="traced rays" if k == 0 else None)
    ax.set_aspect("equal")
    ax.set(xlabel="x (mm)", ylabel="y (mm)" if top else "z (mm)")
    return dots


def draw_reconstruction(
    cameras: dict[str, Camera],
    points: pd.DataFrame,
    cell: CellOptics,
    rays: list[np.ndarray],
    point_mm: np.ndarray | None,
    title: str = "",
) -> np.ndarray:
    """A BGR image (matplotlib): top view (x, y), side view (x, z) and a close top view of the
    cell, in mm.

    ``points``: ``id, x_mm, y_mm, z_mm`` (cell-wall targets grey, the others coloured by
    height); ``rays``: from :func:`traced_rays`, each drawn on to ``point_mm``.
    """
    from triaxtrack.report.style import figure_image, new_figure, report_style

    centres = np.array([c.center for c in cameras.values()]).reshape(-1, 3)
    xyz = points[["x_mm", "y_mm", "z_mm"]].to_numpy(float)
    reach = max(np.abs(centres[:, :2]).max(initial=0), cell.outer_radius) + MARGIN_MM
    zlo = min(xyz[:, 2].min(initial=0), centres[:, 2].min(initial=0)) - MARGIN_MM
    near = cell.outer_radius + MARGIN_MM / 4
    is_cell = np.hypot(xyz[:, 0], xyz[:, 1]) > (cell.inner_radius + cell.outer_radius) / 2
    zin = xyz[~is_cell, 2]
    z_range = (float(zin.min(initial=0)), float(zin.max(initial=1)))
    panels = [
        ("top view (x right, y up)", [0, 1], (-reach, reach), (-reach, reach)),
        ("side view (x right, z up)", [0, 2], (-reach, reach), (zlo, zlo + 2 * reach)),
        ("the cell from above: rays refract at both walls", [0, 1], (-near, near), (-near, near)),
    ]
    with report_style():
        fig = new_figure(3 * PANEL_PX, PANEL_PX + TITLE_PX)
        axes = fig.subplots(1, 3)
        for ax, (label, cols, xlim, ylim) in zip(axes, panels, strict=True):
            dots = _draw_view(ax, cols, cameras, xyz, is_cell, cell, rays, point_mm, z_range)
            ax.set(title=label, xlim=xlim, ylim=ylim)
        axes[0].legend(loc="lower left", markerscale=3)
        fig.colorbar(dots, ax=list(axes), label="z of the specimen's targets (mm)", shrink=0.8)
        if title:
            fig.suptitle(title)
    return figure_image(fig)


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
