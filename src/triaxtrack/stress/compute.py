"""Stress and strain per processed frame on the measured area (:func:`stress_strain`).

Sign conventions: compression positive (strains, q); stresses in kPa, forces in N, lengths mm.

* The log is read at each frame's time on its own clock (``time_s + offset``), linearly between
  samples.
* Zeroing at ``zero_time_s`` (test clock; default the volume's reference frame): the log's load
  then is subtracted (the ram's friction and uplift, a seating load), strains count from the
  measured height and volume then, and the log's displacement and volume gauge from their
  readings then; the log's readings "then" are its means over ``zero_window_s`` up to the zero
  time (the specimen must be at rest: a load that starts rising just after would otherwise leak
  into the zero through the interpolation), or interpolated at it when the window holds fewer
  than 2 samples.
* ``force_n`` is the zeroed load; the membrane carries ``4 E_m t_m ea / D0`` (ASTM D4767 /
  ISO 17892-9) and filter paper strips ``K_fp P / A`` (ASTM D4767: in full beyond 2 % axial
  strain, in proportion below), stresses taken on the measured mean area; ``soil_force_n`` is
  what remains; ``q_mean_kpa``, ``q_mid_kpa``, ``q_min_kpa`` it on the measured mean area
  ``V / H``, the section at mid-height and the smallest section
  (:mod:`triaxtrack.stress.sections`).
* The lab's standard ``q_standard_kpa``: the zeroed load on ``A0 (1 - ev) / (1 - ea)`` (A0 from
  the nominal diameter, ea from the log's displacement over the nominal height, ev from the
  volume gauge over the nominal volume, 0 without a gauge), less the same corrections at ea.
* ``p = sigma_3 + q / 3``, ``p' = p - u`` (on ``q_mean_kpa``); the secant modulus ``q / ea``
  and the tangent modulus (local straight line of q against ea over ``tangent_frames`` frames,
  NaN where the strain spans less than ``tangent_min_strain``).

Standard uncertainties (1 sigma, ``*_sigma_*``; :func:`force_sigma`): the log's load noise
(estimated from the log's second differences) or, when coarser, its resolution's
``step / sqrt(12)``, through interpolation and zeroing; the chord error of the straight line
between samples (:func:`interpolation_sigma`); the clock offset's uncertainty times the load's
rate; the measured volume's ``volume_sigma_mm3`` (the mean area's relative uncertainty; the
sections are given the same relative uncertainty, which is an approximation: their own error is
not yet measured), the height's frame-to-frame scatter for the strain.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

from triaxtrack.config_section import section_from_dict
from triaxtrack.kit_design import KitDesign

FILTER_PAPER_FULL_STRAIN = 0.02  # ASTM D4767: the filter-paper correction applies in full beyond 2 %


@dataclass(frozen=True)
class StressConfig:
    """Settings of the stress stage (config ``stress``; see config/README.md)."""

    membrane_modulus_kpa: float = 1400.0  # ASTM D4767's latex membrane
    membrane_thickness_mm: float | None = None  # None: the kit's
    filter_paper_kn_per_m: float = 0.0  # K_fp, load per perimeter of side drains; 0: none
    zero_time_s: float | None = None  # test clock; None: the volume's reference frame
    zero_window_s: float = 0.5  # the log's zeros: its mean over this long up to the zero time (at rest)
    tangent_frames: int = 5  # frames of the local fit for the tangent modulus (odd)
    tangent_min_strain: float = 2e-4  # the window's strain span below which no tangent is given
    secant_min_strain: float = 1e-4  # no secant modulus below this axial strain
    search_s: tuple[float, float] | None = None  # clock offsets tried; None: every overlap
    section_margin: float = 0.1
    section_levels: int = 41

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> StressConfig:
        """From the config's ``stress`` section (ValueError naming an unknown key); ``search_s``
        a ``(lo, hi)`` tuple of floats."""
        cfg = section_from_dict(StressConfig, d, "stress")
        if cfg.search_s is None:
            return cfg
        return replace(cfg, search_s=(float(cfg.search_s[0]), float(cfg.search_s[1])))


def noise_sigma(x: np.ndarray) -> float:
    """White-noise standard deviation of a sampled series from its second differences (robust:
    the MAD; var(x[i-1] - 2 x[i] + x[i+1]) = 6 sigma^2 for white noise; smooth signals add little
    at a log's rate)."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if len(x) < 5:
        return np.nan
    d2 = x[:-2] - 2 * x[1:-1] + x[2:]
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6))


