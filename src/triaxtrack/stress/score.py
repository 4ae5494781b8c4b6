"""Scoring the stress stage against a simulated test's truth (``triaxtrack score``):
:func:`score_stress`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from triaxtrack.layout import RESULTS, TRUTH

Q_SIGNIFICANT = 0.1  # q is scored relative to the truth where it exceeds this share of its peak,
# in kPa elsewhere (a relative error means nothing near q = 0)


def score_stress(
    stress: pd.DataFrame,
    truth: pd.DataFrame,
    clock: dict | None,
    truth_clock: dict | None,
    tol,
    source: str = RESULTS.stress_strain,
) -> pd.DataFrame:
    """Rows of ``triaxtrack score`` (:data:`triaxtrack.score.COLUMNS`): ``clock_offset_error``
    (|estimated - true| offset in frames, tolerance ``clock_offset_frames``; from clock.json and
    truth/loadframe.json), per frame ``q_mean_error`` (|q - q_true| / q_true where q_true > 10 %
    of its peak, tolerance ``q_rel``) and ``q_mean_error_kpa`` (|q - q_true| elsewhere,
    tolerance ``q_abs_kpa``), and, reported only, the same relative errors of q on the mid-height
    section, the smallest section and the lab's standard q (each against the truth of its own
    area; the standard q against the mean-area truth), the clock offset's error in its sigmas
    and q's error in its sigmas (:func:`uncertainty_rows`). A frame the results lack fails."""
    from triaxtrack.score import COLUMNS, _metric, summarise_frames

    rows = []
    if clock is not None and truth_clock is not None:
        fps = float(clock.get("fps", np.nan))
        err = abs(float(clock["estimated_offset_s"]) - float(truth_clock["clock_offset_s"])) * fps
        rows.append(
            _metric("clock_offset_error", "all", err, tol.clock_offset_frames, "frames", RESULTS.clock)
        )
        rows.append(_metric("clock_offset_sigma", "all", float(clock["sigma_s"]) * fps, unit="frames",
                            source=RESULTS.clock))  # fmt: skip
        rows.append(
            _metric("clock_residual", "all", float(clock["residual_mm"]), unit="mm", source=RESULTS.clock)
        )
        rows.append(_metric("clock_offset_error_sigmas", "all", err / fps / float(clock["sigma_s"]),
                            unit="sigma", source=RESULTS.clock))  # fmt: skip
    m = truth.merge(stress, on="frame", how="left", suffixes=("_true", ""))
    peak = float(np.nanmax(np.abs(m["q_mean_kpa_true"]))) if len(m) else np.nan
    per_frame = []
    for r in m.itertuples(index=False):
        big = abs(r.q_mean_kpa_true) > Q_SIGNIFICANT * peak
        err = abs(r.q_mean_kpa - r.q_mean_kpa_true)
        item = f"all@{r.frame}"
        if big:
            per_frame.append(
                _metric("q_mean_error", item, err / abs(r.q_mean_kpa_true), tol.q_rel, "", source)
            )
            for name, value, true in (
                ("q_mid_error", r.q_mid_kpa, r.q_mid_kpa_true),
                ("q_min_error", r.q_min_kpa, r.q_min_kpa_true),
                ("q_standard_error", r.q_standard_kpa, r.q_mean_kpa_true),
            ):
                per_frame.append(_metric(name, item, abs(value - true) / abs(true), unit="", source=source))
        else:
            per_frame.append(_metric("q_mean_error_kpa", item, err, tol.q_abs_kpa, "kPa", source))
    rows += uncertainty_rows(m, source)
    out = [pd.DataFrame(rows, columns=COLUMNS)]
    if per_frame:
        out.append(summarise_frames(pd.DataFrame(per_frame, columns=COLUMNS)))
    return pd.concat(out, ignore_index=True)


def uncertainty_rows(m: pd.DataFrame, source: str) -> list[dict]:
    """Reported only: how honest ``q_mean_sigma_kpa`` is over the frames with a q
    (``m``: the truth merged with the results, suffix ``_true``): the RMS of error / sigma and
    the share of frames within 2 sigma (1 and 0.95 for an honest Gaussian sigma); and the same
    with the measured mean area's own error taken out (q rescaled to the true area: what the
    load, its timing and zero contribute, against the whole sigma), which tells the stress
    stage's share from the volume stage's ``volume_sigma_mm3``."""
    from triaxtrack.score import _metric

    q, qt, sig = (m[c].to_numpy(float) for c in ("q_mean_kpa", "q_mean_kpa_true", "q_mean_sigma_kpa"))
    ok = np.isfinite(q) & np.isfinite(qt) & np.isfinite(sig) & (sig > 0)
    if not ok.any():
        return []
    z = (q - qt)[ok] / sig[ok]
    area = (m["area_mean_mm2"] / m["area_mean_mm2_true"]).to_numpy(float)[ok]
    z_load = (q[ok] * area - qt[ok]) / sig[ok]
    return [
        _metric("q_mean_error_sigmas", "rms", float(np.sqrt(np.mean(z**2))), unit="sigma", source=source),
        _metric("q_mean_within_2_sigma", "share", float(np.mean(np.abs(z) < 2)), source=source),
        _metric("q_mean_error_sigmas", "rms, true area", float(np.sqrt(np.mean(z_load**2))),
                unit="sigma", source=source),
        _metric("q_mean_within_2_sigma", "share, true area", float(np.mean(np.abs(z_load) < 2)),
                source=source),
    ]  # fmt: skip


def score_stress_files(results_dir: Path, truth_dir: Path, tol) -> pd.DataFrame:
    """:func:`score_stress` of ``results_dir/stress_strain.parquet`` (and ``clock.json``) against
    ``truth_dir/stress_strain.parquet`` (and ``loadframe.json``)."""
    from triaxtrack.tables import STRESS_STRAIN, STRESS_TRUTH, read_table

    clock, truth_clock = Path(results_dir) / RESULTS.clock, Path(truth_dir) / TRUTH.load_frame
    return score_stress(
        read_table(Path(results_dir) / RESULTS.stress_strain, STRESS_STRAIN),
        read_table(Path(truth_dir) / TRUTH.stress_strain, STRESS_TRUTH),
        json.loads(clock.read_text()) if clock.exists() else None,
        json.loads(truth_clock.read_text()) if truth_clock.exists() else None,
        tol,
    )
