"""Strain maps: the local membrane strain on the unrolled membrane, on matplotlib.

The membrane is unrolled and seen from outside: design theta (deg) to the right from the kit's
first column, design z (mm, undeformed, material coordinates) up; the kit's column and row
numbers are on the opposite axes. Each cell of :data:`triaxtrack.tables.STRAINS` (between grid
rows ``row, row + 1`` and columns ``col, col + 1`` of the kit's :class:`MembraneLayout`) is
filled between its corner dots' design coordinates, coloured on a diverging scale symmetric
about zero (blue compression, red tension: these strains are tension positive), in per cent;
grey (hatched) where the cell has no value.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.collections import QuadMesh
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from triaxtrack.report.common import MIN_RANGE, half_range
from triaxtrack.report.layout import MembraneLayout
from triaxtrack.report.style import DIVERGING_CMAP, MISSING, new_figure, no_data, styled

__all__ = ["strain_map_figure", "strain_maps_figure"]

MAP_PX = 250  # width of one unrolled membrane (360 deg), pixels
MAP_MARGIN_PX = {"width": 62, "height": 100}  # axes labels, ticks and title around one map
COLOURBAR_PX = 110
TITLE_PX = 30
TITLE = "local Green-Lagrange strain of the membrane (%), tension positive; unrolled, seen from outside"


def _cell_values(cells: pd.DataFrame, component: str, layout: MembraneLayout) -> np.ndarray:
    """(rows - 1, columns) values of one frame's cells (NaN where absent), row index from the
    bottom (increasing z), column index increasing theta."""
    values = np.full(layout.n_cells, np.nan)
    k = layout.cell_index(cells["row"].to_numpy(), cells["col"].to_numpy())
    inside = k >= 0
    values[k[inside]] = cells[component].to_numpy(float)[inside]
    return values.reshape(layout.rows - 1, layout.columns)[::-1]  # kit row 1 is the top


def _map_height_px(layout: MembraneLayout) -> int:
    """Height of a map MAP_PX wide, true to the membrane's proportions (arc length : height)."""
    span = abs(float(layout.row_z_mm[0] - layout.row_z_mm[-1]))
    return max(int(round(MAP_PX * span / (2 * np.pi * layout.radius_mm))), 40)


def _draw_map(
    ax: Axes,
    cells: pd.DataFrame,
    layout: MembraneLayout,
    component: str,
    vmax: float,
    row_axis: bool,
    column_axis: bool,
) -> QuadMesh:
    """Draw one frame's map of ``component`` (strain; drawn in %) into ``ax``, the colour range
    -vmax..vmax; ``row_axis``/``column_axis``: number the kit's rows (right) / columns (top)."""
    theta = layout.theta_edges_deg()
    z = layout.row_z_mm[::-1]
    ax.patch.set(facecolor=MISSING, hatch="////", edgecolor="0.55")  # seen through cells without a value
    mesh = ax.pcolormesh(
        theta,
        z,
        np.ma.masked_invalid(100 * _cell_values(cells, component, layout)),
        cmap=DIVERGING_CMAP.with_extremes(bad=(0.0, 0.0, 0.0, 0.0)),
        vmin=-100 * vmax,
        vmax=100 * vmax,
        shading="flat",
    )
    ax.set_aspect(360.0 / (2 * np.pi * layout.radius_mm))  # 1 mm of arc as long as 1 mm of height
    ax.set_xlim(theta[0], theta[-1])
    ax.set_ylim(z[0], z[-1])
    ax.set_xticks(theta[0] + np.arange(0.0, 361.0, 90.0))
    ax.grid(False)
    ax.set(xlabel="theta (deg)", ylabel="z (mm, undeformed)")
    time_s = float(cells["time_s"].iloc[0])
    ax.set_title(f"{component}   t = {time_s:.2f} s   (frame {int(cells['frame'].iloc[0])})")
    if column_axis:
        top = ax.secondary_xaxis("top", functions=(layout.column_of_theta, layout.theta_of_column))
        top.xaxis.set_major_locator(MaxNLocator(nbins=4, integer=True))
        top.set_xlabel(f"column (of {layout.columns})", fontsize=8)
    if row_axis:
        right = ax.secondary_yaxis("right", functions=(layout.row_of_z, layout.z_of_row))
        right.yaxis.set_major_locator(MaxNLocator(nbins=5, integer=True))
        right.set_ylabel(f"row (of {layout.rows}; 1 at the top)", fontsize=8)
    return mesh


