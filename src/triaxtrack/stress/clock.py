"""Synchronising a load-frame log's clock with the test clock without trusting either: the
log's external axial displacement is matched to the measured top-cap displacement
(:func:`estimate_clock_offset`).

The offset ``tau`` is the log's time at test time 0 (log time = test time + tau). For a trial
``tau`` the log's displacement is interpolated at the processed frames' times ``t + tau`` and
fitted to the measured cap displacement by least squares with a free zero and a free scale
(the LVDT has its own zero; the frame's compliance and bedding make its travel differ from the
cap's by a few per cent). A constant-rate ramp cannot fix the offset (a shift is a zero): the
history's holds, changes of rate and unload-reload loops do.

* The log is interpolated by a monotone cubic (PCHIP), not a straight line between samples: a
  straight line cuts a change of rate that falls between two samples, and the fit moves the
  offset to follow the cut corner (on exact heights of the stress test, 0.4-0.7 ms with a line,
  0.05-0.1 ms with PCHIP).
* The residuals are not white: consecutive frames read the log between the same two samples
  (its noise is shared) and the measured cap's errors persist over seconds (a few micrometres
  per chunk or loading phase; the information on ``tau`` sits in the steps at changes of rate,
  where a persistent error looks like a shift). The offset is therefore fitted twice: by
  ordinary least squares (a grid half a frame apart finds the basin, Brent's method refines it),
  then, with an error model fitted to those residuals (white noise plus a first-order
  autoregressive part, from their autocorrelation over processed frames), by generalised least
  squares (the residuals whitened by the model's Kalman innovations), which weighs the sharp
  changes of rate over slow drifts. ``sigma_s`` is the generalised fit's Gauss-Newton
  uncertainty with the zero and the scale fitted alongside (they take up much of a shift's
  signature).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.optimize import minimize_scalar

MIN_OVERLAP = 0.8  # share of the measured frames the shifted log must cover for a trial offset
ACF_LAGS = 15  # lags (processed frames) of the residuals' autocorrelation the error model is fitted on
MAX_RHO = 0.98  # the autoregressive part's largest lag-1 correlation
MAX_CORRELATED_SHARE = 0.95  # of the residuals' variance the correlated part may take


@dataclass(frozen=True)
class ClockEstimate:
    """The estimated offset (s) and how well the log then matches the measured cap."""

    offset_s: float  # log time at test time 0, s
    sigma_s: float  # its standard uncertainty (generalised least squares, zero and scale fitted)
    residual_mm: float  # RMS residual of the fit at the estimate, mm
    scale: float  # log displacement -> cap displacement
    zero_mm: float  # log displacement at zero cap displacement, mm
    frames_used: int
    search_s: tuple[float, float]
    white_mm: float = 0.0  # the residuals' white part (1 sigma, mm)
    correlated_mm: float = 0.0  # their autoregressive part (1 sigma, mm)
    rho: float = 0.0  # its correlation from one processed frame to the next
    ols_offset_s: float = np.nan  # the ordinary least-squares offset (before the error model)

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class NoiseModel:
    """Residual errors ``white + x``, ``x[k] = rho x[k-1] + w`` (variances in mm^2)."""

    white_var: float
    corr_var: float
    rho: float

    @staticmethod
    def from_residuals(res: np.ndarray, lags: int = ACF_LAGS) -> NoiseModel:
        """The model fitted to residuals' autocorrelation: a straight line through the logarithm
        of its positive values at lags 1 to ``lags`` (weighted by their size) gives rho and the
        correlated variance; the rest of the lag-0 variance is white."""
        r = np.asarray(res, float) - np.mean(res)
        n = len(r)
        acf0 = float(np.dot(r, r) / n)
        lags = min(lags, max(n // 8, 0))
        k = np.arange(1, lags + 1)
        acf = np.array([np.dot(r[: n - j], r[j:]) / n for j in k])
        pos = acf > 0
        if acf0 <= 0 or pos.sum() < 3:
            return NoiseModel(max(acf0, 0.0), 0.0, 0.0)
        slope, icept = np.polyfit(k[pos], np.log(acf[pos]), 1, w=np.sqrt(acf[pos] / acf0))
        rho = float(np.clip(np.exp(slope), 0.0, MAX_RHO))
        corr = float(min(np.exp(icept), MAX_CORRELATED_SHARE * acf0)) if rho > 0 else 0.0
        return NoiseModel(acf0 - corr, corr, rho)

    def whitener(self, n: int):
        """A function whitening (n,) or (n, m) arrays in processed-frame order (the Kalman
        filter's normalised innovations: L^-1 of the model's covariance's Cholesky factor L)."""
        if self.corr_var <= 0 or self.rho <= 0:
            s = np.sqrt(self.white_var) if self.white_var > 0 else 1.0
            return lambda a: np.asarray(a, float) / s
        q = self.corr_var * (1 - self.rho**2)
        gain, norm = np.empty(n), np.empty(n)
        p = self.corr_var
        for i in range(n):
            s = p + self.white_var
            gain[i], norm[i] = p / s, np.sqrt(s)
            p = self.rho**2 * (1 - gain[i]) * p + q

        def whiten(a: np.ndarray) -> np.ndarray:
            a = np.asarray(a, float)
            out = np.empty_like(a)
            x = np.zeros(a.shape[1:])
            for i in range(len(a)):
                innov = a[i] - x
                out[i] = innov / norm[i]
                x = self.rho * (x + gain[i] * innov)
            return out

        return whiten


def _fit(d_log: np.ndarray, cap_mm: np.ndarray, whiten=None) -> tuple[float, float, float, np.ndarray]:
    """Least-squares cap = scale (d_log - zero), residuals whitened by ``whiten`` if given:
    (rms of the (whitened) residuals, scale, zero, unwhitened residuals)."""
    a = np.c_[d_log, np.ones_like(d_log)]
    if whiten is None:
        coef, *_ = np.linalg.lstsq(a, cap_mm, rcond=None)
    else:
        coef, *_ = np.linalg.lstsq(whiten(a), whiten(cap_mm), rcond=None)
    res = cap_mm - a @ coef
    rms = res if whiten is None else whiten(res)
    scale = float(coef[0])
    zero = float(-coef[1] / scale) if scale != 0 else np.nan
    return float(np.sqrt(np.mean(rms**2))), scale, zero, res


def _cost(tau: float, log_d, t: np.ndarray, cap: np.ndarray, span: tuple[float, float], whiten=None) -> float:
    ts = t + tau
    inside = (ts >= span[0]) & (ts <= span[1])
    if inside.sum() < max(MIN_OVERLAP * len(t), 3):
        return np.inf
    if whiten is not None and not inside.all():
        return np.inf  # the error model is the whole series'
    return _fit(log_d(ts[inside]), cap[inside], whiten)[0]


def _refine(log_d, t, cap, span, lo: float, hi: float, whiten=None) -> float:
    res = minimize_scalar(
        _cost, bounds=(lo, hi), args=(log_d, t, cap, span, whiten), method="bounded", options={"xatol": 1e-6}
    )
    return float(res.x)


def _sigma(log_d, t: np.ndarray, cap: np.ndarray, tau: float, whiten, n_frames: float) -> float:
    """Gauss-Newton standard uncertainty of tau with the zero and the scale fitted alongside:
    the whitened derivative of the model in tau, projected off the zero's and the scale's
    columns; the whitened residuals' variance (3 parameters) scales it."""
    ts = t + tau
    d = log_d(ts)
    rms, scale, _, res = _fit(d, cap, whiten)
    dt = 1e-3 / max(n_frames, 1.0)
    ends = log_d.x[[0, -1]]
    deriv = scale * (log_d(np.clip(ts + dt, *ends)) - log_d(np.clip(ts - dt, *ends))) / (2 * dt)
    a = whiten(np.c_[d, np.ones_like(d)])
    g = whiten(deriv)
    g = g - a @ np.linalg.lstsq(a, g, rcond=None)[0]
    info = float(g @ g)
    dof = max(len(t) - 3, 1)
    s2 = float(np.sum(whiten(res) ** 2) / dof)
    return float(np.sqrt(s2 / info)) if info > 0 else np.inf


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
    NaN rows are left out); the module docstring says how.

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
    order = np.argsort(log_t, kind="stable")
    log_t, log_d = log_t[order], log_d[order]
    keep = np.r_[True, np.diff(log_t) > 0]  # PCHIP needs strictly increasing times
    interp = PchipInterpolator(log_t[keep], log_d[keep], extrapolate=False)
    span = (float(log_t[0]), float(log_t[-1]))
    if step_s is None:
        step_s = 0.5 * float(np.median(np.diff(t))) if len(t) > 1 else 0.05
    if search_s is None:
        dur = t[-1] - t[0]
        search_s = (log_t[0] - t[0] - (1 - MIN_OVERLAP) * dur, log_t[-1] - t[-1] + (1 - MIN_OVERLAP) * dur)
    lo, hi = float(search_s[0]), float(search_s[1])
    grid = np.arange(lo, hi + step_s / 2, step_s)
    costs = np.array([_cost(tau, interp, t, cap, span) for tau in grid])
    if not np.isfinite(costs).any():
        raise ValueError(
            f"clock offset: no offset in [{lo:.2f}, {hi:.2f}] s puts {MIN_OVERLAP:.0%} of the frames "
            "inside the log"
        )
    k = int(np.nanargmin(costs))
    tau = _refine(interp, t, cap, span, grid[k] - step_s, grid[k] + step_s)
    if _cost(tau, interp, t, cap, span) > costs[k]:
        tau = float(grid[k])
    tau_ols = tau
    inside = (t + tau >= span[0]) & (t + tau <= span[1])
    t_in, cap_in = t[inside], cap[inside]
    model = NoiseModel.from_residuals(_fit(interp(t_in + tau), cap_in)[3])
    whiten = model.whitener(len(t_in))
    tau_gls = _refine(interp, t_in, cap_in, span, tau - step_s, tau + step_s, whiten)
    if np.isfinite(_cost(tau_gls, interp, t_in, cap_in, span, whiten)):
        tau = tau_gls
    rms, scale, zero, _ = _fit(interp(t_in + tau), cap_in)
    sigma = _sigma(interp, t_in, cap_in, tau, whiten, 1 / step_s)
    return ClockEstimate(
        tau, sigma, rms, scale, zero, len(t_in), (lo, hi),
        float(np.sqrt(model.white_var)), float(np.sqrt(model.corr_var)), model.rho, tau_ols,
    )  # fmt: skip


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
