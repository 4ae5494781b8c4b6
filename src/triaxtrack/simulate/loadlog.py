"""The simulated load-frame log (issue 18): what a triaxial frame's control software records
while the simulated specimen deforms, and the stress-strain truth it implies.

The soil's deviator stress follows a hyperbolic law of the specimen's true axial strain
``ea = (H0 - H) / H0`` (Kondner): on first loading ``q = ea / (a + b ea)`` (``1/a`` the initial
Young's modulus, ``1/b`` the asymptotic deviator stress); below the largest strain reached so
far (an unloading, then the reloading back up to it) the specimen is elastic,
``q = q(ea_max) - E_ur (ea_max - ea)`` (not below 0); the loading history (holds, unload-reload
loops) is the simulation's ``loading_history``. ``q`` is the stress on the true mean area
``A = V / H`` (V the soil volume, H the height).

The log, sampled at ``rate_hz`` on its own clock (log time = test time + ``clock_offset_s``; it
starts at log time 0, so ``clock_offset_s`` of pre-roll before the first frame, and runs
``post_s`` beyond the last), holds columns as a GDS-like export names them:

* ``Axial Load (kN)``: ``(q + q_m) A + load_offset_n``, ``q_m = 4 E_m t_m ea / D0`` the
  membrane's share (ASTM D4767's membrane correction, ``membrane_modulus_kpa``, the kit's
  thickness and diameter), ``load_offset_n`` what the load cell reads before shearing (the ram's
  friction and uplift; removed by zeroing);
* ``Axial Displacement (mm)``: an external LVDT, ``lvdt_zero_mm + (H0 - H)`` (compression
  positive);
* ``Radial Pressure (kPa)``, ``Pore Pressure (kPa)``: constant cell and pore (back) pressures
  (a drained test);
* ``Back Volume (mm³)``: the volume gauge, ``volume_zero_mm3 + (V0 - V)`` (water out of the
  specimen positive);

each with Gaussian noise of its own (seeded by the simulation's seed). Times before the first
frame hold the undeformed specimen, after the last the final state.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from triaxtrack.config_section import section_from_dict
from triaxtrack.deformation import Deformation
from triaxtrack.layout import TEST_FOLDER
from triaxtrack.simulate.config import SimulationConfig, loading_progress
from triaxtrack.stress.sections import SECTION_LEVELS, SECTION_MARGIN, section_heights
from triaxtrack.tables import STRESS_TRUTH, write_table

LOG_FILE = TEST_FOLDER.load_frame_log  # the log, in the test folder
NOISE_STREAM = 18  # seed stream of the log's noise (the number: independent of the renders)
# the columns of the simulated export (GDS-like names) and what they map to (test.yaml load_frame)
LOG_COLUMNS = {
    "time": ("Time since start of test (s)", "s"),
    "axial_load": ("Axial Load (kN)", "kN"),
    "cell_pressure": ("Radial Pressure (kPa)", "kPa"),
    "pore_pressure": ("Pore Pressure (kPa)", "kPa"),
    "axial_displacement": ("Axial Displacement (mm)", "mm"),
    "volume_change": ("Back Volume (mm³)", "mm3"),
}


@dataclass(frozen=True)
class LoadFrameSimulation:
    """Settings of the simulated log (``SimulationConfig.load_frame``); kPa, N, mm, s."""

    rate_hz: float = 10.0  # the log's sampling rate
    clock_offset_s: float = 0.0  # log time minus test time (the log starts this long before frame 0)
    offset_in_test_yaml: bool = False  # write clock_offset_s into test.yaml (else the pipeline estimates it)
    post_s: float = 2.0  # logged beyond the last frame
    a_per_kpa: float = 5.0e-5  # hyperbolic law: 1/a = initial Young's modulus (20 MPa, a loose sand)
    b_per_kpa: float = 2.5e-3  # 1/b = asymptotic deviator stress (400 kPa)
    unload_modulus_kpa: float = 6.0e4  # unloading-reloading Young's modulus (3 / a)
    membrane_modulus_kpa: float = 1400.0  # latex (ASTM D4767: 1400 kPa)
    load_offset_n: float = 25.0  # load-cell reading before shearing (removed by zeroing)
    cell_pressure_kpa: float = 300.0
    pore_pressure_kpa: float = 200.0  # back pressure (drained)
    lvdt_zero_mm: float = 12.5  # the external LVDT's reading at the first frame
    volume_zero_mm3: float = 50000.0  # the volume gauge's reading at the first frame
    noise_force_n: float = 0.2  # standard deviations of the log's noise (a 5 kN load cell's 0.2 N)
    noise_displacement_mm: float = 0.002
    noise_pressure_kpa: float = 0.1
    noise_volume_mm3: float = 5.0

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> LoadFrameSimulation:
        """Settings from ``SimulationConfig.load_frame`` (ValueError naming an unknown key or a
        non-positive rate)."""
        out = section_from_dict(LoadFrameSimulation, d, "simulation.load_frame")
        if not out.rate_hz > 0 or not out.a_per_kpa > 0 or out.b_per_kpa < 0:
            raise ValueError("load_frame: rate_hz and a_per_kpa must be > 0 and b_per_kpa >= 0")
        return out


def load_frame_entry(cfg: SimulationConfig) -> dict | None:
    """The test.yaml ``load_frame`` entry of a simulated test (None without a log): the file and
    its column mapping, and ``clock_offset_s`` if ``offset_in_test_yaml``."""
    if not cfg.load_frame:
        return None
    lf = LoadFrameSimulation.from_dict(cfg.load_frame)
    entry: dict = {
        "file": LOG_FILE,
        "columns": {key: {"name": name, "unit": unit} for key, (name, unit) in LOG_COLUMNS.items()},
    }
    if lf.offset_in_test_yaml:
        entry["clock_offset_s"] = float(lf.clock_offset_s)
    return entry


def deviator_stress(lf: LoadFrameSimulation, ea: np.ndarray) -> np.ndarray:
    """Soil deviator stress q (kPa) along a history of true axial strains ``ea`` (in time
    order): the hyperbolic law on first loading, elastic (``unload_modulus_kpa``) below the
    largest strain reached so far."""
    ea = np.asarray(ea, float)
    ea_max = np.maximum.accumulate(np.maximum(ea, 0.0))
    virgin = ea_max / (lf.a_per_kpa + lf.b_per_kpa * ea_max)
    return np.maximum(virgin - lf.unload_modulus_kpa * (ea_max - ea), 0.0)


def membrane_stress(
    modulus_kpa: float, thickness_mm: float, diameter_mm: float, ea: np.ndarray
) -> np.ndarray:
    """ASTM D4767 membrane correction (kPa): ``4 E_m t_m ea / D0``, the axial stress the rubber
    membrane carries at axial strain ``ea``."""
    return 4 * modulus_kpa * thickness_mm * np.asarray(ea, float) / diameter_mm


def _state(deformation: Deformation, p: np.ndarray) -> dict[str, np.ndarray]:
    """Height, volume and the mean, mid-height and smallest section areas at progress values."""
    height = np.array([deformation.current_height(float(q)) for q in p])
    volume = np.array([deformation.soil_volume(float(q)) for q in p])
    mid = np.array([deformation.section_area(h / 2, float(q))[0] for h, q in zip(height, p, strict=True)])
    smallest = np.array([
        deformation.section_area(section_heights(0.0, h, SECTION_LEVELS, SECTION_MARGIN), float(q)).min()
        for h, q in zip(height, p, strict=True)
    ])  # fmt: skip
    return {"height_mm": height, "volume_mm3": volume, "area_mean_mm2": volume / height,
            "area_mid_mm2": mid, "area_min_mm2": smallest}  # fmt: skip


def simulate_load_frame(
    cfg: SimulationConfig, deformation: Deformation
) -> tuple[pd.DataFrame, pd.DataFrame, dict]:
    """The log (columns as :data:`LOG_COLUMNS` names them), the per-frame truth
    (:data:`~triaxtrack.tables.STRESS_TRUTH`) and the truth's settings (``loadframe.json``)."""
    lf = LoadFrameSimulation.from_dict(cfg.load_frame)
    h0, d0, t_m = deformation.height, 2 * deformation.radius, deformation.membrane_thickness
    v0 = deformation.soil_volume(0.0)
    duration = (cfg.frames - 1) / cfg.fps
    n = int(np.floor((duration + lf.post_s + lf.clock_offset_s) * lf.rate_hz)) + 1
    t_log = np.arange(max(n, 2)) / lf.rate_hz
    p = loading_progress(cfg, t_log - lf.clock_offset_s)
    s = _state(deformation, p)
    ea = (h0 - s["height_mm"]) / h0
    q = deviator_stress(lf, ea)
    force = (q + membrane_stress(lf.membrane_modulus_kpa, t_m, d0, ea)) * s[
        "area_mean_mm2"
    ] / 1000 + lf.load_offset_n
    rng = np.random.default_rng([cfg.seed, NOISE_STREAM])
    m = len(t_log)
    sig_p = lf.noise_pressure_kpa
    log = pd.DataFrame({
        LOG_COLUMNS["time"][0]: np.round(t_log, 3),
        LOG_COLUMNS["axial_load"][0]: np.round((force + lf.noise_force_n * rng.standard_normal(m)) / 1000, 7),
        LOG_COLUMNS["cell_pressure"][0]: np.round(lf.cell_pressure_kpa + sig_p * rng.standard_normal(m), 3),
        LOG_COLUMNS["pore_pressure"][0]: np.round(lf.pore_pressure_kpa + sig_p * rng.standard_normal(m), 3),
        LOG_COLUMNS["axial_displacement"][0]: np.round(
            lf.lvdt_zero_mm + (h0 - s["height_mm"]) + lf.noise_displacement_mm * rng.standard_normal(m), 5),
        LOG_COLUMNS["volume_change"][0]: np.round(
            lf.volume_zero_mm3 + (v0 - s["volume_mm3"]) + lf.noise_volume_mm3 * rng.standard_normal(m), 2),
    })  # fmt: skip
    log.insert(0, "Stage Number", 1)
    frames = np.arange(cfg.frames)
    # the truth at the frames: the same law, along the history up to each frame
    pf = loading_progress(cfg, frames / cfg.fps)
    sf = _state(deformation, pf)
    eaf = (h0 - sf["height_mm"]) / h0
    # q at a frame from the strain history sampled finely enough to catch every turning point
    t_fine = np.union1d(frames / cfg.fps, np.asarray(cfg.loading_history or [[0, 0]], float)[:, 0] * duration)
    p_fine = loading_progress(cfg, t_fine)
    h_fine = h0 * (1 - deformation.axial_strain * p_fine)  # current_height, vectorised
    q_fine = deviator_stress(lf, (h0 - h_fine) / h0)
    qf = np.interp(frames / cfg.fps, t_fine, q_fine)
    force_soil = qf * sf["area_mean_mm2"]  # N x 1000 (kPa mm^2 = mN)
    truth = pd.DataFrame({
        "frame": frames.astype(np.int64), "time_s": frames / cfg.fps, "axial_strain": eaf,
        "volumetric_strain": (v0 - sf["volume_mm3"]) / v0, "height_mm": sf["height_mm"],
        "volume_mm3": sf["volume_mm3"], "area_mean_mm2": sf["area_mean_mm2"],
        "area_mid_mm2": sf["area_mid_mm2"], "area_min_mm2": sf["area_min_mm2"],
        "soil_force_n": force_soil / 1000, "q_mean_kpa": qf, "q_mid_kpa": force_soil / sf["area_mid_mm2"],
        "q_min_kpa": force_soil / sf["area_min_mm2"], "cell_pressure_kpa": lf.cell_pressure_kpa,
        "pore_pressure_kpa": lf.pore_pressure_kpa, "p_kpa": lf.cell_pressure_kpa + qf / 3,
        "p_eff_kpa": lf.cell_pressure_kpa - lf.pore_pressure_kpa + qf / 3,
    })  # fmt: skip
    meta = {
        "clock_offset_s": lf.clock_offset_s,
        "clock_offset_frames": lf.clock_offset_s * cfg.fps,
        "file": LOG_FILE,
        "settings": asdict(lf),
        "membrane_thickness_mm": t_m,
        "diameter_mm": d0,
        "section_margin": SECTION_MARGIN,
        "section_levels": SECTION_LEVELS,
        "notes": "log time = test time + clock_offset_s; q_mean_kpa is the soil's deviator stress on the "
                 "true mean area V/H (hyperbolic law); q_mid_kpa and q_min_kpa the same force on the true "
                 "mid-height and smallest horizontal sections; the log's axial load adds the membrane's "
                 "share (ASTM D4767, membrane_modulus_kpa) and load_offset_n",
    }  # fmt: skip
    return log, truth, meta


def write_load_frame(test_dir: str | Path, settings: dict | None = None) -> None:
    """Write ``loadframe.csv``, ``truth/loadframe.json`` and ``truth/stress_strain.parquet`` of
    a simulated test: with the log's ``settings`` (``SimulationConfig.load_frame``; default
    the scene's), which must not be empty (ValueError). The log only reads the scene (the
    deformation and its history), so it can be rewritten with other settings without
    rendering again; ``offset_in_test_yaml`` is the scene's (test.yaml is written with it)."""
    from dataclasses import replace

    from triaxtrack.simulate.scene import load_scene

    test_dir = Path(test_dir)
    scene = load_scene(test_dir)
    cfg = scene.cfg if settings is None else replace(scene.cfg, load_frame=dict(settings))
    if not cfg.load_frame:
        raise ValueError(f"{test_dir}: the simulation has no load_frame settings (no log to write)")
    log, truth, meta = simulate_load_frame(cfg, scene.deformation)
    log.to_csv(test_dir / LOG_FILE, index=False)
    (test_dir / TEST_FOLDER.truth.load_frame).write_text(json.dumps(meta, indent=2))
    write_table(truth, test_dir / TEST_FOLDER.truth.stress_strain, STRESS_TRUTH)
