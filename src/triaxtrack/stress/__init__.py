"""Stress and strain from a load-frame log on the measured specimen (issue 18).

* :mod:`~triaxtrack.stress.log`: reading the log as test.yaml maps it (:func:`read_load_frame_log`);
* :mod:`~triaxtrack.stress.clock`: the log's clock offset from the displacements
  (:func:`estimate_clock_offset`);
* :mod:`~triaxtrack.stress.sections`: mid-height and smallest horizontal sections of the measured
  soil surface (:func:`section_areas`);
* :mod:`~triaxtrack.stress.compute`: q on each area, the lab's standard q, corrections, p, p',
  moduli and uncertainties (:func:`stress_strain`);
* :func:`measure_stress`: all of it for one test; :func:`run_stress_strain`: the workflow's
  stage, from the files to the table and the clock report.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from triaxtrack.jsonfile import write_json
from triaxtrack.kit import load_kit_design, target_table
from triaxtrack.kit_design import KitDesign
from triaxtrack.stress.clock import ClockEstimate, estimate_clock_offset, offset_warning
from triaxtrack.stress.compute import StressConfig, noise_sigma, stress_strain
from triaxtrack.stress.log import QUANTITIES, read_load_frame_log
from triaxtrack.stress.sections import SECTION_LEVELS, SECTION_MARGIN, section_areas
from triaxtrack.tables import POINTS, STRESS_STRAIN, VOLUME_RESULT, conform, read_table, write_table
from triaxtrack.testfolder import read_test_yaml
from triaxtrack.volume.config import VolumeConfig


def measure_stress(
    test_dir: str | Path,
    test_yaml: dict,
    volume: pd.DataFrame,
    points: pd.DataFrame,
    table: pd.DataFrame,
    design: KitDesign,
    config: StressConfig | None = None,
    volume_config: VolumeConfig | None = None,
) -> tuple[pd.DataFrame, dict]:
    """The stress-strain table (:data:`~triaxtrack.tables.STRESS_STRAIN`) of a test whose
    test.yaml (``test_yaml``, a mapping) has a ``load_frame`` entry, and the clock report:
    ``estimated_offset_s``, its ``sigma_s``, ``residual_mm``, ``scale``, the ``given_offset_s``
    (None when test.yaml gives none), the ``used_offset_s`` (the given one if any, else the
    estimate) and a ``warning`` ('' or why). ``volume_config``: config ``volume``
    (membrane thickness, its model, max missing share) for the sections."""
    config = config or StressConfig()
    entry = test_yaml["load_frame"]
    log = read_load_frame_log(test_dir, entry)
    fps = float(test_yaml["fps"])
    ok = volume["height_mm"].notna()
    ref = volume["reference_frame"].dropna()
    if not ok.any() or not len(ref):
        raise ValueError(f"{test_dir}: no frame has a volume: no stress can be measured")
    h_ref = float(volume.loc[volume["frame"] == int(ref.iloc[0]), "height_mm"].iloc[0])
    estimate = estimate_clock_offset(
        log["log_time_s"].to_numpy(), log["axial_displacement_mm"].to_numpy(),
        volume.loc[ok, "time_s"].to_numpy(), h_ref - volume.loc[ok, "height_mm"].to_numpy(),
        search_s=config.search_s,
    )  # fmt: skip
    given = entry.get("clock_offset_s")
    used = estimate.offset_s if given is None else float(given)
    vs = volume_config or VolumeConfig()
    sections = section_areas(
        points, table, design, int(ref.iloc[0]), t0=vs.membrane_thickness_mm,
        thickness_model=vs.thickness_model, margin=config.section_margin,
        levels=config.section_levels, max_missing_share=vs.max_missing_share,
    )  # fmt: skip
    out = stress_strain(
        volume, sections, log, used, design, config, offset_sigma_s=estimate.sigma_s if given is None else 0.0
    )
    report = {
        "estimated_offset_s": estimate.offset_s,
        "sigma_s": estimate.sigma_s,
        "residual_mm": estimate.residual_mm,
        "scale": estimate.scale,
        "zero_mm": estimate.zero_mm,
        "frames_used": estimate.frames_used,
        "search_s": list(estimate.search_s),
        "given_offset_s": None if given is None else float(given),
        "used_offset_s": used,
        "fps": fps,
        "zero_time_s": out.attrs.get("zero_time_s"),
        "load_noise_n": noise_sigma(log["axial_load_n"].to_numpy()),
        "load_resolution_n": out.attrs.get("load_resolution_n"),
        "residual_white_mm": estimate.white_mm,
        "residual_correlated_mm": estimate.correlated_mm,
        "residual_rho": estimate.rho,
        "ols_offset_s": estimate.ols_offset_s,
        "warning": offset_warning(estimate, given, fps),
        "log_rows": len(log),
        "log_span_s": [float(log["log_time_s"].iloc[0]), float(log["log_time_s"].iloc[-1])],
    }
    return conform(out, STRESS_STRAIN, "stress_strain"), report


def run_stress_strain(
    *,
    volume: str | Path,
    points: str | Path,
    kit: str | Path,
    test_yaml: str | Path,
    stress: str | Path,
    clock: str | Path,
    stress_cfg: dict,
    volume_cfg: dict,
) -> None:
    """Rule stress_strain: :func:`measure_stress` of the test of ``test_yaml`` (its load-frame
    log, in the same folder) on its ``volume`` and ``points``, with the kit folder ``kit``
    (``stress_cfg``, ``volume_cfg``: the config's ``stress`` and ``volume`` sections). Writes the
    ``stress`` table and the ``clock`` report (JSON), and prints the report and its warning."""
    design = load_kit_design(kit)
    table, report = measure_stress(
        Path(test_yaml).parent, read_test_yaml(test_yaml), read_table(volume, VOLUME_RESULT),
        read_table(points, POINTS), target_table(design), design, StressConfig.from_dict(stress_cfg),
        VolumeConfig.from_dict(volume_cfg),
    )  # fmt: skip
    write_table(table, stress, STRESS_STRAIN)
    write_json(clock, report)
    print(json.dumps(report, indent=2))
    if report["warning"]:
        print(f"WARNING: {report['warning']}")


__all__ = [
    "QUANTITIES", "SECTION_LEVELS", "SECTION_MARGIN", "ClockEstimate", "StressConfig",
    "estimate_clock_offset", "measure_stress", "noise_sigma", "offset_warning", "read_load_frame_log",
    "run_stress_strain", "section_areas", "stress_strain",
]  # fmt: skip
