"""The tracker's per-frame kernels (:mod:`triaxtrack.track`), compiled with numba: the ``shape``
check (:func:`shape_changed`) and the state's advance past a frame (:func:`advance`), each one
pass over a frame's targets where numpy took some thirty calls over the whole arrays. The same
arithmetic as numpy's, element by element (``np.median``, ``np.hypot``, ``np.maximum`` with its
NaN; a division by zero gives inf or NaN: numba's numpy error model), so the same results."""

from __future__ import annotations

import math
import sys

import numba
import numpy as np

_LARGEST = sys.float_info.max  # np.nan_to_num's stand-in for an infinity


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
                  slast: np.ndarray, measured: np.ndarray, blind: np.ndarray, divided: np.ndarray,
                  change: float, step: float, noise_k: float, min_count: int, mad_to_sigma: float
                  ) -> np.ndarray:  # fmt: skip
    """(n,) bool: the ``measured`` targets whose normalised mass ``mass`` (standard uncertainty
    ``smass``) changed since the chunk's first frame (``ref``, ``sref``) by more than ``change``,
    or since the frame it was last reported in (``last``, ``slast``; only for a target reported
    in the previous measured frame: ``blind`` 0) by more than ``step``, each or ``noise_k`` of its
    standard uncertainty: the larger of the one propagated from the pixel noise and the robust
    scatter of that change over the targets measured and reported in the previous frame (at least
    ``min_count``; ``mad_to_sigma`` x their MAD) of its class: measured apart from a touching
    target (``divided``: its mass ends at a valley line that moves with the noise) or not (where a
    class has fewer, the scatter over all)."""
    n = len(mass)
    fresh = np.empty(n, np.bool_)
    for i in range(n):
        fresh[i] = measured[i] and blind[i] == 0
    scatter_ref, scatter_last = np.empty(2), np.empty(2)
    over_all = False  # whether a class's scatter was taken over all (the other's may be the same)
    for c in range(2):
        of = fresh & (divided == (c == 1))
        everyone = of.sum() < min_count or of.sum() == fresh.sum()  # (the same targets as all)
        if everyone and over_all:  # the scatter over all again: the same medians
            scatter_ref[c], scatter_last[c] = scatter_ref[c - 1], scatter_last[c - 1]
            continue
        if everyone:  # the scatter over all (only then: each takes two medians)
            of, over_all = fresh, True
        scatter_ref[c] = _scatter(mass, ref, of, min_count, mad_to_sigma)
        scatter_last[c] = _scatter(mass, last, of, min_count, mad_to_sigma)
    out = np.zeros(n, np.bool_)
    for i in range(n):
        if not measured[i]:
            continue
        c = 1 if divided[i] else 0
        same = _mass_ok(mass[i], smass[i], ref[i], sref[i], change, scatter_ref[c], noise_k)
        moved = _mass_ok(mass[i], smass[i], last[i], slast[i], step, scatter_last[c], noise_k)
        out[i] = not (same and (moved or blind[i] > 0))
    return out


