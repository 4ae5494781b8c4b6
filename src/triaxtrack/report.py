"""Figures and a movie for the workflow's HTML report, drawn with OpenCV (no plotting library).

Every figure function takes tables (or ``quality.json`` as a dict) and returns a new BGR uint8
image of shape (H, W, 3); nothing here reads or writes files except :func:`write_movie` and
:func:`write_movie_page`, which write the one file they are given.

* :func:`volume_strain_plot`: volume change and the specimen strains against time.
* :func:`strain_map`, :func:`strain_maps`: local membrane strain on the unrolled membrane.
* :func:`reprojection_plot`: mean reprojection error per camera (and per frame if given).
* :func:`tracking_plot`: share of targets reported per frame, losses by reason, per camera.
* :func:`specimen_frames`, :func:`write_movie`, :func:`write_movie_page`: the deforming
  specimen seen from the side, as an H.264 MP4 and as a self-contained HTML player.
* :func:`chosen_frames`: a few frames spread over the test.

Conventions: strains of ``volume`` are compression positive, those of ``strains`` (local
Green-Lagrange) tension positive, as in :mod:`triaxtrack.tables`; both are drawn in per cent.
Colour scales of signed quantities are diverging and symmetric about zero: blue negative, red
positive. OpenCV's Hershey fonts are ASCII only, hence "mm^3", "deg", "e_zz".
"""

from __future__ import annotations

import base64
import html
import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import av
import cv2
import numpy as np
import pandas as pd

from triaxtrack.video import CODECS, ENCODER_THREADS

__all__ = [
    "Series",
    "chosen_frames",
    "line_chart",
    "bar_chart",
    "reprojection_plot",
    "specimen_frames",
    "strain_map",
    "strain_maps",
    "tracking_plot",
    "volume_strain_plot",
    "write_movie",
    "write_movie_page",
]

BGR = tuple[int, int, int]

WHITE: BGR = (255, 255, 255)
BLACK: BGR = (0, 0, 0)
TEXT: BGR = (30, 30, 30)
GRID: BGR = (225, 225, 225)
AXIS: BGR = (90, 90, 90)
MISSING: BGR = (200, 200, 200)  # cells or bars without data
FONT = cv2.FONT_HERSHEY_SIMPLEX
SMALL = 0.4  # font scale of tick labels and legends
LABEL = 0.45  # font scale of axis labels
TITLE = 0.5  # font scale of panel titles

# Tableau-10, BGR: distinguishable series colours
PALETTE: tuple[BGR, ...] = (
    (180, 119, 31),
    (14, 127, 255),
    (44, 160, 44),
    (40, 39, 214),
    (189, 103, 148),
    (75, 86, 140),
    (194, 119, 227),
    (127, 127, 127),
    (34, 189, 188),
    (207, 190, 23),
)

#: Why a target is not reported in a frame (``tables.TRACKS``, ``triaxtrack.track``), in the
#: order drawn; any other reason is drawn after them in OTHER_REASON.
LOSS_REASONS = ("lost", "edge", "merged", "jump", "shape", "ambiguous", "drift", "disagrees", "not_recorded")
REASON_COLOURS: dict[str, BGR] = {
    "lost": PALETTE[3],  # red
    "edge": PALETTE[1],  # orange
    "merged": PALETTE[4],  # purple
    "jump": PALETTE[5],  # brown
    "shape": PALETTE[6],  # pink
    "ambiguous": PALETTE[8],  # olive
    "drift": PALETTE[9],  # cyan
    "disagrees": (128, 0, 0),  # navy
    "not_recorded": PALETTE[7],  # grey: the camera has no image, not a tracking failure
}
REPORTED: BGR = PALETTE[2]  # green
OTHER_REASON: BGR = (60, 60, 60)

# The membrane grid of the kit (test-folder.md, Table 1): dot (r, c) has ID (r-1)*64 + c + 1000.
MEMBRANE_ROWS = 60
MEMBRANE_COLS = 64
MEMBRANE_FIRST_ID = 1001
MEMBRANE_LAST_ID = MEMBRANE_FIRST_ID + MEMBRANE_ROWS * MEMBRANE_COLS - 1
SPECIMEN_RADIUS_MM = 35.5  # 71 mm specimen: only sets the aspect ratio of the unrolled map

# Colour ranges ignore the most extreme 1 % of values, so that one bad dot does not wash out a
# map; values beyond the range are drawn in the end colour (the colour bar says the range).
RANGE_PERCENTILE = 99.0
MIN_RANGE = 1e-9  # the half range of an all-zero quantity (the reference frame)


# --------------------------------------------------------------------------- colours


def _diverging_lut() -> np.ndarray:
    """A (256, 1, 3) uint8 BGR look-up table, blue - light grey - red (Moreland's cool-warm)."""
    anchors_rgb = np.array(
        [[59, 76, 192], [141, 176, 254], [221, 221, 221], [244, 154, 123], [180, 4, 38]], float
    )
    at = np.linspace(0, 255, len(anchors_rgb))
    ramp = np.column_stack([np.interp(np.arange(256), at, anchors_rgb[:, k]) for k in (2, 1, 0)])
    return ramp.round().astype(np.uint8).reshape(256, 1, 3)


DIVERGING = _diverging_lut()


def _colours(values: np.ndarray, vmax: float) -> np.ndarray:
    """(N, 3) uint8 BGR colours of signed values on the diverging scale -vmax..vmax; NaN grey."""
    v = np.asarray(values, float)
    idx = np.clip(np.round((np.nan_to_num(v) / vmax + 1) * 127.5), 0, 255).astype(np.intp)
    out = DIVERGING[idx, 0].copy()
    out[~np.isfinite(v)] = MISSING
    return out


def _half_range(values: np.ndarray) -> float:
    """The symmetric colour range of signed values: a high percentile of their magnitude."""
    v = np.abs(np.asarray(values, float))
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 1.0
    return max(float(np.percentile(v, RANGE_PERCENTILE)), MIN_RANGE)


# --------------------------------------------------------------------------- text and ticks


