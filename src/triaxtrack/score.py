"""Score a results folder against a synthetic test's truth.

``score(results_dir, truth_dir, tolerances)`` compares whatever results exist (cameras now;
points, IDs and volume as the later stages land) with ``truth/`` and returns a tidy table with
one row per metric and item: ``metric``, ``item`` (a camera name or 'all'), ``value``,
``tolerance`` (NaN when only reported), ``unit``, ``passed``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import pandas as pd

from triaxtrack.optics import Camera, read_cameras


@dataclass(frozen=True)
class ScoreTolerances:
    """Pass limits (config ``score``); issue 3-5 metrics are added here as they land."""

    focal_rel: float = 0.002
    principal_point_px: float = 1.0
    camera_center_mm: float = 0.5
    camera_rotation_deg: float = 0.05

    @staticmethod
    def from_dict(d: dict | None) -> ScoreTolerances:
        d = dict(d or {})
        known = {f.name for f in fields(ScoreTolerances)}
        return ScoreTolerances(**{k: float(v) for k, v in d.items() if k in known})


def rotation_angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Angle of the rotation between two rotation matrices, degrees."""
    c = (np.trace(Ra.T @ Rb) - 1) / 2
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def _metric(metric: str, item: str, value: float, tolerance: float = np.nan, unit: str = "") -> dict:
    """One score row; it passes when within tolerance, or when only reported (no tolerance)."""
    passed = bool(np.isfinite(value) and (np.isnan(tolerance) or value <= tolerance))
    return dict(metric=metric, item=item, value=value, tolerance=tolerance, unit=unit, passed=passed)


def score_cameras(result: dict[str, Camera], truth: dict[str, Camera], tol: ScoreTolerances) -> pd.DataFrame:
    """Per-camera intrinsic and pose errors of estimated cameras against the true ones.

    A camera whose pose is the identity (intrinsics only, e.g. after calibration) is scored on
    its intrinsics alone. Cameras missing from, or unknown to, the truth fail.
    """
    rows = []
    for name, cam in sorted(result.items()):
        if name not in truth:
            rows.append(_metric("camera_unknown", name, np.nan))
            continue
        tr = truth[name]
        f_err = max(abs(cam.K[0, 0] / tr.K[0, 0] - 1), abs(cam.K[1, 1] / tr.K[1, 1] - 1))
        pp = float(np.hypot(cam.K[0, 2] - tr.K[0, 2], cam.K[1, 2] - tr.K[1, 2]))
        rows.append(_metric("focal_rel_error", name, f_err, tol.focal_rel))
        rows.append(_metric("principal_point_error", name, pp, tol.principal_point_px, "px"))
        if not (np.allclose(cam.R, np.eye(3)) and np.allclose(cam.t, 0)):
            dc = float(np.linalg.norm(cam.center - tr.center))
            rows.append(_metric("camera_center_error", name, dc, tol.camera_center_mm, "mm"))
            rot = rotation_angle_deg(cam.R, tr.R)
            rows.append(_metric("camera_rotation_error", name, rot, tol.camera_rotation_deg, "deg"))
    rows += [_metric("camera_missing", name, np.nan) for name in sorted(set(truth) - set(result))]
    return pd.DataFrame(rows, columns=["metric", "item", "value", "tolerance", "unit", "passed"])


def score(results_dir: str | Path, truth_dir: str | Path, tol: ScoreTolerances | None = None) -> pd.DataFrame:
    """Every metric that the results present in ``results_dir`` allow, against ``truth_dir``.

    ``truth_dir`` may be a test folder (its ``truth/`` is used) or the truth folder itself.
    """
    tol = tol or ScoreTolerances()
    results_dir, truth_dir = Path(results_dir), Path(truth_dir)
    if (truth_dir / "truth").is_dir():
        truth_dir = truth_dir / "truth"
    if not (truth_dir / "cameras.json").exists():
        raise ValueError(f"{truth_dir}: no truth here (cameras.json missing)")
    if not results_dir.is_dir():
        raise ValueError(f"{results_dir}: no such results folder")
    parts = []
    if (results_dir / "cameras.json").exists():
        parts.append(
            score_cameras(
                read_cameras(results_dir / "cameras.json"), read_cameras(truth_dir / "cameras.json"), tol
            )
        )
    if not parts:
        return pd.DataFrame(columns=["metric", "item", "value", "tolerance", "unit", "passed"])
    return pd.concat(parts, ignore_index=True)


def format_table(df: pd.DataFrame) -> str:
    """Human-readable score table."""
    if df.empty:
        return "nothing to score: the results folder holds none of cameras.json, points, volume"
    lines = [f"{'metric':<26} {'item':<8} {'value':>12} {'tolerance':>10} {'unit':<4} result"]
    for r in df.itertuples(index=False):
        tol = "" if pd.isna(r.tolerance) else f"{r.tolerance:.4g}"
        val = "missing" if pd.isna(r.value) else f"{r.value:.5g}"
        lines.append(
            f"{r.metric:<26} {r.item:<8} {val:>12} {tol:>10} {r.unit:<4} {'ok' if r.passed else 'FAIL'}"
        )
    lines.append(f"{int(df.passed.sum())} of {len(df)} within tolerance")
    return "\n".join(lines)