@numba.njit(cache=True, error_model="numpy")
def advance(uv: np.ndarray, mass: np.ndarray, smass: np.ndarray, ok: np.ndarray, unconfirmed: np.ndarray,
            flow: np.ndarray, valid: np.ndarray, ref_uv: np.ndarray, pred: np.ndarray, last_uv: np.ndarray,
            last_vel: np.ndarray, last_mass: np.ndarray, last_smass: np.ndarray, timed: np.ndarray,
            blind: np.ndarray, since: np.ndarray, excused: bool, first: bool, smoothing: float
            ) -> tuple:  # fmt: skip
    """The tracker's state past a measured frame (new arrays): ``(last_uv, last_vel, last_mass,
    last_smass, timed, blind, since, pred)`` from the old ones and the frame's centroids ``uv``
    (n, 2), masses ``mass`` and ``smass``, the targets reported (``ok``) and found again but not
    confirmed (``unconfirmed``), the neighbours' flow ``flow`` (n, 2) where ``valid``, the
    reference places ``ref_uv`` and this frame's predictions ``pred``. A target reported after a
    reported frame (``blind`` 0) has its velocity measured (per frame since it was last reported;
    once known, ``smoothing`` of the previous one kept); at the chunk's ``first`` frame every
    velocity is zero. The next predictions: a reported target's by its velocity, an unconfirmed
    one's where it was found, the others' with their neighbours (each coordinate, where finite)
    or else blind, or in an ``excused`` frame (blank) moved on by their velocity."""
    n = len(uv)
    new_uv, new_vel, new_pred = np.empty((n, 2)), np.empty((n, 2)), np.empty((n, 2))
    new_mass, new_smass = np.empty(n), np.empty(n)
    new_timed, new_blind, new_since = np.empty(n, np.bool_), np.empty(n, np.int64), np.empty(n, np.int64)
    for i in range(n):
        steady = ok[i] and blind[i] == 0
        for c in range(2):
            moved = (uv[i, c] - last_uv[i, c]) / since[i]  # per frame since it was last reported
            smoothed = smoothing * last_vel[i, c] + (1 - smoothing) * moved
            vel = smoothed if timed[i] else moved
            new_vel[i, c] = 0.0 if first else (vel if steady else last_vel[i, c])
            new_uv[i, c] = uv[i, c] if ok[i] else last_uv[i, c]
        new_timed[i] = timed[i] or (steady and not first)
        new_mass[i], new_smass[i] = (mass[i], smass[i]) if ok[i] else (last_mass[i], last_smass[i])
        new_blind[i] = 0 if ok[i] else (blind[i] if excused else blind[i] + 1)
        new_since[i] = 1 if ok[i] else since[i] + 1
        for c in range(2):
            if ok[i]:
                new_pred[i, c] = uv[i, c] + new_vel[i, c]
            elif unconfirmed[i]:
                new_pred[i, c] = uv[i, c]
            elif excused:
                new_pred[i, c] = pred[i, c] + new_vel[i, c]
            else:
                blind_pred = new_uv[i, c] + new_vel[i, c] * new_since[i]
                v = ref_uv[i, c] + flow[i, c] if valid[i] else blind_pred
                new_pred[i, c] = v if np.isfinite(v) else blind_pred
    return new_uv, new_vel, new_mass, new_smass, new_timed, new_blind, new_since, new_pred


@numba.njit(cache=True, error_model="numpy")
def camera_shift(wall: np.ndarray, uv: np.ndarray, pred: np.ndarray, spacing: np.ndarray, gate: float,
                 min_count: int, agree_share: float) -> np.ndarray:  # fmt: skip
    """(2,) the per-axis median departure ``uv - pred`` of the targets ``wall`` (n,) within
    ``gate`` x their ``spacing`` of their predictions, if at least ``min_count`` of them agree
    with it: the median of their distances from it within ``agree_share`` x ``gate`` x their
    median spacing; else zero. As numpy's masks and ``np.median`` (``track._camera_motion``)."""
    n = len(wall)
    mu, mv, sp = np.empty(n), np.empty(n), np.empty(n)
    m = 0
    for i in range(n):
        if not wall[i]:
            continue
        du, dv = uv[i, 0] - pred[i, 0], uv[i, 1] - pred[i, 1]
        if math.sqrt(du * du + dv * dv) <= gate * spacing[i]:
            mu[m], mv[m], sp[m] = du, dv, spacing[i]
            m += 1
    shift = np.zeros(2)
    if m < min_count:
        return shift
    su, sv = np.median(mu[:m]), np.median(mv[:m])
    dist = np.empty(m)
    for q in range(m):
        du, dv = mu[q] - su, mv[q] - sv
        dist[q] = math.sqrt(du * du + dv * dv)
    if np.median(dist) <= agree_share * gate * np.median(sp[:m]):
        shift[0], shift[1] = su, sv
    return shift


@numba.njit(cache=True, error_model="numpy")
def found_miss(uv: np.ndarray, pred: np.ndarray, found: np.ndarray) -> np.ndarray:
    """(n, 2) ``uv - pred`` of the targets ``found`` (NaN as 0, an infinity as the largest finite
    number of its sign: ``np.nan_to_num``), else 0."""
    n = len(uv)
    out = np.zeros((n, 2))
    for i in range(n):
        if not found[i]:
            continue
        for c in range(2):
            d = uv[i, c] - pred[i, c]
            if math.isnan(d):
                d = 0.0
            elif math.isinf(d):
                d = _LARGEST if d > 0 else -_LARGEST
            out[i, c] = d
    return out


@numba.njit(cache=True, error_model="numpy")
def spread_motion(motion: np.ndarray, known: np.ndarray, miss: np.ndarray, found: np.ndarray, tol: np.ndarray
                  ) -> np.ndarray:  # fmt: skip
    """(n, 2) the ``motion`` of the ``known`` targets that are not seeds (``found`` with their
    ``miss`` within ``tol``: measured already), else 0."""
    n = len(motion)
    out = np.zeros((n, 2))
    for i in range(n):
        seed = found[i] and math.sqrt(miss[i, 0] * miss[i, 0] + miss[i, 1] * miss[i, 1]) <= tol[i]
        if known[i] and not seed:
            out[i, 0], out[i, 1] = motion[i, 0], motion[i, 1]
    return out
