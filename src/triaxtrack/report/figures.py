"""The report's charts on matplotlib: volume and strains against time, reprojection error and
tracking losses; and the workflow's stage that draws every figure of a test from its files
(:func:`run_report_figures`).

Each ``*_figure`` function takes tables (or ``quality.json`` as a dict) and returns a new
:class:`matplotlib.figure.Figure` (Agg, never pyplot). :func:`draw_bars` is the bar panel they share (and
:func:`triaxtrack.camera_report.camera_quality_figure` uses).

Conventions: strains of ``volume`` are compression positive, as in :mod:`triaxtrack.tables`,
drawn in per cent; times in seconds on the test clock.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from triaxtrack.camera_report import camera_quality, camera_quality_figure
from triaxtrack.kit import load_kit_design
from triaxtrack.report.common import chosen_frames, number
from triaxtrack.report.config import ReportConfig
from triaxtrack.report.layout import MembraneLayout, membrane_layout
from triaxtrack.report.maps import strain_maps_figure
from triaxtrack.report.style import PALETTE, new_figure, no_data, save_figure, styled
from triaxtrack.tables import LABELS, STRAINS, TRACKS, VOLUME, read_table
from triaxtrack.testfolder import read_quality
from triaxtrack.timesteps import LARGE_LOSS_SHARE, large_losses

__all__ = [
    "LOSS_REASONS",
    "REASON_COLOURS",
    "REPORTED",
    "draw_bars",
    "reprojection_figure",
    "run_report_figures",
    "tracking_figure",
    "volume_strain_figure",
]

#: Why a target is not reported in a frame (``tables.TRACKS``, ``triaxtrack.track``), in the
#: order drawn; any other reason is drawn after them in OTHER_REASON.
LOSS_REASONS = ("lost", "edge", "merged", "jump", "shape", "ambiguous", "drift", "disagrees", "not_recorded")
REASON_COLOURS: dict[str, str] = {
    "lost": PALETTE[3],  # red
    "edge": PALETTE[1],  # orange
    "merged": PALETTE[4],  # purple
    "jump": PALETTE[5],  # brown
    "shape": PALETTE[6],  # pink
    "ambiguous": PALETTE[8],  # olive
    "drift": PALETTE[9],  # cyan
    "disagrees": "#000080",  # navy
    "not_recorded": PALETTE[7],  # grey: the camera has no image, not a tracking failure
}
REPORTED = PALETTE[2]  # green
OTHER_REASON = "#3c3c3c"

MARKERS_UP_TO = 50  # series with at most this many points mark each point (short tests)
PANEL_PX = {"line": 300, "bars": 340, "wide": 360}  # heights of the panels, pixels
BAR_WIDTH = 0.7  # of the slot of one bar
TICK_CHAR_PX = 6.5  # approximate width of a tick label's character at 8 pt, to decide on rotation
HEADROOM = 1.15  # the bar panels' y range above their highest bar, room for the annotations


def _line(ax: Axes, x: np.ndarray, y: np.ndarray, colour: str, label: str | None = None, **kw) -> None:
    """One series (NaN breaks the line); each point marked when there are few."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    marker = "o" if np.isfinite(y).sum() <= MARKERS_UP_TO else None
    ax.plot(x, y, color=colour, lw=1.8, marker=marker, ms=3, label=label, **kw)


def _has_data(*arrays: np.ndarray) -> bool:
    return any(np.isfinite(np.asarray(a, float)).any() for a in arrays)


# --------------------------------------------------------------------------- volume and strain


def _volume_change(v: pd.DataFrame) -> np.ndarray:
    """``volume_change_mm3``, or else ``volume_mm3`` minus its first finite value."""
    if "volume_change_mm3" in v and v["volume_change_mm3"].notna().any():
        return v["volume_change_mm3"].to_numpy(float)
    vol = v["volume_mm3"].to_numpy(float)
    first = vol[np.isfinite(vol)][:1]
    return vol - (first[0] if first.size else np.nan)