def _text(
    img: np.ndarray,
    text: str,
    org: tuple[float, float],
    scale: float = SMALL,
    colour: BGR = TEXT,
    align: str = "left",
    thickness: int = 1,
) -> None:
    """Draw ``text`` with its baseline at ``org[1]``; ``align`` left / centre / right of org[0]."""
    (w, _), _ = cv2.getTextSize(text, FONT, scale, thickness)
    x = org[0] - {"left": 0, "centre": w / 2, "right": w}[align]
    cv2.putText(img, text, (int(round(x)), int(round(org[1]))), FONT, scale, colour, thickness, cv2.LINE_AA)


def _vertical_text(img: np.ndarray, text: str, centre: tuple[float, float], scale: float = LABEL) -> None:
    """Draw ``text`` rotated 90 deg anticlockwise (read bottom to top), centred at ``centre``."""
    (w, h), base = cv2.getTextSize(text, FONT, scale, 1)
    tile = np.full((h + base + 4, w + 4, 3), 255, np.uint8)
    cv2.putText(tile, text, (2, h + 2), FONT, scale, TEXT, 1, cv2.LINE_AA)
    tile = np.rot90(tile)
    th, tw = tile.shape[:2]
    y0, x0 = int(centre[1] - th / 2), int(centre[0] - tw / 2)
    ys, xs = slice(max(y0, 0), min(y0 + th, img.shape[0])), slice(max(x0, 0), min(x0 + tw, img.shape[1]))
    sub = tile[ys.start - y0 : ys.stop - y0, xs.start - x0 : xs.stop - x0]
    img[ys, xs] = np.minimum(img[ys, xs], sub)  # dark text over a light background


def _nice_ticks(lo: float, hi: float, n: int = 5) -> np.ndarray:
    """About ``n`` round tick values (1, 2, 2.5, 5 x 10^k apart) within [lo, hi]."""
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi <= lo:
        return np.array([lo]) if np.isfinite(lo) else np.array([])
    raw = (hi - lo) / max(n, 1)
    mag = 10.0 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw * (1 - 1e-9))
    first = math.ceil(lo / step - 1e-9) * step
    ticks = np.arange(first, hi + step * 1e-6, step)
    return np.where(np.abs(ticks) < step * 1e-9, 0.0, ticks)


def _tick_label(value: float, step: float) -> str:
    """A tick value with as many decimals as its step needs."""
    if abs(value) >= 1e5 or (value != 0 and abs(value) < 1e-3):
        return f"{value:.3g}"
    decimals = max(0, -math.floor(math.log10(step) + 1e-9)) if step > 0 else 0
    if step > 0 and round(step / 10.0**-decimals, 6) % 1:  # e.g. 2.5 x 10^k
        decimals += 1
    return f"{value:.{decimals}f}"


def _padded_range(values: Iterable[np.ndarray], pad: float = 0.05) -> tuple[float, float]:
    """(lo, hi) of the finite values, widened by ``pad`` of the span (or by 1 if constant)."""
    finite = [v[np.isfinite(v)] for v in (np.asarray(a, float).ravel() for a in values)]
    finite = [v for v in finite if v.size]
    if not finite:
        return 0.0, 1.0
    lo, hi = float(min(v.min() for v in finite)), float(max(v.max() for v in finite))
    span = hi - lo
    if span <= 0:
        span = max(abs(lo) * 0.2, 1.0)
        return lo - span / 2, hi + span / 2
    return lo - pad * span, hi + pad * span


# --------------------------------------------------------------------------- charts


@dataclass(frozen=True)
class Series:
    """One line of a :func:`line_chart`: ``x`` and ``y`` of equal length (NaN breaks the line)."""

    label: str
    x: np.ndarray
    y: np.ndarray
    colour: BGR
    thickness: int = 2