def _interp_weights(t: np.ndarray, log_t: np.ndarray) -> np.ndarray:
    """sqrt(w^2 + (1 - w)^2): the share of a sample's white noise left after linear interpolation."""
    k = np.clip(np.searchsorted(log_t, t) - 1, 0, len(log_t) - 2)
    w = np.clip((t - log_t[k]) / (log_t[k + 1] - log_t[k]), 0, 1)
    return np.sqrt(w**2 + (1 - w) ** 2)


def local_slope(x: np.ndarray, y: np.ndarray, window: int, min_span: float) -> tuple[np.ndarray, np.ndarray]:
    """Slope dy/dx (and its standard error from the fit's residuals) of a straight line through
    ``window`` consecutive finite points centred on each; NaN where x spans less than ``min_span``."""
    n = len(x)
    slope = np.full(n, np.nan)
    err = np.full(n, np.nan)
    half = window // 2
    ok = np.isfinite(x) & np.isfinite(y)
    for i in range(n):
        if not ok[i]:
            continue
        sel = np.arange(max(0, i - half), min(n, i + half + 1))
        sel = sel[ok[sel]]
        if len(sel) < 3:
            continue
        xs, ys = x[sel], y[sel]
        if xs.max() - xs.min() < min_span:
            continue
        xm = xs - xs.mean()
        b = float(np.dot(xm, ys - ys.mean()) / np.dot(xm, xm))
        r = ys - ys.mean() - b * xm
        slope[i] = b
        err[i] = float(np.sqrt(np.sum(r**2) / max(len(sel) - 2, 1) / np.dot(xm, xm)))
    return slope, err


def load_resolution(x: np.ndarray) -> float:
    """The smallest step between a logged column's distinct values (its resolution: the load
    cell's and the export's digits); 0 with fewer than 2 distinct values."""
    u = np.unique(np.asarray(x, float)[np.isfinite(x)])
    if len(u) < 2:
        return 0.0
    d = np.diff(u)
    d = d[d > 1e-9 * float(np.ptp(u))]  # float fuzz of unit conversions is not a step
    return float(d.min()) if len(d) else 0.0


def interpolation_sigma(t: np.ndarray, log_t: np.ndarray, v: np.ndarray, noise: float) -> np.ndarray:
    """Standard uncertainty of a log column ``v`` read by a straight line between its samples at
    times ``t``: ``w (1 - w) (|d2_k| + |d2_k+1|) / 2``, ``d2`` the second differences at the two
    samples either side, each less its white noise (``6 noise^2`` of variance). A curvature's
    chord error is ``w (1 - w) d2 / 2`` (half the sigma); a change of rate between two samples
    spreads over both second differences and cuts the corner by up to twice the sigma at the
    change, less elsewhere: a systematic error given as a standard uncertainty."""
    v = np.asarray(v, float)
    d2 = np.zeros(len(v))
    if len(v) >= 3:
        d2[1:-1] = v[:-2] - 2 * v[1:-1] + v[2:]
        d2[0], d2[-1] = d2[1], d2[-2]  # the end samples: their neighbour's
    d2 = np.sqrt(np.maximum(np.nan_to_num(d2) ** 2 - 6 * np.nan_to_num(noise) ** 2, 0.0))
    k = np.clip(np.searchsorted(log_t, t) - 1, 0, len(log_t) - 2)
    w = np.clip((t - log_t[k]) / (log_t[k + 1] - log_t[k]), 0, 1)
    return w * (1 - w) * (d2[k] + d2[k + 1]) / 2