def _volume_panel(ax: Axes, v: pd.DataFrame, t: np.ndarray) -> None:
    dv = _volume_change(v)
    sigma = v["volume_sigma_mm3"].to_numpy(float) if "volume_sigma_mm3" in v else np.full(len(v), np.nan)
    ax.set(title="volume change of the specimen (negative: it contracts)", xlabel="time (s)",
           ylabel="volume change (mm³)")  # fmt: skip
    if not _has_data(dv):
        no_data(ax)
        return
    ax.axhline(0.0, color="0.35", lw=0.8)
    if np.isfinite(sigma).any():
        ax.fill_between(t, dv - sigma, dv + sigma, color=PALETTE[9], alpha=0.3, lw=0,
                        label="± 1 standard uncertainty")  # fmt: skip
    _line(ax, t, dv, PALETTE[0], "volume change")
    ax.legend(loc="best")


def _strain_panel(ax: Axes, v: pd.DataFrame, t: np.ndarray) -> None:
    strains = [("axial", "axial_strain", PALETTE[0]), ("radial", "radial_strain", PALETTE[1]),
               ("volumetric", "volumetric_strain", PALETTE[2])]  # fmt: skip
    note = "" if "radial_strain" in v else " (no radial strain in the table)"
    ax.set(title=f"strains of the specimen, compression positive{note}", xlabel="time (s)",
           ylabel="strain (%)")  # fmt: skip
    drawn = [(lab, col, c) for lab, col, c in strains if col in v and _has_data(v[col])]
    if not drawn:
        no_data(ax)
        return
    ax.axhline(0.0, color="0.35", lw=0.8)
    if "axial_sigma" in v and np.isfinite(v["axial_sigma"].to_numpy(float)).any():
        axial, sigma = 100 * v["axial_strain"].to_numpy(float), 100 * v["axial_sigma"].to_numpy(float)
        ax.fill_between(t, axial - sigma, axial + sigma, color=PALETTE[9], alpha=0.3, lw=0,
                        label="axial ± 1 standard uncertainty")  # fmt: skip
    for lab, col, c in drawn:
        _line(ax, t, 100 * v[col].to_numpy(float), c, lab)
    ax.legend(loc="best")


@styled
def volume_strain_figure(volume: pd.DataFrame, width_px: int = 900) -> Figure:
    """Panels against time (s): the volume change (mm³, from ``volume_change_mm3`` or else
    ``volume_mm3`` minus its first value; with ``volume_sigma_mm3``, a band of +- 1 standard
    uncertainty of the volume) and the axial (with ``axial_sigma``, its band), radial (if the
    column is there) and volumetric strain (%, compression positive); with
    ``measured_fraction``, a third: the share of the membrane's dots measured (%). ``volume``: a
    ``tables.VOLUME`` table (``VOLUME_RESULT``'s columns optional)."""
    v = volume.sort_values("frame")
    t = v["time_s"].to_numpy(float)
    fraction = "measured_fraction" in v
    heights = [340, 340] + ([260] if fraction else [])
    fig = new_figure(width_px, sum(heights))
    axes = fig.subplots(len(heights), 1, height_ratios=heights)
    _volume_panel(axes[0], v, t)
    _strain_panel(axes[1], v, t)
    if fraction:
        ax = axes[2]
        share = 100 * v["measured_fraction"].to_numpy(float)
        ax.set(title="membrane dots measured (the others filled from their neighbours)", xlabel="time (s)",
               ylabel="measured (%)")  # fmt: skip
        if _has_data(share):
            _line(ax, t, share, PALETTE[2])
            ax.set_ylim(min(np.nanmin(share) - 5, 95), 100.5)
        else:
            no_data(ax)
    if _has_data(t) and np.nanmax(t) > np.nanmin(t):  # the panels share the test's time span
        for ax in axes:
            ax.set_xlim(np.nanmin(t), np.nanmax(t))
    return fig


# --------------------------------------------------------------------------- bars


