"""Synchronising a load-frame log's clock with the test clock without trusting either: the
log's external axial displacement is matched to the measured top-cap displacement
(:func:`estimate_clock_offset`).

The offset ``tau`` is the log's time at test time 0 (log time = test time + tau). For a trial
``tau`` the log's displacement is interpolated at the processed frames' times ``t + tau`` and
fitted to the measured cap displacement by least squares with a free zero and a free scale
(the LVDT has its own zero; the frame's compliance and bedding make its travel differ from the
cap's by a few per cent); the residual's RMS is the cost. A grid over the search range (half a
frame apart) finds the basin, Brent's method within one grid step either side refines it.
A constant-rate ramp cannot fix the offset (a shift is a zero): the history's holds, changes of
rate and unload-reload loops do, and ``sigma_s`` (from the cost's curvature) says how well.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import minimize_scalar

MIN_OVERLAP = 0.8  # share of the measured frames the shifted log must cover for a trial offset


@dataclass(frozen=True)
class ClockEstimate:
    """The estimated offset (s) and how well the log then matches the measured cap."""

    offset_s: float  # log time at test time 0, s
    sigma_s: float  # its standard uncertainty (Gauss-Newton, from the residual and the slope)
    residual_mm: float  # RMS residual of the fit at the estimate, mm
    scale: float  # log displacement -> cap displacement
    zero_mm: float  # log displacement at zero cap displacement, mm
    frames_used: int
    search_s: tuple[float, float]

    def to_dict(self) -> dict:
        return asdict(self)


def _fit(d_log: np.ndarray, cap_mm: np.ndarray) -> tuple[float, float, float]:
    """Least-squares cap = scale (d_log - zero): (rms, scale, zero)."""
    a = np.c_[d_log, np.ones_like(d_log)]
    coef, *_ = np.linalg.lstsq(a, cap_mm, rcond=None)
    res = cap_mm - a @ coef
    scale = float(coef[0])
    zero = float(-coef[1] / scale) if scale != 0 else np.nan
    return float(np.sqrt(np.mean(res**2))), scale, zero


def _cost(tau: float, log_t: np.ndarray, log_d: np.ndarray, t: np.ndarray, cap: np.ndarray) -> float:
    ts = t + tau
    inside = (ts >= log_t[0]) & (ts <= log_t[-1])
    if inside.sum() < max(MIN_OVERLAP * len(t), 3):
        return np.inf
    return _fit(np.interp(ts[inside], log_t, log_d), cap[inside])[0]


def estimate_clock_offset(
    log_time_s: np.ndarray,
    log_displacement_mm: np.ndarray,
    time_s: np.ndarray,
    cap_displacement_mm: np.ndarray,
    search_s: tuple[float, float] | None = None,
    step_s: float | None = None,
) -> ClockEstimate:
    """Offset tau (s, log time = test time + tau) that best matches the log's displacement
    (``log_time_s``, ``log_displacement_mm``: (M,), the log's clock) to the measured top-cap
    displacement (``time_s``, ``cap_displacement_mm``: (N,), test clock, compression positive;
    NaN rows are left out).

    ``search_s``: the range of tau tried (default: every shift that keeps MIN_OVERLAP of the
    frames inside the log); ``step_s`` the grid's step (default half the median frame interval).
    ValueError when fewer than 3 frames are finite or no trial offset overlaps enough.
    """
    log_t = np.asarray(log_time_s, float)
    log_d = np.asarray(log_displacement_mm, float)
    ok = np.isfinite(time_s) & np.isfinite(cap_displacement_mm)
    t = np.asarray(time_s, float)[ok]
    cap = np.asarray(cap_displacement_mm, float)[ok]
    good = np.isfinite(log_t) & np.isfinite(log_d)
    log_t, log_d = log_t[good], log_d[good]
    if len(t) < 3 or len(log_t) < 2:
        raise ValueError("clock offset: fewer than 3 measured frames or 2 log samples")
    if step_s is None:
        step_s = 0.5 * float(np.median(np.diff(t))) if len(t) > 1 else 0.05
    if search_s is None:
        span = t[-1] - t[0]
        search_s = (log_t[0] - t[0] - (1 - MIN_OVERLAP) * span, log_t[-1] - t[-1] + (1 - MIN_OVERLAP) * span)
    lo, hi = float(search_s[0]), float(search_s[1])
    grid = np.arange(lo, hi + step_s / 2, step_s)
    costs = np.array([_cost(tau, log_t, log_d, t, cap) for tau in grid])
    if not np.isfinite(costs).any():
        raise ValueError(
            f"clock offset: no offset in [{lo:.2f}, {hi:.2f}] s puts {MIN_OVERLAP:.0%} of the frames "
            "inside the log"
        )
    k = int(np.nanargmin(costs))
    res = minimize_scalar(
        _cost,
        bounds=(grid[k] - step_s, grid[k] + step_s),
        args=(log_t, log_d, t, cap),
        method="bounded",
        options={"xatol": 1e-5},
    )
    tau = float(res.x) if res.fun <= costs[k] else float(grid[k])
    ts = t + tau
    inside = (ts >= log_t[0]) & (ts <= log_t[-1])
    d = np.interp(ts[inside], log_t, log_d)
    rms, scale, zero = _fit(d, cap[inside])
    # Gauss-Newton: sigma_tau^2 = s^2 / sum (scale d'(t))^2, the slope from the log
    slope = (
        scale * np.gradient(np.interp(ts[inside], log_t, log_d), ts[inside])
        if inside.sum() > 2
        else np.array([0.0])
    )
    info = float(np.sum(slope**2))
    n = int(inside.sum())
    dof = max(n - 3, 1)
    s = rms * np.sqrt(n / dof)
    sigma = float(s / np.sqrt(info)) if info > 0 else np.inf
    return ClockEstimate(tau, sigma, rms, scale, zero, n, (lo, hi))


def offset_warning(estimate: ClockEstimate, given_s: float | None, fps: float) -> str:
    """'' or a warning when the given offset and the estimate differ by more than one frame."""
    if given_s is None:
        return ""
    diff = estimate.offset_s - float(given_s)
    if abs(diff) * fps > 1:
        return (
            f"the load-frame log's clock_offset_s {given_s:.3f} s in test.yaml differs from the offset "
            f"estimated from the displacements, {estimate.offset_s:.3f} +- {estimate.sigma_s:.3f} s, by "
            f"{diff:+.3f} s ({diff * fps:+.2f} frames): check the log's clock or the offset"
        )
    return ""