def _log_reader(log: pd.DataFrame):
    """``at(col, times)``: a log column read linearly between its samples (NaN outside)."""
    log_t = log["log_time_s"].to_numpy(float)

    def at(col: str, times: np.ndarray) -> np.ndarray:
        v = log[col].to_numpy(float)
        if not np.isfinite(v).any():
            return np.full(len(times), np.nan)
        return np.interp(times, log_t, v, left=np.nan, right=np.nan)

    return at


@dataclass(frozen=True)
class _Zero:
    """The zeroing: the test-clock time, the measured height and volume then, and the log's
    readings then (load, displacement, gauge) with the count of at-rest samples averaged."""

    t_s: float
    height_mm: float
    volume_mm3: float
    load_n: float
    displacement_mm: float
    gauge_mm3: float
    n_samples: int  # samples averaged (0: interpolated at the zero time)
    share: float  # the zero's share of one sample's white noise


def _zeroing(vol: pd.DataFrame, log: pd.DataFrame, offset_s: float, config: StressConfig) -> _Zero:
    """The zero time (``config.zero_time_s``, else the volume's reference frame, else its first
    measured frame) and the readings then (module docstring)."""
    t = vol["time_s"].to_numpy(float)
    height, v_mm3 = vol["height_mm"].to_numpy(float), vol["volume_mm3"].to_numpy(float)
    finite = np.isfinite(height) & np.isfinite(v_mm3)
    if config.zero_time_s is None:
        ref = vol["reference_frame"].dropna()
        k0 = (
            int(np.flatnonzero(vol["frame"].to_numpy() == int(ref.iloc[0]))[0])
            if len(ref)
            else int(np.argmax(finite))
        )
        t_zero = float(t[k0])
    else:
        t_zero = float(config.zero_time_s)
    h_zero = float(np.interp(t_zero, t[finite], height[finite])) if finite.any() else np.nan
    v_zero = float(np.interp(t_zero, t[finite], v_mm3[finite])) if finite.any() else np.nan
    log_t = log["log_time_s"].to_numpy(float)
    tz = np.array([t_zero + offset_s])
    window = (log_t <= tz[0]) & (log_t >= tz[0] - config.zero_window_s)
    at_rest = config.zero_window_s > 0 and int(window.sum()) >= 2
    at = _log_reader(log)

    def zero(col: str) -> float:
        """The mean over the window (the specimen at rest, so a load rising just after the zero
        time does not leak into it), or the reading interpolated at the zero time."""
        if at_rest:
            return float(np.mean(log[col].to_numpy(float)[window]))
        return float(at(col, tz)[0])

    n = int(window.sum()) if at_rest else 0
    share = 1 / np.sqrt(n) if at_rest else float(_interp_weights(tz, log_t)[0])
    return _Zero(t_zero, h_zero, v_zero, zero("axial_load_n"), zero("axial_displacement_mm"),
                 zero("volume_change_mm3"), n, share)  # fmt: skip


def force_sigma(
    log: pd.DataFrame, t: np.ndarray, offset_s: float, offset_sigma_s: float, zero: _Zero
) -> tuple[np.ndarray, dict]:
    """Standard uncertainty (N) of the zeroed load at the frames' times ``t`` (test clock) and
    its parts (``noise``, ``resolution``, ``interpolation``, ``timing``, per frame or scalar):
    the log's white noise (its second differences) or, when coarser, its resolution's
    ``step / sqrt(12)``, through the interpolation and the zero; the straight line's chord error
    (:func:`interpolation_sigma`); the clock offset's uncertainty times the load's rate."""
    log_t = log["log_time_s"].to_numpy(float)
    tl = t + offset_s
    f = log["axial_load_n"].to_numpy(float)
    noise = noise_sigma(f)
    step = load_resolution(f)
    white = max(np.nan_to_num(noise), step / np.sqrt(12))
    read = white * np.sqrt(_interp_weights(tl, log_t) ** 2 + zero.share**2)
    chord = interpolation_sigma(tl, log_t, f, noise)
    load = _log_reader(log)("axial_load_n", tl)
    rate = np.gradient(load, t) if len(t) > 1 else np.zeros_like(t)
    timing = np.abs(rate) * offset_sigma_s
    total = np.sqrt(read**2 + chord**2 + np.nan_to_num(timing) ** 2)
    return total, {"noise": noise, "resolution": step, "interpolation": chord, "timing": timing}