@dataclass(frozen=True)
class _Axes:
    """The plot rectangle of a chart and the data range it shows; maps data to pixels."""

    left: int
    top: int
    right: int
    bottom: int
    xlim: tuple[float, float]
    ylim: tuple[float, float]

    def px(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        fx = (np.asarray(x, float) - self.xlim[0]) / (self.xlim[1] - self.xlim[0])
        fy = (np.asarray(y, float) - self.ylim[0]) / (self.ylim[1] - self.ylim[0])
        u = self.left + fx * (self.right - self.left)
        v = self.bottom - fy * (self.bottom - self.top)
        return np.column_stack([u, v])


MARGINS = {"left": 72, "right": 16, "top": 30, "bottom": 46}  # pixels around a chart's plot area


def _axes_frame(
    img: np.ndarray,
    xlim: tuple[float, float],
    ylim: tuple[float, float],
    title: str,
    xlabel: str,
    ylabel: str,
    xticks: bool = True,
    bottom: int = MARGINS["bottom"],
    right: int = MARGINS["right"],
) -> _Axes:
    """Draw a chart's grid, y ticks (and x ticks if asked), labels and title; return its axes.
    ``bottom``, ``right``: the pixels under the plot area (x tick labels and the x label) and
    right of it (an outside legend)."""
    h, w = img.shape[:2]
    ax = _Axes(MARGINS["left"], MARGINS["top"], w - right, h - bottom, xlim, ylim)
    yt = _nice_ticks(*ylim)
    ystep = float(yt[1] - yt[0]) if len(yt) > 1 else 1.0
    for v in yt:
        y = int(round(ax.px([xlim[0]], [v])[0, 1]))
        cv2.line(img, (ax.left, y), (ax.right, y), GRID, 1)
        _text(img, _tick_label(v, ystep), (ax.left - 6, y + 4), align="right")
    if xticks:
        xt = _nice_ticks(*xlim, n=8)
        xstep = float(xt[1] - xt[0]) if len(xt) > 1 else 1.0
        for v in xt:
            x = int(round(ax.px([v], [ylim[0]])[0, 0]))
            cv2.line(img, (x, ax.top), (x, ax.bottom), GRID, 1)
            cv2.line(img, (x, ax.bottom), (x, ax.bottom + 4), AXIS, 1)
            _text(img, _tick_label(v, xstep), (x, ax.bottom + 17), align="centre")
    cv2.rectangle(img, (ax.left, ax.top), (ax.right, ax.bottom), AXIS, 1)
    _text(img, title, (ax.left, ax.top - 10), TITLE)
    _text(img, xlabel, ((ax.left + ax.right) / 2, h - 8), LABEL, align="centre")
    _vertical_text(img, ylabel, (14, (ax.top + ax.bottom) / 2))
    return ax


def _legend(img: np.ndarray, ax: _Axes, entries: Sequence[tuple[str, BGR]], where: str = "left") -> None:
    """A boxed legend, a colour swatch and a label each, in the top left or right corner of the
    plot area, or ``outside`` it on the right (leave :func:`_legend_width` for it)."""
    if not entries:
        return
    width = _legend_width(entries)
    height = 18 * len(entries) + 6
    x0 = {"left": ax.left + 8, "right": ax.right - 8 - width, "outside": ax.right + 10}[where]
    y0 = ax.top + (0 if where == "outside" else 8)
    cv2.rectangle(img, (x0, y0), (x0 + width, y0 + height), WHITE, -1)
    cv2.rectangle(img, (x0, y0), (x0 + width, y0 + height), GRID, 1)
    for k, (label, colour) in enumerate(entries):
        y = y0 + 15 + 18 * k
        cv2.line(img, (x0 + 6, y - 4), (x0 + 28, y - 4), colour, 3, cv2.LINE_AA)
        _text(img, label, (x0 + 34, y))


def _legend_width(entries: Sequence[tuple[str, BGR]]) -> int:
    """The width in pixels of the legend of ``entries`` (0 if none)."""
    if not entries:
        return 0
    return max(cv2.getTextSize(lab, FONT, SMALL, 1)[0][0] for lab, _ in entries) + 40


def _no_data(img: np.ndarray, message: str) -> np.ndarray:
    _text(img, message, (img.shape[1] / 2, img.shape[0] / 2), LABEL, align="centre")
    return img


def line_chart(
    series: Sequence[Series],
    title: str = "",
    xlabel: str = "",
    ylabel: str = "",
    size: tuple[int, int] = (900, 360),
    hlines: Sequence[float] = (),
    legend: str = "left",
) -> np.ndarray:
    """A BGR image (``size`` = (width, height) px) of lines against a shared x axis, with grid,
    round ticks, axis labels, a title and a legend (``legend``: 'left' or 'right' inside the plot,
    'outside' right of it, or '' for none).
    ``hlines``: y values marked by thin dark lines (e.g. 0). A series with one point is a dot.
    """
    w, h = size
    img = np.full((h, w, 3), 255, np.uint8)
    drawn = [s for s in series if np.isfinite(np.asarray(s.y, float)).any()]
    if not drawn:
        _axes_frame(img, (0.0, 1.0), (0.0, 1.0), title, xlabel, ylabel)
        return _no_data(img, "no data")
    xlim = _padded_range([s.x for s in drawn], pad=0.0)
    ylim = _padded_range([s.y for s in drawn] + [np.asarray(hlines, float)])
    entries = [(s.label, s.colour) for s in drawn if s.label] if legend else []
    right = MARGINS["right"] + (_legend_width(entries) + 10 if legend == "outside" and entries else 0)
    ax = _axes_frame(img, xlim, ylim, title, xlabel, ylabel, right=right)
    for y in hlines:
        a, b = ax.px(xlim, [y, y]).round().astype(int)
        cv2.line(img, tuple(a), tuple(b), AXIS, 1, cv2.LINE_AA)
    for s in drawn:
        x, y = np.asarray(s.x, float), np.asarray(s.y, float)
        ok = np.isfinite(x) & np.isfinite(y)
        xy = np.where(ok[:, None], ax.px(x, y), 0.0)
        pts = (xy * 16).round().astype(np.int32)  # 4 bits of sub-pixel precision
        breaks = np.flatnonzero(np.diff(ok.astype(int)) != 0) + 1
        for run, good in zip(np.split(pts, breaks), np.split(ok, breaks), strict=True):
            if not good[0]:
                continue
            if len(run) == 1:
                cv2.circle(img, tuple(run[0]), 3 * 16, s.colour, -1, cv2.LINE_AA, shift=4)
            else:
                cv2.polylines(img, [run], False, s.colour, s.thickness, cv2.LINE_AA, shift=4)
    _legend(img, ax, entries, legend)
    return img


def bar_chart(
    labels: Sequence[str],
    stacks: Sequence[tuple[str, np.ndarray, BGR]],
    title: str = "",
    ylabel: str = "",
    size: tuple[int, int] = (900, 360),
    hline: tuple[str, float] | None = None,
    annotate: Sequence[str] | None = None,
    sublabels: Sequence[str] | None = None,
) -> np.ndarray:
    """A BGR image of one bar per label, stacked from ``stacks`` (name, values per label, colour),
    NaN drawn as nothing. ``hline``: (legend label, y) of a dashed reference line; ``annotate``:
    text above each bar; ``sublabels``: a second line under each label. Labels too wide for their
    slot are written vertically; the legend (named stacks, the line) is right of the plot."""
    w, h = size
    img = np.full((h, w, 3), 255, np.uint8)
    if not labels or not stacks:
        _axes_frame(img, (0.0, 1.0), (0.0, 1.0), title, "", ylabel, xticks=False)
        return _no_data(img, "no data")
    values = np.vstack([np.nan_to_num(np.asarray(v, float)) for _, v, _ in stacks])
    top = values.sum(axis=0)
    hi = max(float(top.max(initial=0)), hline[1] if hline else 0.0)
    hi = hi * 1.12 if hi > 0 else 1.0  # room for the annotations
    entries = [(name, colour) for name, _, colour in stacks if name]
    if hline is not None:
        entries.append((hline[0], TEXT))
    right = MARGINS["right"] + (_legend_width(entries) + 10 if entries else 0)
    tall = max(cv2.getTextSize(lab, FONT, SMALL, 1)[0][0] for lab in labels)
    slot = (w - MARGINS["left"] - right) / len(labels)
    vertical = tall > slot - 4
    bottom = MARGINS["bottom"] + (tall - 20 if vertical else 0)  # room for vertical labels
    img = np.full((h - MARGINS["bottom"] + bottom, w, 3), 255, np.uint8)
    ax = _axes_frame(
        img, (0.0, float(len(labels))), (0.0, hi), title, "", ylabel, xticks=False, bottom=bottom, right=right
    )
    bar_w = max(int(slot * 0.7), 1)
    for k, label in enumerate(labels):
        xc = ax.px([k + 0.5], [0])[0, 0]
        base = 0.0
        for _, vals, colour in stacks:
            v = float(np.nan_to_num(np.asarray(vals, float)[k]))
            if v <= 0:
                continue
            (x0, y0), (x1, y1) = ax.px([k + 0.5, k + 0.5], [base, base + v]).round().astype(int)
            cv2.rectangle(img, (int(xc - bar_w / 2), y1), (int(xc + bar_w / 2), y0), colour, -1)
            base += v
        if annotate is not None:
            y = ax.px([0], [base])[0, 1]
            _text(img, annotate[k], (xc, y - 4), SMALL * 0.9, align="centre")
        if vertical:
            _vertical_text(img, label, (xc, ax.bottom + 6 + tall / 2), SMALL)
        else:
            _text(img, label, (xc, ax.bottom + 16), align="centre")
            if sublabels is not None:
                _text(img, sublabels[k], (xc, ax.bottom + 31), SMALL * 0.85, AXIS, align="centre")
    if hline is not None:
        y = int(round(ax.px([0], [hline[1]])[0, 1]))
        for x in range(ax.left, ax.right, 12):  # dashed
            cv2.line(img, (x, y), (min(x + 6, ax.right), y), TEXT, 1)
    _legend(img, ax, entries, "outside")
    return img


# --------------------------------------------------------------------------- frames


def chosen_frames(frames: Iterable[int], n: int) -> list[int]:
    """``n`` frames spread over a test: the first, the last and evenly between (nearest by index
    in the sorted unique ``frames``). All of them when there are ``n`` or fewer; with ``n == 1``
    the last (the most deformed: the first is the undeformed reference); none for ``n <= 0``."""
    unique = sorted({int(f) for f in frames})
    if n <= 0 or not unique:
        return []
    if len(unique) <= n:
        return unique
    if n == 1:
        return [unique[-1]]
    idx = np.round(np.linspace(0, len(unique) - 1, n)).astype(int)
    return [unique[i] for i in sorted(set(idx.tolist()))]


# --------------------------------------------------------------------------- volume and strain


def volume_strain_plot(volume: pd.DataFrame, width: int = 900) -> np.ndarray:
    """Panels against time (s): the volume change (mm^3, from ``volume_change_mm3`` or else
    ``volume_mm3`` minus its first value; with ``volume_sigma_mm3``, thin lines at +- 1 sigma of
    the volume) and the axial, radial (if the column is there) and volumetric strain (%,
    compression positive); with ``measured_fraction``, a third: the share of the membrane's dots
    measured (%). ``volume``: a ``tables.VOLUME`` table (``VOLUME_RESULT``'s columns optional)."""
    v = volume.sort_values("frame")
    t = v["time_s"].to_numpy(float)
    if "volume_change_mm3" in v and v["volume_change_mm3"].notna().any():
        dv = v["volume_change_mm3"].to_numpy(float)
    else:
        vol = v["volume_mm3"].to_numpy(float)
        first = vol[np.isfinite(vol)][:1]
        dv = vol - (first[0] if first.size else np.nan)
    sigma = v["volume_sigma_mm3"].to_numpy(float) if "volume_sigma_mm3" in v else np.full(len(v), np.nan)
    band = [Series(lab, t, dv + k * sigma, PALETTE[9], 1) for lab, k in (("+- 1 sigma", 1), ("", -1))]
    top = line_chart(
        [Series("volume change", t, dv, PALETTE[0]), *band],
        "volume change of the specimen",
        "time (s)",
        "volume change (mm^3)",
        (width, 340),
        hlines=[0.0],
        legend="left" if np.isfinite(sigma).any() else "",
    )
    strains = [
        ("axial", "axial_strain", PALETTE[0]),
        ("radial", "radial_strain", PALETTE[1]),
        ("volumetric", "volumetric_strain", PALETTE[2]),
    ]
    series = [Series(lab, t, 100 * v[col].to_numpy(float), c) for lab, col, c in strains if col in v]
    note = "" if "radial_strain" in v else " (no radial strain in the table)"
    bottom = line_chart(
        series,
        f"strains of the specimen, compression positive{note}",
        "time (s)",
        "strain (%)",
        (width, 340),
        hlines=[0.0],
    )
    if "measured_fraction" not in v:
        return np.vstack([top, bottom])
    dots = [Series("measured", t, 100 * v["measured_fraction"].to_numpy(float), PALETTE[2])]
    third = line_chart(dots, "membrane dots measured", "time (s)", "measured (%)", (width, 260), legend="")
    return np.vstack([top, bottom, third])


# --------------------------------------------------------------------------- strain maps

MAP_WIDTH_PX = 320  # the unrolled membrane, 0..360 deg
MAP_MARGINS = {"left": 52, "right": 10, "top": 26, "bottom": 40}
COLOURBAR_PX = 78  # the colour bar and its labels


def _colour_bar(height: int, vmax: float, unit: str, scale: float = 1.0) -> np.ndarray:
    """A (height, >= COLOURBAR_PX, 3) tile: the diverging scale from -vmax (bottom) to +vmax
    (top), labelled in ``unit`` with the values times ``scale``."""
    width = max(COLOURBAR_PX, cv2.getTextSize(unit, FONT, SMALL, 1)[0][0] + 16)
    tile = np.full((height, width, 3), 255, np.uint8)
    top, bottom = MAP_MARGINS["top"], height - MAP_MARGINS["bottom"]
    ramp = np.linspace(255, 0, max(bottom - top, 2)).round().astype(np.uint8)
    bar = DIVERGING[ramp][:, 0][:, None, :].repeat(14, axis=1)
    tile[top : top + len(ramp), 8:22] = bar
    cv2.rectangle(tile, (8, top), (21, top + len(ramp) - 1), AXIS, 1)
    mid = (top + bottom) / 2
    for y, v in ((top, vmax), (mid, 0.0), (bottom - 1, -vmax)):
        _text(tile, f"{v * scale:+.3g}" if v else "0", (26, y + 4))
    _text(tile, unit, (8, top - 8))
    return tile


def _pivot_cells(cells: pd.DataFrame, value: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The grid of a frame's cells: (row centres z mm, column centres theta rad in [0, 2 pi),
    values (n_rows, n_cols)), rows and columns in the order of the ``row``, ``col`` numbers."""
    grid = cells.pivot_table(index="row", columns="col", values=value, aggfunc="mean", dropna=False)
    z = cells.groupby("row")["z_mm"].median().reindex(grid.index).to_numpy(float)
    theta = np.mod(
        cells.groupby("col")["theta_rad"].median().reindex(grid.columns).to_numpy(float), 2 * np.pi
    )
    return z, theta, grid.to_numpy(float)


def _unrolled(
    z: np.ndarray, theta: np.ndarray, values: np.ndarray, width: int, height: int, z_lo: float, z_hi: float
) -> np.ndarray:
    """(height, width) values on pixels: each pixel takes the cell whose centre is nearest in z and
    (circularly) in theta; pixel column x is theta = (x + 0.5) / width * 360 deg, row y is z from
    z_hi (top) down to z_lo."""
    tx = (np.arange(width) + 0.5) / width * 2 * np.pi
    dt = np.abs(tx[:, None] - theta[None, :])
    col = np.argmin(np.minimum(dt, 2 * np.pi - dt), axis=1)
    zy = z_hi - (np.arange(height) + 0.5) / height * (z_hi - z_lo)
    row = np.argmin(np.abs(zy[:, None] - z[None, :]), axis=1)
    return values[row[:, None], col[None, :]]


def _z_limits(z: np.ndarray) -> tuple[float, float]:
    """The z extent of grid rows with centres ``z``: half a row spacing beyond the outer ones."""
    zs = np.sort(z[np.isfinite(z)])
    half = float(np.median(np.diff(zs))) / 2 if len(zs) > 1 else 1.0
    return float(zs[0]) - half, float(zs[-1]) + half


def strain_map(
    strains: pd.DataFrame,
    frame: int,
    component: str = "e_zz",
    vmax: float | None = None,
    colorbar: bool = True,
) -> np.ndarray:
    """The unrolled membrane at one frame as a BGR image: theta 0..360 deg to the right (the
    membrane seen from outside), z (mm, undeformed) up, coloured by ``component`` of
    ``strains`` (a ``tables.STRAINS`` table; %, tension positive) on a diverging scale of
    -vmax..vmax (strain, not %; default: the frame's 99th percentile magnitude). Grey cells have
    no value. ``colorbar``: add the scale and its range on the right.
    Raises ValueError if the frame or the component is not in the table."""
    if component not in strains:
        raise ValueError(f"strains table has no column {component!r}")
    cells = strains[strains["frame"] == frame]
    if cells.empty:
        raise ValueError(f"frame {frame} is not in the strains table")
    z, theta, values = _pivot_cells(cells, component)
    vmax = _half_range(values) if vmax is None else max(float(vmax), MIN_RANGE)
    z_lo, z_hi = _z_limits(z)
    map_h = max(int(round(MAP_WIDTH_PX * (z_hi - z_lo) / (2 * np.pi * SPECIMEN_RADIUS_MM))), 40)
    m = MAP_MARGINS
    img = np.full((m["top"] + map_h + m["bottom"], m["left"] + MAP_WIDTH_PX + m["right"], 3), 255, np.uint8)
    field = _unrolled(z, theta, values, MAP_WIDTH_PX, map_h, z_lo, z_hi)
    rgb = _colours(field.ravel(), vmax).reshape(map_h, MAP_WIDTH_PX, 3)
    img[m["top"] : m["top"] + map_h, m["left"] : m["left"] + MAP_WIDTH_PX] = rgb
    x0, y0, x1, y1 = m["left"], m["top"], m["left"] + MAP_WIDTH_PX - 1, m["top"] + map_h - 1
    cv2.rectangle(img, (x0, y0), (x1, y1), AXIS, 1)
    for deg in range(0, 361, 90):
        x = x0 + deg / 360 * (x1 - x0)
        cv2.line(img, (int(x), y1), (int(x), y1 + 4), AXIS, 1)
        _text(img, str(deg), (x, y1 + 16), align="centre")
    _text(img, "theta (deg)", ((x0 + x1) / 2, img.shape[0] - 6), SMALL, align="centre")
    zt = _nice_ticks(z_lo, z_hi, 4)
    for v in zt:
        y = y1 - (v - z_lo) / (z_hi - z_lo) * (y1 - y0)
        cv2.line(img, (x0 - 4, int(y)), (x0, int(y)), AXIS, 1)
        _text(img, f"{v:.0f}", (x0 - 6, y + 4), align="right")
    _vertical_text(img, "z (mm)", (10, (y0 + y1) / 2), SMALL)
    time_s = float(cells["time_s"].iloc[0])
    _text(img, f"{component}  t = {time_s:.2f} s  (frame {frame})", (x0, y0 - 9), LABEL)
    if colorbar:
        img = np.hstack([img, _colour_bar(img.shape[0], vmax, f"{component} (%)", 100.0)])
    return img


def strain_maps(
    strains: pd.DataFrame, frames: Sequence[int], components: Sequence[str] = ("e_zz", "e_tt")
) -> np.ndarray:
    """:func:`strain_map` of each component (one row each) at each of ``frames`` (side by side),
    one colour range per component shared by its row (so the times compare), with a title line.
    ``frames`` missing from the table are left out."""
    present = set(strains["frame"].unique().tolist())
    frames = [f for f in frames if f in present]
    title = "local Green-Lagrange strain of the membrane (%), tension positive; unrolled, seen from outside"
    if not frames:
        img = np.full((200, 900, 3), 255, np.uint8)
        _text(img, title, (10, 20), TITLE)
        return _no_data(img, "no strain data")
    rows = []
    for comp in components:
        shown = strains.loc[strains["frame"].isin(frames), comp].to_numpy(float)
        vmax = _half_range(shown)
        maps = [
            strain_map(strains, f, comp, vmax, colorbar=k == len(frames) - 1) for k, f in enumerate(frames)
        ]
        rows.append(np.hstack(maps))
    out = np.vstack(rows)
    head = np.full((28, out.shape[1], 3), 255, np.uint8)
    _text(head, title, (10, 19), TITLE)
    return np.vstack([head, out])


# --------------------------------------------------------------------------- reconstruction quality


def _number(value: object) -> float:
    """A JSON value as a float: NaN unless it is a (non-boolean) number."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return float("nan")
    return float(value)


def reprojection_plot(quality: dict, width: int = 900) -> np.ndarray:
    """Mean reprojection error (px) per camera as bars, labelled with the observations used and
    dropped, the mean over all cameras as a dashed line; below, if the entries of ``quality``'s
    ``per_frame`` (or else ``frames``) list have ``frame`` and ``mean_reprojection_px``, that
    error against the frame. ``quality``: the ``quality.json`` document; absent keys and NaN are
    drawn as no data."""
    per_camera = quality.get("per_camera") or {}
    names = sorted(per_camera)

    err = np.array([_number(per_camera[n].get("mean_reprojection_px")) for n in names], float)
    used = [_number(per_camera[n].get("observations_used")) for n in names]
    dropped = [_number(per_camera[n].get("observations_dropped")) for n in names]
    sub = [
        f"{u:.0f}/{d:.0f}" if np.isfinite(u) and np.isfinite(d) else ""
        for u, d in zip(used, dropped, strict=True)
    ]
    mean = _number(quality.get("mean_reprojection_px"))
    hline = ("all cameras", mean) if np.isfinite(mean) else None
    panels = [
        bar_chart(
            names,
            [("", err, PALETTE[0])],
            "mean reprojection error per camera (below: observations used/dropped)",
            "reprojection error (px)",
            (width, 360),
            hline=hline,
            annotate=[f"{e:.3f}" if np.isfinite(e) else "n/a" for e in err],
            sublabels=sub,
        )
    ]
    per_frame = [
        f
        for f in quality.get("per_frame") or quality.get("frames") or []
        if isinstance(f, dict) and "frame" in f and "mean_reprojection_px" in f
    ]
    if per_frame:
        fr = np.array([f["frame"] for f in per_frame], float)
        e = np.array([_number(f.get("mean_reprojection_px")) for f in per_frame], float)
        order = np.argsort(fr)
        panels.append(
            line_chart(
                [Series("all cameras", fr[order], e[order], PALETTE[0])],
                "mean reprojection error per frame",
                "frame",
                "reprojection error (px)",
                (width, 300),
                legend="",
            )
        )
    return np.vstack(panels)


# --------------------------------------------------------------------------- tracking


def tracking_plot(tracks: pd.DataFrame, width: int = 900) -> np.ndarray:
    """Three panels over all cameras: the share of targets reported per frame (%); the targets
    not reported per frame by reason; the targets not reported per camera over the test, stacked
    by reason. ``tracks``: a ``tables.TRACKS`` table (reason '' when reported); a row repeated
    (a frame two chunks share) is counted once."""
    if tracks.empty:
        img = line_chart([], "share of targets reported, all cameras", "frame", "reported (%)", (width, 300))
        return _no_data(img, "no tracking data")
    t = tracks[["camera", "frame", "id", "reason"]].drop_duplicates(["camera", "frame", "id"], keep="last")
    reason = t["reason"].fillna("").astype(str)
    counts = pd.crosstab(t["frame"], reason)
    frames = counts.index.to_numpy(float)
    total = counts.sum(axis=1).to_numpy(float)
    reported = counts[""].to_numpy(float) if "" in counts else np.zeros_like(total)
    share = np.where(total > 0, 100 * reported / np.maximum(total, 1), np.nan)
    reasons = [r for r in LOSS_REASONS if r in counts] + sorted(set(counts) - set(LOSS_REASONS) - {""})
    colour = {r: REASON_COLOURS.get(r, OTHER_REASON) for r in reasons}
    first = line_chart(
        [Series("reported", frames, share, REPORTED)],
        "share of targets reported, all cameras",
        "frame",
        "reported (%)",
        (width, 300),
        legend="",
    )
    second = line_chart(
        [Series(r, frames, counts[r].to_numpy(float), colour[r]) for r in reasons],
        "targets not reported per frame, by reason (all cameras)",
        "frame",
        "targets",
        (width, 300),
        hlines=[0.0],
        legend="outside",
    )
    if not reasons:  # nothing lost: say so rather than "no data"
        _text(second, "every target reported in every frame", (width / 2, 160), LABEL, align="centre")
    per_cam = pd.crosstab(t["camera"], reason)
    cams = [str(c) for c in per_cam.index]
    stacks = [
        (r, per_cam[r].to_numpy(float) if r in per_cam else np.zeros(len(cams)), colour[r]) for r in reasons
    ]
    lost = per_cam.drop(columns=[""], errors="ignore").sum(axis=1).to_numpy(float)
    third = bar_chart(
        cams,
        stacks or [("", np.zeros(len(cams)), PALETTE[0])],
        "targets not reported per camera over the test, by reason",
        "target-frames",
        (width, 340),
        annotate=[f"{v:.0f}" for v in lost],
    )
    return np.vstack([first, second, third])


# --------------------------------------------------------------------------- the movie


def _membrane_index(ids: np.ndarray) -> np.ndarray:
    """0-based index (r-1)*64 + (c-1) of membrane dot IDs in the grid."""
    return np.asarray(ids, np.int64) - MEMBRANE_FIRST_ID


def _cell_corners() -> np.ndarray:
    """(59*64, 4) grid indices of each cell's corner dots, rows 1..59 by columns 1..64, in order
    around the quad; column 64's cell closes the ring on column 1."""
    r, c = np.meshgrid(np.arange(MEMBRANE_ROWS - 1), np.arange(MEMBRANE_COLS), indexing="ij")
    r, c = r.ravel(), c.ravel()
    c1 = (c + 1) % MEMBRANE_COLS
    return np.column_stack(
        [
            r * MEMBRANE_COLS + c,
            r * MEMBRANE_COLS + c1,
            (r + 1) * MEMBRANE_COLS + c1,
            (r + 1) * MEMBRANE_COLS + c,
        ]
    )


def _displaced(points: pd.DataFrame, magnify: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 3) positions of the rows of ``points``: as measured, of the same target at the first
    frame of the table (NaN where it is missing there), and as drawn, with the displacement
    from the first frame times ``magnify`` (the measured ones when ``magnify`` is 1)."""
    cols = ["x_mm", "y_mm", "z_mm"]
    xyz = points[cols].to_numpy(float)
    if points.empty:
        return xyz, xyz, xyz
    first = points[points["frame"] == points["frame"].min()].drop_duplicates("id").set_index("id")
    ref_xyz = first[cols].reindex(points["id"]).to_numpy(float)
    drawn = xyz if magnify == 1.0 else ref_xyz + magnify * (xyz - ref_xyz)
    return xyz, ref_xyz, drawn


def _rows_by_frame(points: pd.DataFrame) -> dict[int, np.ndarray]:
    """Frame -> positional row indices of ``points`` in that frame."""
    groups = pd.Series(np.arange(len(points)), index=points["frame"].to_numpy()).groupby(level=0)
    return {int(f): k.to_numpy() for f, k in groups}


@dataclass(frozen=True)
class _Stage:
    """Where the movie's views are drawn: pixels per mm and the extents, fixed for all frames."""

    scale: float  # pixels per mm
    z_lo: float
    z_hi: float
    panel_w: int
    top: int


MOVIE_TOP_PX = 34  # the time line
MOVIE_BOTTOM_PX = 26  # the view labels
SHADE_AMBIENT = 0.55  # a quad facing the viewer at angle a is drawn at (0.55 + 0.45 cos a) brightness


def specimen_frames(
    points: pd.DataFrame,
    strains: pd.DataFrame | None = None,
    *,
    colour_by: str = "radial",
    frames: Sequence[int] | None = None,
    views_deg: Sequence[float] = (0.0, 180.0),
    height: int = 720,
    magnify: float = 1.0,
    vmax: float | None = None,
) -> Iterator[np.ndarray]:
    """The deforming specimen seen from the side, one BGR frame per test frame (all of
    ``points``' frames, or those of ``frames`` that it has), all the same even size.

    Each view is an orthographic projection of the membrane along the horizontal direction
    ``(cos a, sin a, 0)`` towards the axis, for each azimuth ``a`` of ``views_deg`` (default: two
    opposite sides, so the whole membrane is seen), z up. The membrane grid cells facing the
    viewer are filled quads between their four dots (a cell is left out while a corner dot is
    missing), shaded by their slant, coloured on a diverging scale by ``colour_by``:

    * ``"radial"``: the mean radial displacement of the cell's dots from the first frame (mm,
      outward positive) about the axis through the first frame's membrane centroid, parallel
      to z;
    * ``"e_zz"``, ``"e_tt"``, ``"e_tz"``: that local strain of ``strains`` (%, tension positive);
      grey where the frame has no value.

    Other targets of ``points`` (the pedestals' coded targets) are dark grey dots. ``magnify``
    scales the displacements from the first frame (geometry only; the colours stay true).
    ``vmax``: half the colour range (mm, or strain); default: the 99th percentile magnitude over
    the whole movie. The frame time is printed at the top left, the scale on the right.
    ``points``: a ``tables.POINTS`` table; membrane dots have IDs 1001..4840.
    Raises ValueError (at the call, before any frame is drawn) when there is no membrane dot, or
    a strain is asked for without ``strains``.
    """
    if colour_by != "radial" and (strains is None or colour_by not in strains):
        raise ValueError(f"colour_by={colour_by!r} needs a strains table with that column")
    height += height % 2  # yuv420p needs even sizes
    pts = points.sort_values(["frame", "id"])
    is_mem = pts["id"].between(MEMBRANE_FIRST_ID, MEMBRANE_LAST_ID)
    mem = pts[is_mem]
    if mem.empty:
        raise ValueError("no membrane dots (IDs 1001..4840) in the points table")
    xyz, ref_xyz, drawn = _displaced(mem, magnify)
    centre = xyz[(mem["frame"] == mem["frame"].min()).to_numpy(), :2].mean(axis=0)  # the axis
    radial = np.hypot(*(xyz[:, :2] - centre).T) - np.hypot(*(ref_xyz[:, :2] - centre).T)
    others = pts[~is_mem]
    others_drawn = _displaced(others, magnify)[2]

    if colour_by == "radial":
        vmax = _half_range(radial) if vmax is None else vmax
        unit, factor = "radial disp. (mm)", 1.0
    else:
        vmax = _half_range(strains[colour_by].to_numpy(float)) if vmax is None else vmax
        unit, factor = f"{colour_by} (%)", 100.0
    vmax = max(float(vmax), MIN_RANGE)

    every = np.vstack([drawn, others_drawn])
    every = every[np.isfinite(every).all(axis=1)]
    reach = float(np.hypot(*(every[:, :2] - centre).T).max()) * 1.04
    z_lo, z_hi = float(every[:, 2].min()), float(every[:, 2].max())
    pad = 0.03 * (z_hi - z_lo + 1.0)
    z_lo, z_hi = z_lo - pad, z_hi + pad
    scale = (height - MOVIE_TOP_PX - MOVIE_BOTTOM_PX) / (z_hi - z_lo)
    panel_w = int(math.ceil(2 * reach * scale)) + 20
    stage = _Stage(scale, z_lo, z_hi, panel_w, MOVIE_TOP_PX)
    bar = _colour_bar(height, vmax, unit, factor)
    bar_x = panel_w * len(views_deg)
    width = bar_x + bar.shape[1]
    width += width % 2

    corners = _cell_corners()
    n_grid = MEMBRANE_ROWS * MEMBRANE_COLS
    mem_frames = _rows_by_frame(mem)
    other_frames = {f: others_drawn[k] for f, k in _rows_by_frame(others).items()}
    strain_frames = dict(tuple(strains.groupby("frame"))) if colour_by != "radial" else {}
    times = pts.groupby("frame")["time_s"].first()
    wanted = sorted(mem_frames) if frames is None else [f for f in sorted(set(frames)) if f in mem_frames]
    grid_idx = _membrane_index(mem["id"].to_numpy())

    def render() -> Iterator[np.ndarray]:
        for frame in wanted:
            rows = mem_frames[frame]
            pos = np.full((n_grid, 3), np.nan)
            pos[grid_idx[rows]] = drawn[rows]
            quad = pos[corners]  # (cells, 4, 3)
            ok = np.isfinite(quad).all(axis=(1, 2))
            if colour_by == "radial":
                disp = np.full(n_grid, np.nan)
                disp[grid_idx[rows]] = radial[rows]
                value = disp[corners].mean(axis=1)
            else:
                value = np.full(len(corners), np.nan)
                cells = strain_frames.get(frame)
                if cells is not None:
                    k = (cells["row"].to_numpy(int) - 1) * MEMBRANE_COLS + cells["col"].to_numpy(int) - 1
                    inside = (k >= 0) & (k < len(corners))
                    value[k[inside]] = cells[colour_by].to_numpy(float)[inside]
            colours = _colours(value, vmax).astype(float)
            extra = other_frames.get(frame)
            img = np.full((height, width, 3), 255, np.uint8)
            for v, azimuth in enumerate(views_deg):
                _draw_view(img, v * panel_w, stage, quad[ok], colours[ok], centre, azimuth, extra)
            img[:, bar_x : bar_x + bar.shape[1]] = bar
            _text(img, f"t = {float(times.get(frame, np.nan)):.2f} s   frame {frame}", (12, 22), TITLE)
            if magnify != 1.0:
                _text(
                    img,
                    f"displacements x{magnify:g}",
                    (panel_w * len(views_deg) - 12, 22),
                    SMALL,
                    align="right",
                )
            yield img

    return render()  # the checks above run now, the drawing frame by frame


def _draw_view(
    img: np.ndarray,
    x_off: int,
    stage: _Stage,
    quad: np.ndarray,
    colours: np.ndarray,
    centre: np.ndarray,
    azimuth_deg: float,
    extra: np.ndarray | None,
) -> None:
    """Draw one orthographic side view into ``img`` at column ``x_off``: the quads facing the
    viewer (back to front), then the other targets in front of the axis, then the view label."""
    a = math.radians(azimuth_deg)
    toward = np.array([math.cos(a), math.sin(a)])  # from the axis to the viewer
    right = np.array([-math.sin(a), math.cos(a)])
    mid = quad.mean(axis=1)
    radial = mid[:, :2] - centre
    r = np.linalg.norm(radial, axis=1)
    facing = radial @ toward / np.maximum(r, 1e-9)
    front = np.flatnonzero(facing > 0)
    front = front[np.argsort(facing[front])]  # the slanted ones first, the nearest last
    cx = x_off + stage.panel_w / 2

    def to_px(p: np.ndarray) -> np.ndarray:
        u = (p[..., :2] - centre) @ right
        return np.stack([cx + u * stage.scale, stage.top + (stage.z_hi - p[..., 2]) * stage.scale], axis=-1)

    px = (to_px(quad[front]) * 16).round().astype(np.int32)  # 4 bits of sub-pixel precision
    shade = SHADE_AMBIENT + (1 - SHADE_AMBIENT) * facing[front]
    for poly, colour, s in zip(px, colours[front], shade, strict=True):
        cv2.fillConvexPoly(img, poly, tuple(float(c) * s for c in colour), cv2.LINE_8, shift=4)
    if extra is not None and len(extra):
        p = extra[np.isfinite(extra).all(axis=1)]
        p = p[(p[:, :2] - centre) @ toward > 0]
        for u, v in to_px(p).round().astype(int):
            cv2.circle(img, (int(u), int(v)), 3, (70, 70, 70), -1, cv2.LINE_AA)
    _text(img, f"seen from azimuth {azimuth_deg:g} deg", (cx, img.shape[0] - 8), SMALL, AXIS, align="centre")


def write_movie(
    frames: Iterable[np.ndarray], path: str | Path, fps: float, crf: int = 23, preset: str = "medium"
) -> int:
    """Encode BGR uint8 frames (all of the first frame's shape) to an H.264 MP4 at ``path`` that
    browsers play: yuv420p (limited range, BT.601, so tagged), the index at the front of the
    file (``faststart``). An odd width or height is padded with one white column or row.
    Frame k is at time k / fps s. Returns the number of frames written; ValueError if none or if
    a frame's shape differs from the first's.

    Not :class:`triaxtrack.video.VideoWriter`: that writes grayscale frames into the luma plane
    (full range, constant chroma), made for the camera videos; this movie is in colour."""
    rate = Fraction(fps).limit_denominator(100_000)
    if rate <= 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    path = Path(path)
    container = None
    stream = None
    shape: tuple[int, ...] | None = None
    n = 0
    try:
        for frame in frames:
            if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
                raise ValueError(
                    f"{path}: frames must be (H, W, 3) uint8 BGR, got {frame.dtype} {frame.shape}"
                )
            if shape is None:
                shape = frame.shape
                h, w = shape[0] + shape[0] % 2, shape[1] + shape[1] % 2
                container = av.open(str(path), mode="w", options={"movflags": "+faststart"})
                stream = container.add_stream(
                    CODECS["h264"],
                    rate=rate,
                    options={"crf": str(crf), "preset": preset, "x264-params": f"threads={ENCODER_THREADS}"},
                )
                stream.width, stream.height, stream.pix_fmt = w, h, "yuv420p"
                ctx = stream.codec_context
                ctx.colorspace = ctx.color_primaries = ctx.color_trc = 6  # SMPTE 170M (BT.601)
                ctx.color_range = 1  # MPEG (limited) range, what swscale makes and players expect
            elif frame.shape != shape:
                raise ValueError(f"{path}: frame {n} has shape {frame.shape}, the first {shape}")
            if frame.shape[:2] != (stream.height, stream.width):
                frame = cv2.copyMakeBorder(
                    frame,
                    0,
                    stream.height - frame.shape[0],
                    0,
                    stream.width - frame.shape[1],
                    cv2.BORDER_CONSTANT,
                    value=WHITE,
                )
            vf = av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="bgr24").reformat(
                format="yuv420p"
            )
            vf.pts = n
            vf.time_base = 1 / rate
            for packet in stream.encode(vf):
                container.mux(packet)
            n += 1
        if stream is None:
            raise ValueError(f"{path}: no frames to encode")
        for packet in stream.encode(None):
            container.mux(packet)
    finally:
        if container is not None:
            container.close()
    return n


def write_movie_page(movie: str | Path, path: str | Path, title: str = "") -> None:
    """Write ``path``: a self-contained HTML page that plays the MP4 ``movie`` (embedded as a
    base64 data URI) in a looping ``<video>`` element. Snakemake's report shows HTML results in a
    frame but offers other files, an MP4 included, only as a download."""
    data = base64.b64encode(Path(movie).read_bytes()).decode("ascii")
    name = html.escape(Path(movie).name)
    heading = f"<p>{html.escape(title)}</p>\n" if title else ""
    page = (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        f"<title>{html.escape(title) or name}</title>\n"
        "<style>body{margin:0;font-family:sans-serif;font-size:14px}video{max-width:100%;height:auto}"
        "p{margin:6px 8px}</style>\n</head>\n<body>\n"
        f'{heading}<video controls loop muted autoplay playsinline preload="auto" '
        f'src="data:video/mp4;base64,{data}"></video>\n'
        "</body>\n</html>\n"
    )
    Path(path).write_text(page, encoding="ascii")