def _frame_cells(strains: pd.DataFrame, frame: int, component: str) -> pd.DataFrame:
    if component not in strains:
        raise ValueError(f"strains table has no column {component!r}")
    cells = strains[strains["frame"] == frame]
    if cells.empty:
        raise ValueError(f"frame {frame} is not in the strains table")
    return cells


@styled
def strain_map_figure(
    strains: pd.DataFrame,
    layout: MembraneLayout,
    frame: int,
    component: str = "e_zz",
    vmax: float | None = None,
    colorbar: bool = True,
) -> Figure:
    """The unrolled membrane at one frame coloured by ``component`` of ``strains`` (a
    ``tables.STRAINS`` table; %, tension positive) on a diverging scale of -vmax..vmax (strain,
    not %; default: the frame's 99th percentile magnitude), on the grid of ``layout`` (the
    kit's). ``colorbar``: add the scale on the right.
    Raises ValueError if the frame or the component is not in the table."""
    cells = _frame_cells(strains, frame, component)
    vmax = half_range(cells[component].to_numpy(float)) if vmax is None else max(float(vmax), MIN_RANGE)
    width = MAP_PX + MAP_MARGIN_PX["width"] + (COLOURBAR_PX if colorbar else 0)
    fig = new_figure(width, _map_height_px(layout) + MAP_MARGIN_PX["height"], layout="compressed")
    ax = fig.subplots()
    mesh = _draw_map(ax, cells, layout, component, vmax, row_axis=True, column_axis=True)
    if colorbar:
        fig.colorbar(mesh, ax=ax, label=f"{component} (%)", extend="both", shrink=0.9)
    return fig


@styled
def strain_maps_figure(
    strains: pd.DataFrame,
    layout: MembraneLayout,
    frames: Sequence[int],
    components: Sequence[str] = ("e_zz", "e_tt"),
) -> Figure:
    """The unrolled membrane (:func:`strain_map_figure`) for each component (one row each) at
    each of ``frames`` (side by side), one colour range and colour bar per component, shared by
    its row (so the times compare), with a title. ``frames`` missing from the table are left
    out; with none left, a "no strain data" figure."""
    present = set(strains["frame"].unique().tolist())
    frames = [f for f in frames if f in present]
    if not frames:
        fig = new_figure(900, 200)
        ax = fig.subplots()
        ax.set_axis_off()
        fig.suptitle(TITLE)
        no_data(ax, "no strain data")
        return fig
    for comp in components:
        if comp not in strains:
            raise ValueError(f"strains table has no column {comp!r}")
    n = len(frames)
    map_h = _map_height_px(layout) + MAP_MARGIN_PX["height"]
    width = n * (MAP_PX + MAP_MARGIN_PX["width"]) + COLOURBAR_PX
    fig = new_figure(width, len(components) * map_h + TITLE_PX, layout="compressed")
    axes = fig.subplots(len(components), n, squeeze=False)
    for i, comp in enumerate(components):
        shown = strains.loc[strains["frame"].isin(frames), comp].to_numpy(float)
        vmax = half_range(shown)
        for j, frame in enumerate(frames):
            cells = strains[strains["frame"] == frame]
            mesh = _draw_map(axes[i, j], cells, layout, comp, vmax, row_axis=j == n - 1, column_axis=i == 0)
        fig.colorbar(mesh, ax=list(axes[i]), label=f"{comp} (%)", extend="both", shrink=0.9)
    fig.suptitle(TITLE)
    return fig