def _corrections(
    config: StressConfig, t_m: float, d0: float, strain: np.ndarray, area: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Membrane and filter-paper corrections (kPa) at axial strain ``strain`` on ``area``."""
    membrane = 4 * config.membrane_modulus_kpa * t_m * strain / d0
    share = np.clip(strain / FILTER_PAPER_FULL_STRAIN, 0, 1)
    paper = 1000 * config.filter_paper_kn_per_m * np.pi * d0 / area * share  # kN/m x mm / mm^2 -> kPa
    return membrane, paper


def _moduli(
    ea: np.ndarray, q: np.ndarray, sig_q: np.ndarray, sig_ea: float, config: StressConfig
) -> dict[str, np.ndarray]:
    """Secant and tangent Young's moduli of q against ea, with their uncertainties."""
    with np.errstate(divide="ignore", invalid="ignore"):
        secant = np.where(ea > config.secant_min_strain, q / ea, np.nan)
        secant_sigma = np.abs(secant) * np.sqrt((sig_q / q) ** 2 + (sig_ea / ea) ** 2)
    tangent, tangent_sigma = local_slope(ea, q, config.tangent_frames, config.tangent_min_strain)
    return {"e_secant_kpa": secant, "e_secant_sigma_kpa": secant_sigma,
            "e_tangent_kpa": tangent, "e_tangent_sigma_kpa": tangent_sigma}  # fmt: skip


def _mean_stress(log: pd.DataFrame, tl: np.ndarray, q: np.ndarray, sig_q: np.ndarray) -> dict:
    """Cell and pore pressures at log times ``tl``, ``p = sigma_3 + q / 3``, ``p' = p - u`` and
    their uncertainties (the log's noise and q's)."""
    at = _log_reader(log)
    cell, pore = at("cell_pressure_kpa", tl), at("pore_pressure_kpa", tl)
    sig_cell = noise_sigma(log["cell_pressure_kpa"].to_numpy(float))
    sig_pore = noise_sigma(log["pore_pressure_kpa"].to_numpy(float))
    return {"cell_pressure_kpa": cell, "pore_pressure_kpa": pore,
            "p_kpa": cell + q / 3, "p_eff_kpa": cell - pore + q / 3,
            "p_sigma_kpa": np.sqrt(sig_cell**2 + (sig_q / 3) ** 2),
            "p_eff_sigma_kpa": np.sqrt(sig_cell**2 + sig_pore**2 + (sig_q / 3) ** 2)}  # fmt: skip


def stress_strain(
    volume: pd.DataFrame,
    sections: pd.DataFrame,
    log: pd.DataFrame,
    offset_s: float,
    design: KitDesign,
    config: StressConfig = StressConfig(),
    offset_sigma_s: float = 0.0,
) -> pd.DataFrame:
    """Stress and strain per processed frame (the :data:`~triaxtrack.tables.STRESS_STRAIN`
    columns; the module docstring says how).

    ``volume``: volume.parquet (VOLUME_RESULT); ``sections``: :func:`section_areas`' table;
    ``log``: :func:`read_load_frame_log`'s table; ``offset_s``: log time at test time 0, with
    its standard uncertainty ``offset_sigma_s``; ``design``: the kit design
    (``specimen.diameter``, ``height``, ``membrane_thickness``). A frame without a volume or
    outside the log has NaN and its ``reason``. ``attrs``: ``zero_time_s``, ``load_noise_n`` and
    ``load_resolution_n`` (:func:`force_sigma`).
    """
    spec = design.specimen
    d0, h0 = float(spec.diameter), float(spec.height)
    t_m = config.membrane_thickness_mm
    t_m = float(spec.membrane_thickness) if t_m is None else t_m
    a0 = np.pi * d0**2 / 4
    vol = volume.sort_values("frame").reset_index(drop=True)
    sec = sections.set_index("frame").reindex(vol["frame"]).reset_index(drop=True)
    t = vol["time_s"].to_numpy(float)
    tl = t + offset_s
    at = _log_reader(log)
    z = _zeroing(vol, log, offset_s, config)
    height, v_mm3 = vol["height_mm"].to_numpy(float), vol["volume_mm3"].to_numpy(float)
    load = at("axial_load_n", tl)
    force = load - z.load_n
    ea = (z.height_mm - height) / z.height_mm
    ea_log = (at("axial_displacement_mm", tl) - z.displacement_mm) / h0
    ev_gauge = (at("volume_change_mm3", tl) - z.gauge_mm3) / (a0 * h0)
    area_mean = v_mm3 / height
    area_std = a0 * (1 - np.nan_to_num(ev_gauge, nan=0.0)) / (1 - ea_log)
    area_mid, area_min = sec["area_mid_mm2"].to_numpy(float), sec["area_min_mm2"].to_numpy(float)
    membrane, paper = _corrections(config, t_m, d0, ea, area_mean)
    soil_force = force - (membrane + paper) * area_mean / 1000
    m_std, p_std = _corrections(config, t_m, d0, ea_log, area_std)
    q_std = 1000 * force / area_std - m_std - p_std
    sig_force, parts = force_sigma(log, t, offset_s, offset_sigma_s, z)
    rel_area = np.nan_to_num(vol["volume_sigma_mm3"].to_numpy(float) / v_mm3, nan=0.0)

    def q_and_sigma(area: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q = 1000 * soil_force / area
        return q, np.sqrt((1000 * sig_force / area) ** 2 + (q * rel_area) ** 2)

    (q_mean, sig_q_mean), (q_mid, sig_q_mid), (q_min, sig_q_min) = (
        q_and_sigma(a) for a in (area_mean, area_mid, area_min)
    )
    finite = np.isfinite(height) & np.isfinite(v_mm3)
    sig_ea = noise_sigma(height) * np.sqrt(2) / z.height_mm if finite.sum() >= 5 else np.nan
    sig_d = noise_sigma(log["axial_displacement_mm"].to_numpy(float))
    inside = (tl >= log["log_time_s"].iloc[0]) & (tl <= log["log_time_s"].iloc[-1])
    reason = np.where(~finite, "no volume", np.where(~inside, "outside the load-frame log", ""))
    reason = np.where((reason == "") & ~np.isfinite(area_mid), "no sections", reason)
    out = pd.DataFrame({
        "frame": vol["frame"].to_numpy(np.int64), "time_s": t, "log_time_s": tl,
        "axial_strain": ea, "volumetric_strain": (z.volume_mm3 - v_mm3) / z.volume_mm3,
        "axial_strain_log": ea_log, "volumetric_strain_gauge": ev_gauge,
        "height_mm": height, "volume_mm3": v_mm3, "axial_load_n": load, "force_n": force,
        "soil_force_n": soil_force,
        "area_mean_mm2": area_mean, "area_mid_mm2": area_mid, "area_min_mm2": area_min,
        "area_standard_mm2": area_std, "membrane_kpa": membrane, "filter_paper_kpa": paper,
        "q_mean_kpa": q_mean, "q_mean_sigma_kpa": sig_q_mean,
        "q_mid_kpa": q_mid, "q_mid_sigma_kpa": sig_q_mid,
        "q_min_kpa": q_min, "q_min_sigma_kpa": sig_q_min, "q_standard_kpa": q_std,
        "q_standard_sigma_kpa": np.sqrt((1000 * sig_force / area_std) ** 2 + (q_std * sig_d / h0) ** 2),
        **_mean_stress(log, tl, q_mean, sig_q_mean),
        "axial_strain_sigma": np.full(len(t), sig_ea),
        **_moduli(ea, q_mean, sig_q_mean, sig_ea, config), "reason": reason,
    })  # fmt: skip
    value_cols = [c for c in out.columns if c not in ("frame", "time_s", "log_time_s", "reason")]
    out.loc[(reason != "") & ~inside, value_cols] = np.nan
    noise_n, resolution_n = float(parts["noise"]), float(parts["resolution"])
    out.attrs.update(zero_time_s=z.t_s, load_noise_n=noise_n, load_resolution_n=resolution_n)
    return out
