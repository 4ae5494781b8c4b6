"""matplotlib plumbing of the report: figures of a given size in pixels, drawn by the Agg
renderer into an image or a PNG file, never through pyplot (no display, no global figure
registry: a figure is freed as soon as nothing refers to it)."""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, ParamSpec, TypeVar, cast

import matplotlib as mpl
import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import Colormap, ListedColormap, to_hex
from matplotlib.figure import Figure

if TYPE_CHECKING:
    from matplotlib.typing import RcKeyType

__all__ = [
    "DIVERGING_CMAP",
    "DPI",
    "MISSING",
    "PALETTE",
    "figure_image",
    "new_figure",
    "no_data",
    "report_style",
    "save_figure",
    "styled",
]

DPI = 100  # figure sizes are given in pixels; 100 px per inch keeps the fonts' point sizes readable
#: Tableau-10: distinguishable series colours (matplotlib's default cycle)
PALETTE: tuple[str, ...] = tuple(
    to_hex(c) for c in np.asarray(cast(ListedColormap, mpl.colormaps["tab10"]).colors)
)
MISSING = "#c8c8c8"  # cells without a value
#: Signed quantities: blue negative, light grey zero, red positive (Moreland's cool-warm), NaN grey
DIVERGING_CMAP: Colormap = mpl.colormaps["coolwarm"].with_extremes(bad=MISSING)

STYLE: dict[RcKeyType, Any] = {
    "font.size": 9.0,
    "axes.titlesize": 9.5,
    "axes.labelsize": 9.0,
    "axes.grid": True,
    "axes.axisbelow": True,  # the grid under bars too
    "grid.color": "#e1e1e1",
    "grid.linewidth": 0.8,
    "legend.fontsize": 8.0,
    "legend.framealpha": 0.9,
    "xtick.labelsize": 8.0,
    "ytick.labelsize": 8.0,
    "figure.facecolor": "white",
    "savefig.facecolor": "white",
}

P = ParamSpec("P")
R = TypeVar("R")


def report_style() -> contextlib.AbstractContextManager:
    """A context in which figures are built in the report's matplotlib style (:data:`STYLE`);
    the process-wide settings are restored on leaving it."""
    return mpl.rc_context(STYLE)


def styled(draw: Callable[P, R]) -> Callable[P, R]:
    """Decorate a figure function to run under :func:`report_style`."""

    @functools.wraps(draw)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with report_style():
            return draw(*args, **kwargs)

    return wrapper


def new_figure(
    width_px: int, height_px: int, layout: Literal["constrained", "compressed"] | None = "constrained"
) -> Figure:
    """An empty white figure of ``width_px`` x ``height_px`` pixels attached to an Agg canvas
    (not to pyplot). ``layout``: matplotlib's layout engine ("constrained"; "compressed" for
    grids of fixed-aspect axes; None: axes placed by hand)."""
    # Agg truncates the size in pixels to an integer: a quarter pixel more keeps float error
    # in width_px / DPI from losing a row or column
    size = ((width_px + 0.25) / DPI, (height_px + 0.25) / DPI)
    fig = Figure(figsize=size, dpi=DPI, layout=layout)
    FigureCanvasAgg(fig)
    return fig


def figure_image(fig: Figure) -> np.ndarray:
    """The figure drawn by Agg: a new (H, W, 3) uint8 BGR image (OpenCV's channel order, so
    ``cv2.imwrite`` writes it), H, W the figure's size in pixels."""
    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba())
    return np.ascontiguousarray(rgba[..., 2::-1])


def save_figure(fig: Figure, path: str | Path) -> None:
    """Write the figure as a PNG file at ``path`` (its size in pixels as drawn); OSError
    naming the file when it cannot be written."""
    if not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)
    try:
        fig.savefig(path, dpi=fig.dpi, format="png")
    except OSError as err:
        raise OSError(f"cannot write {path}: {err}") from err


def no_data(ax: Axes, message: str = "no data") -> None:
    """Write ``message`` in the middle of an empty panel."""
    ax.text(0.5, 0.5, message, transform=ax.transAxes, ha="center", va="center", color="0.3")