def draw_bars(
    ax: Axes,
    labels: Sequence[str],
    stacks: Sequence[tuple[str, np.ndarray, str]],
    *,
    title: str = "",
    ylabel: str = "",
    annotate: Sequence[str] | None = None,
    sublabels: Sequence[str] | None = None,
    hline: tuple[str, float] | None = None,
) -> None:
    """One bar per label, stacked from ``stacks`` (legend name or '', values per label,
    colour), NaN drawn as nothing. ``annotate``: text above each bar; ``sublabels``: a second
    line under each label; ``hline``: (legend label, y) of a dashed reference line. Labels too
    long for their slot are turned upright; a legend of the named stacks and the line sits
    right of the panel."""
    ax.set(title=title, ylabel=ylabel)
    ax.grid(axis="x", visible=False)
    if not labels or not stacks:
        no_data(ax)
        return
    x = np.arange(len(labels), dtype=float)
    top = np.zeros(len(labels))
    for name, values, colour in stacks:
        v = np.clip(np.nan_to_num(np.asarray(values, float)), 0, None)
        ax.bar(x, v, BAR_WIDTH, bottom=top, color=colour, label=name or None)
        top += v
    subs = list(sublabels) if sublabels is not None else [""] * len(labels)
    ticks = [f"{lab}\n{s}" if s else str(lab) for lab, s in zip(labels, subs, strict=True)]
    root = ax.figure.figure  # the figure itself (or, were ax in a subfigure, the whole one)
    slot_px = root.get_figwidth() * root.dpi * 0.8 / len(labels)
    upright = max(len(str(lab)) for lab in labels) * TICK_CHAR_PX > slot_px
    ax.set_xticks(x, ticks, rotation=90 if upright else 0)
    ax.set_xlim(-0.6, len(labels) - 0.4)
    if annotate is not None:
        for k, text in enumerate(annotate):
            ax.annotate(text, (x[k], top[k]), xytext=(0, 2), textcoords="offset points", ha="center",
                        va="bottom", fontsize=7)  # fmt: skip
    hi = max(float(top.max(initial=0.0)), hline[1] if hline is not None else 0.0)
    ax.set_ylim(0.0, hi * HEADROOM if hi > 0 else 1.0)
    if hline is not None:
        ax.axhline(hline[1], color="0.1", lw=1.0, ls="--", label=hline[0])
    if any(name for name, _, _ in stacks) or hline is not None:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)


# --------------------------------------------------------------------------- reconstruction quality


def _per_frame_errors(quality: dict) -> tuple[np.ndarray, np.ndarray]:
    """(frames, mean reprojection px) of ``quality``'s ``per_frame`` (or else ``frames``)
    entries that have both, sorted by frame."""
    entries = [
        f
        for f in quality.get("per_frame") or quality.get("frames") or []
        if isinstance(f, dict) and "frame" in f and "mean_reprojection_px" in f
    ]
    fr = np.array([number(f["frame"]) for f in entries], float)
    err = np.array([number(f["mean_reprojection_px"]) for f in entries], float)
    order = np.argsort(fr)
    return fr[order], err[order]


