"""The score table that ``triaxtrack score`` prints: its columns (:data:`COLUMNS`), the
tolerances (config ``score``: :class:`ScoreTolerances`) and one row (:func:`_metric`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from triaxtrack.config_section import field_names, section_dict

COLUMNS = ["metric", "item", "value", "tolerance", "unit", "passed", "source"]
AT_LEAST = {"membrane_3_rays"}  # per-frame metrics whose tolerance is a minimum


@dataclass(frozen=True)
class ScoreTolerances:
    """Pass limits (config ``score``); issue 3-5 metrics are added here as they land."""

    focal_rel: float = 0.002
    principal_point_px: float = 1.0
    camera_center_mm: float = 0.5
    camera_rotation_deg: float = 0.05
    undistortion_px: float = 0.1
    wrong_id_px: float = 1.0  # a label whose centroid is farther than this from the truth is wrong
    wrong_ids: float = 0.0
    coverage: float = 0.95  # minimum share of the targets the truth says a camera sees
    cell_centroid_median_px: float = 0.05
    cell_centroid_p95_px: float = 0.15
    mean_reprojection_px: float = 0.3  # reconstruction (quality.json), all cameras and per camera
    membrane_rms_mm: float = 0.05  # 3-D error of the membrane dots against the truth
    membrane_3_rays: float = 0.9  # minimum share of the membrane dots reconstructed from 3+ rays
    id_swaps: float = 0.0  # tracked observations farther than wrong_id_px from their own truth
    membrane_kept: float = 0.95  # share of the membrane dots visible at the start still at the end
    volume_rel: float = 0.0025  # |V - V_true| / V_true at every processed frame
    volume_change_rel: float = 0.0005  # |dV - dV_true| / V0_true at every processed frame
    axial_strain: float = 0.0005  # |axial strain - true|, at every processed frame
    clock_offset_frames: float = 1.0  # |estimated - true| clock offset of the load-frame log, frames
    q_rel: float = 0.005  # |q - q_true| / q_true on the mean area, where q_true > 10 % of its peak
    q_abs_kpa: float = 1.0  # |q - q_true| on the mean area elsewhere, kPa

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> ScoreTolerances:
        """From the config's ``score`` section (ValueError naming an unknown key), as floats."""
        items = section_dict(d, "score", field_names(ScoreTolerances))
        return ScoreTolerances(**{key: float(value) for key, value in items.items()})


def _metric(
    metric: str,
    item: str,
    value: float,
    tolerance: float = np.nan,
    unit: str = "",
    source: str = "",
    minimum: bool = False,
) -> dict:
    """One score row; it passes when within tolerance (at least it, for a ``minimum``), or when
    only reported (no tolerance)."""
    within = value >= tolerance if minimum else value <= tolerance
    passed = bool(np.isfinite(value) and (np.isnan(tolerance) or within))
    return dict(
        metric=metric, item=item, value=value, tolerance=tolerance, unit=unit, passed=passed, source=source
    )
