"""The tracker's ``shape`` check (:mod:`triaxtrack.track`), compiled with numba: one pass over a
frame's targets, where numpy took some thirty calls over the whole arrays. The same arithmetic
as numpy's (``np.median``, ``np.hypot``, ``np.maximum`` with its NaN; a division by zero gives
inf or NaN: numba's numpy error model), so the same results."""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, error_model="numpy")
def _nan_max(a: float, b: float) -> float:
    """``np.maximum(a, b)``: NaN if either is."""
    if math.isnan(a) or math.isnan(b):
        return math.nan
    return a if a >= b else b


@numba.njit(cache=True, error_model="numpy")
def _scatter(mass: np.ndarray, ref: np.ndarray, use: np.ndarray, min_count: int, mad_to_sigma: float
             ) -> float:  # fmt: skip
    """Robust standard deviation (``mad_to_sigma`` x MAD) of the finite relative changes
    ``mass / ref - 1`` of the targets ``use`` (0 when fewer than ``min_count``)."""
    rel = np.empty(len(mass))
    m = 0
    for i in range(len(mass)):
        r = mass[i] / ref[i] - 1
        if use[i] and np.isfinite(r):
            rel[m] = r
            m += 1
    if m < min_count:
        return 0.0
    r = rel[:m]
    return float(mad_to_sigma * np.median(np.abs(r - np.median(r))))


@numba.njit(cache=True, error_model="numpy")
def _mass_ok(mass: float, smass: float, ref: float, sref: float, fraction: float, scatter: float,
             noise_k: float) -> bool:  # fmt: skip
    """Whether a normalised mass agrees with a reference one: a relative change within the
    larger of ``fraction`` and ``noise_k`` x its standard uncertainty, the larger of the one
    propagated from the pixel noise of both and the camera's ``scatter`` (NaN: no)."""
    sigma = _nan_max(np.hypot(smass, sref) / ref, scatter)
    return abs(mass / ref - 1) <= _nan_max(fraction, noise_k * sigma)


@numba.njit(cache=True, error_model="numpy")
def shape_changed(mass: np.ndarray, smass: np.ndarray, ref: np.ndarray, sref: np.ndarray, last: np.ndarray,
                  slast: np.ndarray, measured: np.ndarray, blind: np.ndarray, change: float, step: float,
                  noise_k: float, min_count: int, mad_to_sigma: float) -> np.ndarray:  # fmt: skip
    """(n,) bool: the ``measured`` targets whose normalised mass ``mass`` (standard uncertainty
    ``smass``) changed since the chunk's first frame (``ref``, ``sref``) by more than ``change``,
    or since the frame it was last reported in (``last``, ``slast``; only for a target reported
    in the previous measured frame: ``blind`` 0) by more than ``step``, each or ``noise_k`` of its
    standard uncertainty: the larger of the one propagated from the pixel noise and the robust
    scatter of that change over the targets measured and reported in the previous frame (at least
    ``min_count``; ``mad_to_sigma`` x their MAD)."""
    n = len(mass)
    fresh = np.empty(n, np.bool_)
    for i in range(n):
        fresh[i] = measured[i] and blind[i] == 0
    scatter_ref = _scatter(mass, ref, fresh, min_count, mad_to_sigma)
    scatter_last = _scatter(mass, last, fresh, min_count, mad_to_sigma)
    out = np.zeros(n, np.bool_)
    for i in range(n):
        if not measured[i]:
            continue
        same = _mass_ok(mass[i], smass[i], ref[i], sref[i], change, scatter_ref, noise_k)
        moved = _mass_ok(mass[i], smass[i], last[i], slast[i], step, scatter_last, noise_k)
        out[i] = not (same and (moved or blind[i] > 0))
    return out