@styled
def reprojection_figure(quality: dict, width_px: int = 900) -> Figure:
    """Mean reprojection error (px) per camera as bars, labelled with the observations used and
    dropped, the mean over all cameras as a dashed line; below, if the entries of ``quality``'s
    ``per_frame`` (or else ``frames``) list have ``frame`` and ``mean_reprojection_px``, that
    error against the frame. ``quality``: the ``quality.json`` document; absent keys and NaN are
    drawn as no data."""
    per_camera = quality.get("per_camera") or {}
    names = sorted(per_camera)
    err = np.array([number(per_camera[n].get("mean_reprojection_px")) for n in names], float)
    used = [number(per_camera[n].get("observations_used")) for n in names]
    dropped = [number(per_camera[n].get("observations_dropped")) for n in names]
    sub = [
        f"{u:.0f}/{d:.0f}" if np.isfinite(u) and np.isfinite(d) else ""
        for u, d in zip(used, dropped, strict=True)
    ]
    mean = number(quality.get("mean_reprojection_px"))
    frames, per_frame = _per_frame_errors(quality)
    heights = [PANEL_PX["wide"]] + ([PANEL_PX["line"]] if len(frames) else [])
    fig = new_figure(width_px, sum(heights))
    axes = np.atleast_1d(fig.subplots(len(heights), 1, height_ratios=heights))
    draw_bars(
        axes[0],
        names,
        [("", err, PALETTE[0])],
        title="mean reprojection error per camera (under each camera: observations used/dropped)",
        ylabel="reprojection error (px)",
        annotate=[f"{e:.3f}" if np.isfinite(e) else "n/a" for e in err],
        sublabels=sub,
        hline=("mean, all cameras", mean) if np.isfinite(mean) else None,
    )
    left_out = quality.get("cameras_left_out") or {}
    note = f" (left out: {', '.join(sorted(left_out))}; why: quality.json)" if left_out else ""
    axes[0].set_xlabel("camera" + note)
    if len(frames):
        ax = axes[1]
        ax.set(title="mean reprojection error per frame, all cameras", xlabel="frame",
               ylabel="reprojection error (px)")  # fmt: skip
        if _has_data(per_frame):
            _line(ax, frames, per_frame, PALETTE[0])
        else:
            no_data(ax)
    return fig


# --------------------------------------------------------------------------- tracking


def _reported_share_panel(ax: Axes, t: pd.DataFrame, layout: MembraneLayout) -> None:
    """The share (%) of the kit's membrane dots and of the other targets reported per frame."""
    ax.set(title=f"share of targets reported per frame, all cameras (kit: {layout.describe()})",
           xlabel="frame", ylabel="reported (%)")  # fmt: skip
    membrane = layout.is_membrane(t["id"].to_numpy())
    reported = (t["reason"] == "").to_numpy()
    groups = ((f"membrane dots ({membrane.sum()} target-frames)", membrane, REPORTED),
              (f"other targets ({(~membrane).sum()} target-frames)", ~membrane, PALETTE[0]))  # fmt: skip
    for label, mask, colour in groups:
        if mask.any():
            share = pd.Series(reported[mask], index=t["frame"].to_numpy()[mask]).groupby(level=0).mean()
            _line(ax, share.index.to_numpy(float), 100 * share.to_numpy(float), colour, label)
    ax.set_ylim(top=100.5)
    ax.legend(loc="lower left")


def _losses_panel(ax: Axes, counts: pd.DataFrame, reasons: list[str], colour: dict[str, str]) -> None:
    """The targets not reported per frame, one line per reason."""
    ax.set(title="targets not reported per frame, by reason (all cameras)", xlabel="frame",
           ylabel="targets not reported")  # fmt: skip
    if not reasons:  # nothing lost: say so rather than "no data"
        no_data(ax, "every target reported in every frame")
        return
    frames = counts.index.to_numpy(float)
    ax.axhline(0.0, color="0.35", lw=0.8)
    for r in reasons:
        _line(ax, frames, counts[r].to_numpy(float), colour[r], r)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, title="reason")


