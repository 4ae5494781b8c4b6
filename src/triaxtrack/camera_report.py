"""How good each camera's footage is: per-camera figures for ``triaxtrack score`` and the report.

* :func:`camera_quality`: from the results alone (no truth, so for a real test too): per camera,
  the targets labelled per chunk start, the share of its target-frames that tracking reported,
  and the per-observation centroid uncertainty ``sigma_px`` (median, 95th percentile).
* :func:`score_camera_quality`: the same as reported-only score rows (``centroid_sigma_median``,
  ``centroid_sigma_p95``, ``tracked_share``; item = camera).
* :func:`camera_summary`, :func:`format_camera_summary`: one line per camera of a score table:
  coverage (min / median over its labelled frames, needs the truth), sigma_px, tracked share.
* :func:`camera_quality_figure`: the report's figure of
  :func:`camera_quality` (matplotlib).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from triaxtrack.layout import RESULTS

if TYPE_CHECKING:
    from matplotlib.figure import Figure

QUALITY_COLUMNS = [
    "camera", "labelled_frames", "labelled_median", "target_frames", "reported", "tracked_share",
    "sigma_median_px", "sigma_p95_px",
]  # fmt: skip
SUMMARY_COLUMNS = [
    "camera", "coverage_min", "coverage_median", "sigma_median_px", "sigma_p95_px", "tracked_share",
]  # fmt: skip
NOT_RECORDED = "not_recorded"  # a frame the camera has no image of: not the footage's fault


def camera_quality(tracks: pd.DataFrame, labels: pd.DataFrame | None = None) -> pd.DataFrame:
    """One row per camera (sorted): how well its footage was labelled and tracked.

    ``tracks``: a ``tables.TRACKS`` table (a row repeated in two chunks counted once);
    ``labels``: a ``tables.LABELS`` table or None. Columns: ``labelled_frames`` the frames with
    labels (chunk starts) and ``labelled_median`` the median number of targets labelled in them
    (``id > 0``; NaN without labels); ``target_frames`` the rows of its labelled targets over the
    chunks' frames (frames the camera did not record left out), ``reported`` those tracking
    reported (``reason`` ''), ``tracked_share = reported / target_frames`` (0-1);
    ``sigma_median_px``, ``sigma_p95_px`` the median and 95th percentile of the reported
    centroids' standard uncertainty ``sigma_px`` (pixels, each coordinate; NaN if none).
    """
    t = tracks[["camera", "frame", "id", "sigma_px", "reason"]].drop_duplicates(
        ["camera", "frame", "id"], keep="last"
    )
    reason = t["reason"].fillna("").astype(str)
    t = t.assign(reason=reason)[reason != NOT_RECORDED]
    labelled = set() if labels is None else set(labels["camera"].astype(str))
    cameras = sorted(set(t["camera"].astype(str)) | labelled)
    rows = []
    for cam in cameras:
        mine = t[t["camera"] == cam]
        ok = mine["reason"] == ""
        sigma = mine.loc[ok, "sigma_px"].to_numpy(float)
        sigma = sigma[np.isfinite(sigma)]
        n_lab = np.nan, np.nan
        if labels is not None:
            lab = labels[(labels["camera"] == cam) & (labels["id"] > 0)].groupby("frame").size()
            n_lab = float(len(lab)), float(lab.median()) if len(lab) else np.nan
        rows.append(dict(
            camera=cam, labelled_frames=n_lab[0], labelled_median=n_lab[1], target_frames=float(len(mine)),
            reported=float(ok.sum()), tracked_share=float(ok.mean()) if len(mine) else np.nan,
            sigma_median_px=float(np.median(sigma)) if sigma.size else np.nan,
            sigma_p95_px=float(np.quantile(sigma, 0.95)) if sigma.size else np.nan,
        ))  # fmt: skip
    return pd.DataFrame(rows, columns=QUALITY_COLUMNS)


def score_camera_quality(quality: pd.DataFrame, source: str = RESULTS.tracking) -> pd.DataFrame:
    """Reported-only score rows (``score.COLUMNS``, no tolerance) of a :func:`camera_quality`
    table, per camera: ``centroid_sigma_median``, ``centroid_sigma_p95`` (px) and
    ``tracked_share`` (0-1). A camera without reported centroids gets no sigma rows (a NaN value
    would fail the score)."""
    from triaxtrack.score_table import COLUMNS, _metric

    rows = []
    for r in quality.itertuples(index=False):
        for metric, value, unit in (
            ("centroid_sigma_median", r.sigma_median_px, "px"),
            ("centroid_sigma_p95", r.sigma_p95_px, "px"),
            ("tracked_share", r.tracked_share, ""),
        ):
            if np.isfinite(value):
                rows.append(_metric(metric, str(r.camera), float(value), unit=unit, source=source))
    return pd.DataFrame(rows, columns=COLUMNS)


def camera_summary(scores: pd.DataFrame) -> pd.DataFrame:
    """One row per camera of a score table (``score.COLUMNS``) that has per-camera rows: the
    ``coverage`` rows' minimum and median over the camera's labelled frames (items
    ``<camera>@<frame>``), and its ``centroid_sigma_median``, ``centroid_sigma_p95`` (px) and
    ``tracked_share`` (0-1); NaN where the table lacks them. Empty if it has none."""
    cov = scores[scores["metric"] == "coverage"]
    cov = cov.assign(camera=cov["item"].str.rsplit("@", n=1).str[0])
    per_cam = scores[scores["metric"].isin(["centroid_sigma_median", "centroid_sigma_p95", "tracked_share"])]
    cameras = sorted(set(cov["camera"]) | set(per_cam["item"]))
    if not cameras:
        return pd.DataFrame(columns=SUMMARY_COLUMNS)
    by_cam = cov.groupby("camera")["value"]
    wide = per_cam.pivot_table(index="item", columns="metric", values="value", aggfunc="first")
    out = pd.DataFrame({"camera": cameras})
    out["coverage_min"] = by_cam.min().reindex(cameras).to_numpy(float)
    out["coverage_median"] = by_cam.median().reindex(cameras).to_numpy(float)
    for col, metric in (("sigma_median_px", "centroid_sigma_median"), ("sigma_p95_px", "centroid_sigma_p95"),
                        ("tracked_share", "tracked_share")):  # fmt: skip
        out[col] = wide[metric].reindex(cameras).to_numpy(float) if metric in wide else np.nan
    return out[SUMMARY_COLUMNS]


def format_camera_summary(summary: pd.DataFrame) -> str:
    """The per-camera summary of :func:`camera_summary` as a text table ('' if empty)."""
    if summary.empty:
        return ""

    def num(v: float, fmt: str) -> str:
        return "-" if not np.isfinite(v) else format(v, fmt)

    lines = [
        "per camera: labelling coverage over its labelled frames, centroid uncertainty of its tracked"
        " observations, share of its labelled target-frames tracked",
        f"{'camera':<10} {'coverage min/median':>20} {'sigma_px median/p95':>20} {'tracked %':>10}",
    ]
    for r in summary.itertuples(index=False):
        cov = f"{num(r.coverage_min, '.3f')} / {num(r.coverage_median, '.3f')}"
        sig = f"{num(r.sigma_median_px, '.3f')} / {num(r.sigma_p95_px, '.3f')}"
        lines.append(f"{r.camera:<10} {cov:>20} {sig:>20} {num(100 * r.tracked_share, '.1f'):>10}")
    return "\n".join(lines)


def camera_quality_figure(quality: pd.DataFrame, width_px: int = 900) -> Figure:
    """Two panels of a :func:`camera_quality` table (matplotlib, Agg): per camera, the share of
    its labelled targets' frames that tracking reported (%; under each camera the median number
    of targets labelled per chunk start), and the reported centroids' uncertainty ``sigma_px``
    (median, and up to the 95th percentile; px)."""
    from triaxtrack.report.figures import PANEL_PX, draw_bars  # matplotlib only when drawing
    from triaxtrack.report.style import PALETTE, new_figure, report_style

    cams = quality["camera"].astype(str).tolist()
    share = 100 * quality["tracked_share"].to_numpy(float)
    med, p95 = quality["sigma_median_px"].to_numpy(float), quality["sigma_p95_px"].to_numpy(float)
    labelled = quality["labelled_median"].to_numpy(float)
    with report_style():
        fig = new_figure(width_px, 2 * PANEL_PX["bars"])
        top, bottom = fig.subplots(2, 1)
        draw_bars(
            top,
            cams,
            [("", share, PALETTE[2])],
            title="share of labelled target-frames tracked per camera (under each camera: median targets "
            "labelled per chunk start)",
            ylabel="tracked (%)",
            annotate=["n/a" if not np.isfinite(s) else f"{s:.1f}" for s in share],
            sublabels=["" if not np.isfinite(n) else f"{n:.0f}" for n in labelled],
        )
        draw_bars(
            bottom,
            cams,
            [("median", med, PALETTE[0]), ("to 95th percentile", np.clip(p95 - med, 0, None), PALETTE[9])],
            title="centroid uncertainty of the tracked observations per camera (median / 95th percentile)",
            ylabel="sigma_px (px)",
            annotate=[
                "n/a" if not np.isfinite(m) else f"{m:.2f}/{p:.2f}" for m, p in zip(med, p95, strict=True)
            ],
        )
        for ax in (top, bottom):
            ax.set_xlabel("camera")
    return fig
