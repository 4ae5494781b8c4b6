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

Standard uncertainties (1 sigma, ``*_sigma_*``): the log's load noise (estimated from the log's
second differences) through interpolation and zeroing, the clock offset's uncertainty times the
load's rate, the measured volume's ``volume_sigma_mm3`` (the mean area's relative uncertainty;
the sections are given the same relative uncertainty, which is an approximation: their own
error is not yet measured), the height's frame-to-frame scatter for the strain.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import pandas as pd

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
    def from_dict(d: dict) -> StressConfig:
        known = {f.name for f in fields(StressConfig)}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"stress: unknown settings {sorted(unknown)}; known: {sorted(known)}")
        d = dict(d)
        if d.get("search_s") is not None:
            d["search_s"] = (float(d["search_s"][0]), float(d["search_s"][1]))
        return StressConfig(**d)


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


def stress_strain(
    volume: pd.DataFrame,
    sections: pd.DataFrame,
    log: pd.DataFrame,
    offset_s: float,
    design: dict,
    config: StressConfig = StressConfig(),
    offset_sigma_s: float = 0.0,
) -> pd.DataFrame:
    """Stress and strain per processed frame (the :data:`~triaxtrack.tables.STRESS_STRAIN`
    columns; the module docstring says how).

    ``volume``: volume.parquet (VOLUME_RESULT); ``sections``: :func:`section_areas`' table;
    ``log``: :func:`read_load_frame_log`'s table; ``offset_s``: log time at test time 0;
    ``design``: the kit design (``specimen.diameter``, ``height``, ``membrane_thickness``).
    A frame without a volume or outside the log has NaN and its ``reason``.
    """
    spec = design["specimen"]
    d0, h0 = float(spec["diameter"]), float(spec["height"])
    t_m = (
        float(spec["membrane_thickness"])
        if config.membrane_thickness_mm is None
        else config.membrane_thickness_mm
    )
    a0 = np.pi * d0**2 / 4
    v0_nominal = a0 * h0
    vol = volume.sort_values("frame").reset_index(drop=True)
    sec = sections.set_index("frame").reindex(vol["frame"]).reset_index(drop=True)
    t = vol["time_s"].to_numpy(float)
    log_t = log["log_time_s"].to_numpy(float)
    tl = t + offset_s
    inside = (tl >= log_t[0]) & (tl <= log_t[-1])

    def at(col: str, times: np.ndarray) -> np.ndarray:
        v = log[col].to_numpy(float)
        if not np.isfinite(v).any():
            return np.full(len(times), np.nan)
        return np.interp(times, log_t, v, left=np.nan, right=np.nan)

    # zeroing
    height = vol["height_mm"].to_numpy(float)
    v_mm3 = vol["volume_mm3"].to_numpy(float)
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
    tz = np.array([t_zero + offset_s])
    window = (log_t <= tz[0]) & (log_t >= tz[0] - config.zero_window_s)
    n_zero = int(window.sum())

    def zero(col: str) -> float:
        """The log's reading at the zero time: the mean over the window (the specimen at rest, so
        a load rising just after the zero time does not leak into it), or interpolated there."""
        if config.zero_window_s > 0 and n_zero >= 2:
            return float(np.mean(log[col].to_numpy(float)[window]))
        return float(at(col, tz)[0])

    f_zero, d_zero, g_zero = zero("axial_load_n"), zero("axial_displacement_mm"), zero("volume_change_mm3")

    load = at("axial_load_n", tl)
    force = load - f_zero
    ea = (h_zero - height) / h_zero
    ev = (v_zero - v_mm3) / v_zero
    ea_log = (at("axial_displacement_mm", tl) - d_zero) / h0
    ev_gauge = (at("volume_change_mm3", tl) - g_zero) / v0_nominal
    area_mean = v_mm3 / height
    area_std = a0 * (1 - np.nan_to_num(ev_gauge, nan=0.0)) / (1 - ea_log)

    def corrections(strain: np.ndarray, area: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        membrane = 4 * config.membrane_modulus_kpa * t_m * strain / d0
        share = np.clip(strain / FILTER_PAPER_FULL_STRAIN, 0, 1)
        paper = 1000 * config.filter_paper_kn_per_m * np.pi * d0 / area * share  # kN/m x mm / mm^2 -> kPa
        return membrane, paper

    membrane, paper = corrections(ea, area_mean)
    soil_force = force - (membrane + paper) * area_mean / 1000
    q_mean = 1000 * soil_force / area_mean
    q_mid = 1000 * soil_force / sec["area_mid_mm2"].to_numpy(float)
    q_min = 1000 * soil_force / sec["area_min_mm2"].to_numpy(float)
    m_std, p_std = corrections(ea_log, area_std)
    q_std = 1000 * force / area_std - m_std - p_std
    cell = at("cell_pressure_kpa", tl)
    pore = at("pore_pressure_kpa", tl)

    # uncertainties
    sig_f = noise_sigma(log["axial_load_n"].to_numpy(float))
    at_rest = config.zero_window_s > 0 and n_zero >= 2
    zero_share = 1 / np.sqrt(n_zero) if at_rest else _interp_weights(tz, log_t)[0]
    sig_force = sig_f * np.sqrt(_interp_weights(tl, log_t) ** 2 + zero_share**2)
    rate = np.gradient(load, t) if len(t) > 1 else np.zeros_like(t)
    sig_force = np.sqrt(sig_force**2 + (rate * offset_sigma_s) ** 2)
    rel_area = vol["volume_sigma_mm3"].to_numpy(float) / v_mm3
    rel_area = np.where(np.isfinite(rel_area), rel_area, 0.0)

    def q_sigma(q: np.ndarray, area: np.ndarray) -> np.ndarray:
        return np.sqrt((1000 * sig_force / area) ** 2 + (q * rel_area) ** 2)

    sig_q_mean = q_sigma(q_mean, area_mean)
    sig_d = noise_sigma(log["axial_displacement_mm"].to_numpy(float))
    sig_ea = noise_sigma(height) * np.sqrt(2) / h_zero if finite.sum() >= 5 else np.nan
    with np.errstate(divide="ignore", invalid="ignore"):
        secant = np.where(ea > config.secant_min_strain, q_mean / ea, np.nan)
        secant_sigma = np.abs(secant) * np.sqrt((sig_q_mean / q_mean) ** 2 + (sig_ea / ea) ** 2)
    tangent, tangent_sigma = local_slope(ea, q_mean, config.tangent_frames, config.tangent_min_strain)
    sig_cell = noise_sigma(log["cell_pressure_kpa"].to_numpy(float))
    sig_pore = noise_sigma(log["pore_pressure_kpa"].to_numpy(float))

    reason = np.where(~finite, "no volume", np.where(~inside, "outside the load-frame log", ""))
    reason = np.where(
        (reason == "") & ~np.isfinite(sec["area_mid_mm2"].to_numpy(float)), "no sections", reason
    )
    out = pd.DataFrame({
        "frame": vol["frame"].to_numpy(np.int64), "time_s": t, "log_time_s": tl,
        "axial_strain": ea, "volumetric_strain": ev, "axial_strain_log": ea_log,
        "volumetric_strain_gauge": ev_gauge,
        "height_mm": height, "volume_mm3": v_mm3, "axial_load_n": load, "force_n": force,
        "soil_force_n": soil_force,
        "cell_pressure_kpa": cell, "pore_pressure_kpa": pore,
        "area_mean_mm2": area_mean, "area_mid_mm2": sec["area_mid_mm2"].to_numpy(float),
        "area_min_mm2": sec["area_min_mm2"].to_numpy(float), "area_standard_mm2": area_std,
        "membrane_kpa": membrane, "filter_paper_kpa": paper,
        "q_mean_kpa": q_mean, "q_mean_sigma_kpa": sig_q_mean,
        "q_mid_kpa": q_mid, "q_mid_sigma_kpa": q_sigma(q_mid, sec["area_mid_mm2"].to_numpy(float)),
        "q_min_kpa": q_min, "q_min_sigma_kpa": q_sigma(q_min, sec["area_min_mm2"].to_numpy(float)),
        "q_standard_kpa": q_std,
        "q_standard_sigma_kpa": np.sqrt((1000 * sig_force / area_std) ** 2 + (q_std * sig_d / h0) ** 2),
        "p_kpa": cell + q_mean / 3, "p_eff_kpa": cell - pore + q_mean / 3,
        "p_sigma_kpa": np.sqrt(sig_cell**2 + (sig_q_mean / 3) ** 2),
        "p_eff_sigma_kpa": np.sqrt(sig_cell**2 + sig_pore**2 + (sig_q_mean / 3) ** 2),
        "axial_strain_sigma": np.full(len(t), sig_ea),
        "e_secant_kpa": secant, "e_secant_sigma_kpa": secant_sigma,
        "e_tangent_kpa": tangent, "e_tangent_sigma_kpa": tangent_sigma,
        "reason": reason,
    })  # fmt: skip
    bad = out["reason"] != ""
    value_cols = [c for c in out.columns if c not in ("frame", "time_s", "log_time_s", "reason")]
    out.loc[bad & ~inside, value_cols] = np.nan
    out.attrs["zero_time_s"] = t_zero
    return out