@styled
def tracking_figure(tracks: pd.DataFrame, layout: MembraneLayout, width_px: int = 900) -> Figure:
    """Three panels over all cameras: the share of the kit's membrane dots (``layout``) and of
    the other targets reported per frame (%); the targets not reported per frame by reason; the
    target-frames not reported per camera over the test, stacked by reason. ``tracks``: a
    ``tables.TRACKS`` table (reason '' when reported); a row repeated (a frame two chunks share)
    is counted once."""
    if tracks.empty:
        fig = new_figure(width_px, PANEL_PX["line"])
        ax = fig.subplots()
        ax.set(title="share of targets reported per frame", xlabel="frame", ylabel="reported (%)")
        no_data(ax, "no tracking data")
        return fig
    t = tracks[["camera", "frame", "id", "reason"]].drop_duplicates(["camera", "frame", "id"], keep="last")
    t = t.assign(reason=t["reason"].fillna("").astype(str), camera=t["camera"].astype(str))
    counts = pd.crosstab(t["frame"], t["reason"])
    reasons = [r for r in LOSS_REASONS if r in counts] + sorted(set(counts) - set(LOSS_REASONS) - {""})
    colour = {r: REASON_COLOURS.get(r, OTHER_REASON) for r in reasons}
    heights = [PANEL_PX["line"], PANEL_PX["line"], PANEL_PX["bars"]]
    fig = new_figure(width_px, sum(heights))
    axes = fig.subplots(3, 1, height_ratios=heights)
    _reported_share_panel(axes[0], t, layout)
    _losses_panel(axes[1], counts, reasons, colour)
    per_cam = pd.crosstab(t["camera"], t["reason"])
    cams = [str(c) for c in per_cam.index]
    lost = per_cam.drop(columns=[""], errors="ignore").sum(axis=1).to_numpy(float)
    stacks = [(r, per_cam[r].to_numpy(float), colour[r]) for r in reasons]
    flagged = large_losses(t)["camera"].value_counts()
    draw_bars(
        axes[2],
        cams,
        stacks or [("", np.zeros(len(cams)), PALETTE[0])],
        title="target-frames not reported per camera over the test, by reason "
        f"(under each camera: frames with large losses, below {LARGE_LOSS_SHARE:.0%} of its best frame)",
        ylabel="target-frames",
        annotate=[f"{v:.0f}" for v in lost],
        sublabels=[f"{flagged.get(c, 0)} flagged" for c in cams],
    )
    axes[2].set_xlabel("camera")
    return fig


def run_report_figures(
    *,
    volume: str | Path,
    strains: str | Path,
    quality: str | Path,
    tracking: str | Path,
    labels: str | Path,
    kit: str | Path,
    volume_strain_png: str | Path,
    strain_maps_png: str | Path,
    reprojection_png: str | Path,
    tracking_png: str | Path,
    cameras_png: str | Path,
    report_cfg: dict,
) -> None:
    """Rule report_figures: the report's PNG figures of one test from its ``volume``,
    ``strains``, ``quality`` (the test's ``quality.json``), ``tracking`` and ``labels``, with the
    membrane grid of the kit folder ``kit``: volume and strains (:func:`volume_strain_figure`),
    local strain maps at ``strain_map_frames`` (``report_cfg``: the config's ``report`` section,
    :class:`ReportConfig`) frames spread over the test
    (:func:`~triaxtrack.report.maps.strain_maps_figure`), reprojection error
    (:func:`reprojection_figure`), tracking losses (:func:`tracking_figure`) and footage quality
    per camera (:func:`triaxtrack.camera_report.camera_quality_figure`). Prints the kit's grid,
    the per-camera quality table, the frames mapped and the files written."""
    layout = membrane_layout(load_kit_design(kit))
    print(f"kit: {layout.describe()}")
    vol = read_table(volume, VOLUME)
    local = read_table(strains, STRAINS)
    report = read_quality(quality)
    tracks = read_table(tracking, TRACKS)
    cameras = camera_quality(tracks, read_table(labels, LABELS))
    print(cameras.to_string(index=False))
    frames = chosen_frames(local["frame"].unique(), ReportConfig.from_dict(report_cfg).strain_map_frames)
    print(f"strain maps at frames {frames}")
    save_figure(volume_strain_figure(vol), volume_strain_png)
    save_figure(strain_maps_figure(local, layout, frames), strain_maps_png)
    save_figure(reprojection_figure(report), reprojection_png)
    save_figure(tracking_figure(tracks, layout), tracking_png)
    save_figure(camera_quality_figure(cameras), cameras_png)
    written = (volume_strain_png, strain_maps_png, reprojection_png, tracking_png, cameras_png)
    print(f"figures written: {', '.join(str(path) for path in written)}")
