"""The P frames' departure from the keyframes, measured at each keyframe from one camera's
tracks: the membrane's lag and affine field, the rigid bodies' offsets (see
:mod:`triaxtrack.codec_lag`)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike

# P frames extrapolated to the keyframe on each side: the nearest SIDE_FRAMES where the side
# holds FAR_FRAMES more, else those it leaves, at least SHORT_SIDE_FRAMES (a side needs at
# least MIN_SIDE_FRAMES). The departure measured there corrects the whole GOP, but x265 codes
# the first P frames unlike the rest (on realistic 720p renders the membrane's horizontal
# shrink in the first P frame was 1.35 times the GOP's mean, in the second half of it): a
# quadratic through the nearest 5 weighs the first 1.8 times (its weights' norm 2.1) and read
# 1.6-1.8 times the mean; through 10, 0.9 times (norm 1.2)
SIDE_FRAMES = 10
SHORT_SIDE_FRAMES = 5
MIN_SIDE_FRAMES = 4  # fewer on a side: that side of the keyframe is not measured
FAR_FRAMES = 10  # the P frames beyond those that give the velocity (at least MIN_FAR_FRAMES)
MIN_FAR_FRAMES = 4
VELOCITY_FRAMES = 8  # the correction's velocity: a line through the P frames this many frames either side
MIN_VELOCITY_FRAMES = 5  # P frames needed in that window (else the dot is not moved along its motion)
MIN_DOTS = 30  # dots needed (with every frame of the side reported) to measure a lag
SIGNIFICANT_SIGMAS = 3.0  # a lag within this many standard errors of zero is not applied
MAX_SPEED_RATIO = 1.5  # a keyframe whose two sides' RMS speeds differ more is not measured
FIRST_MEMBRANE_ID = 1001  # the membrane dots (target-kit.md): the small dots the field is measured on
FIELD_SCALE_PX = 1000.0  # the affine field's slopes are per this many pixels
FIELD_COLUMNS = ("u0_px", "u_per_u", "u_per_v", "v0_px", "v_per_u", "v_per_v")
MEMBRANE = "membrane"  # the ``body`` of the membrane dots' rows
LAG_ORDER = ["body", "keyframe", "side"]  # the rows' order
MIN_TARGETS = 3  # a rigid body's targets needed (seen in every frame of a side) to measure its offset
LAG_COLUMNS = (
    "body", "keyframe", "side", "lag_frames", "sigma_frames", *FIELD_COLUMNS,
    "sigma_u0_px", "sigma_v0_px", "common_u0_px", "common_v0_px", "jitter_u0_px", "jitter_v0_px", "dots",
    "speed_px", "sigma_speed_px",
)  # fmt: skip


def _quadratic_value_weights(t: np.ndarray) -> np.ndarray:
    """Weights giving, from values at times ``t``, the least-squares quadratic's value at time 0."""
    return np.linalg.pinv(np.c_[np.ones_like(t), t, t * t])[0]


def _side_frames(frames: np.ndarray, keys: np.ndarray, k: int, side: int) -> np.ndarray:
    """The processed frames on one side (-1 before, +1 after) of the keyframe ``k``, nearest
    first, stopping at the next keyframe that way (another GOP)."""
    if side < 0:
        fence = keys[keys < k].max(initial=-1)
        near = frames[(frames < k) & (frames > fence)][::-1]
    else:
        fence = keys[keys > k].min(initial=np.iinfo(np.int64).max)
        near = frames[(frames > k) & (frames < fence)]
    return near


def _positions(tracks: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(frames (F,), ids (N,), uv (F, N, 2))`` of the reported centroids (NaN elsewhere)."""
    rep = tracks[tracks["reason"] == ""]
    frames = np.unique(tracks["frame"].to_numpy(np.int64))
    ids = np.unique(tracks["id"].to_numpy(np.int64))
    uv = np.full((len(frames), len(ids), 2), np.nan)
    fi = np.searchsorted(frames, rep["frame"].to_numpy(np.int64))
    ii = np.searchsorted(ids, rep["id"].to_numpy(np.int64))
    uv[fi, ii] = rep[["u_px", "v_px"]].to_numpy(np.float64)
    return frames, ids, uv


def _side_fit(
    uv: np.ndarray, frames: np.ndarray, keys: np.ndarray, k: int, side: int, least: int = MIN_DOTS
) -> tuple | None:
    """One side of keyframe ``k``: ``(d (n, 2), vel (n, 2), uv_k (n, 2), common (4,))`` for the
    dots seen in every frame used: the keyframe's centroid minus the P frames' quadratic
    extrapolated to it, the velocity from the frames beyond, the keyframe's centroid, and the
    standard error that the frames' common jitter gives the dots' mean ``d`` (u, v) followed by
    that jitter itself (u, v: one P frame's departure from the quadratic; None: fewer than
    ``least`` dots). The common jitter is the scatter of the dots' mean residual about their
    quadratics from frame to frame; it enters through the extrapolation's weights and through
    the keyframe's own frame. A rigid body's targets share it, and so may the cameras: on a
    realistic 720p render the top cap's CTs jumped together by 0.03-0.06 px from frame to frame
    in every camera at once."""
    side_frames = _side_frames(frames, keys, k, side)
    n = max(min(SIDE_FRAMES, len(side_frames) - FAR_FRAMES), SHORT_SIDE_FRAMES)
    near, far = side_frames[:n], side_frames[n : n + FAR_FRAMES]
    if len(near) < MIN_SIDE_FRAMES or len(far) < MIN_FAR_FRAMES:
        return None
    at_k = uv[np.searchsorted(frames, k)]
    w_val = _quadratic_value_weights((near - k).astype(np.float64))
    tf = (far - far.mean()).astype(np.float64)
    w_slope = tf / (tf * tf).sum()
    p = uv[np.searchsorted(frames, near)]  # (n, N, 2)
    q = uv[np.searchsorted(frames, far)]
    ok = np.isfinite(p).all(axis=(0, 2)) & np.isfinite(q).all(axis=(0, 2)) & np.isfinite(at_k).all(axis=1)
    if ok.sum() < least:
        return None
    fit = np.einsum("n,nid->id", w_val, p[:, ok])
    vel = np.einsum("n,nid->id", w_slope, q[:, ok])
    t = (near - k).astype(np.float64)
    basis = np.c_[np.ones_like(t), t, t * t]
    resid = p[:, ok] - np.einsum(
        "nc,cid->nid", basis, np.einsum("cn,nid->cid", np.linalg.pinv(basis), p[:, ok])
    )
    jitter2 = (resid.mean(axis=1) ** 2).sum(axis=0) / max(len(near) - 3, 1)  # (2,)
    common = np.r_[np.sqrt(jitter2 * (1.0 + float(w_val @ w_val))), np.sqrt(jitter2)]
    return at_k[ok] - fit, vel, at_k[ok], common


def _design(vel: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """The (2n, 7) design of the P frames' departure (u rows, then v rows): the lag times the
    velocity, and an affine field per axis in image coordinates (``FIELD_SCALE_PX`` units)."""
    n = len(uv)
    x = uv / FIELD_SCALE_PX
    A = np.zeros((2 * n, 7))
    A[:n, 0], A[n:, 0] = vel[:, 0], vel[:, 1]
    A[:n, 1], A[:n, 2], A[:n, 3] = 1.0, x[:, 0], x[:, 1]
    A[n:, 4], A[n:, 5], A[n:, 6] = 1.0, x[:, 0], x[:, 1]
    return A


def _fit_side(d: np.ndarray, vel: np.ndarray, at_k: np.ndarray, common: np.ndarray) -> tuple:
    """The lag and field coefficients of one side's departures (see :func:`estimate_lag`), by
    backward elimination: the coefficient least distinguishable from zero (under
    ``SIGNIFICANT_SIGMAS`` standard errors) is dropped and the others fitted again, until all
    left are significant. The lag and the field are nearly collinear when the dots' velocity is
    itself a field across the image (a uniform axial strain moves them in proportion to their
    height): zeroing one of such a pair after a joint fit left half a correction, of the wrong
    size. Returns the lag, its standard error (from the last fit that held it), the field's six
    coefficients (0 where dropped), the standard errors of its constant terms (from the spread
    over the dots and from the frames' ``common`` jitter), that jitter in one P frame, the dots
    and their RMS speed."""
    A = _design(vel, at_k)
    y = np.r_[d[:, 0], d[:, 1]]
    active = np.ones(A.shape[1], bool)
    sol = np.zeros(A.shape[1])
    ses = np.full(A.shape[1], np.nan)  # each coefficient's, from the last fit that held it
    while active.any():
        a = A[:, active]
        coef, *_ = np.linalg.lstsq(a, y, rcond=None)
        resid = y - a @ coef
        s2 = float(resid @ resid) / max(len(y) - a.shape[1], 1)
        se = np.sqrt(s2 * np.diag(np.linalg.pinv(a.T @ a)))
        sol = np.zeros(A.shape[1])
        sol[active] = coef
        ses[active] = se
        t = np.abs(coef) / np.maximum(se, 1e-300)
        weakest = int(np.argmin(t))
        if t[weakest] >= SIGNIFICANT_SIGMAS:
            break
        active[np.nonzero(active)[0][weakest]] = False
    else:
        sol = np.zeros(A.shape[1])
    speed = float(np.sqrt((vel * vel).sum() / len(vel)))
    return (
        float(sol[0]),
        float(ses[0]),
        *map(float, sol[1:]),
        float(ses[1]),
        float(ses[4]),
        *map(float, common),
        len(vel),
        speed,
        np.nan,
    )


def _fit_body(d: np.ndarray, vel: np.ndarray, at_k: np.ndarray, common: np.ndarray) -> tuple:
    """A rigid body's offset on one side of a keyframe, in :func:`_fit_side`'s order: no lag
    (NaN), the mean departure of its targets ``d`` as the field's constant terms, their standard
    errors from the spread over the targets and from the frames' ``common`` jitter, that jitter
    in one P frame (:func:`_side_fit`), the targets, and the body's speed with its standard error
    (:func:`_body_speed`)."""
    n = len(d)
    u0, v0 = d.mean(axis=0)
    su, sv = d.std(axis=0, ddof=1) / np.sqrt(n)
    return (
        np.nan,
        np.nan,
        float(u0),
        0.0,
        0.0,
        float(v0),
        0.0,
        0.0,
        float(su),
        float(sv),
        *map(float, common),
        n,
        *_body_speed(vel),
    )


def _body_speed(vel: np.ndarray) -> tuple[float, float]:
    """A rigid body's speed (pixels per frame): the length of its targets' mean velocity (``vel``,
    (n, 2)), and its standard error from their scatter. A body moves as one: the mean is not
    raised by the targets' noise, as the RMS of their speeds is when the motion is slow."""
    mean = vel.mean(axis=0)
    se = float(np.sqrt((vel.var(axis=0, ddof=1)).sum() / len(vel)))
    return float(np.hypot(*mean)), se


def _speeds_differ(a: ArrayLike, sa: ArrayLike, b: ArrayLike, sb: ArrayLike) -> np.ndarray:
    """Whether two speeds (with standard errors; arrays broadcast) differ by more than
    ``MAX_SPEED_RATIO`` allows beyond ``SIGNIFICANT_SIGMAS`` standard errors: a rigid body's
    motion changed between them."""
    slack = (MAX_SPEED_RATIO - 1.0) * np.minimum(a, b) + SIGNIFICANT_SIGMAS * np.hypot(sa, sb)
    return np.abs(np.subtract(a, b)) > slack


def _body_motion_changes(*velocities: np.ndarray) -> bool:
    """:func:`_motion_changes` for a rigid body: its speeds (:func:`_body_speed`) on the two
    sides of a keyframe differ (:func:`_speeds_differ`). A few targets moving 0.005 px a frame
    under 0.003 px of centroid noise: a ratio of their RMS speeds would be noise."""
    if len(velocities) < 2:
        return False
    return bool(_speeds_differ(*_body_speed(velocities[0]), *_body_speed(velocities[1])))


def rigid_bodies(table: pd.DataFrame) -> dict[str, list[int]]:
    """The kit's rigid bodies: surface -> IDs of its targets, for every surface of the
    target ``table`` (:func:`triaxtrack.kit.target_table`) but the membrane."""
    rigid = table[table["surface"] != MEMBRANE]
    return {str(name): sorted(map(int, ids)) for name, ids in rigid.groupby("surface")["id"]}


def estimate_lag(
    tracks: pd.DataFrame,
    keyframes: np.ndarray,
    measure: np.ndarray | None = None,
    bodies: Mapping[str, Sequence[int]] | None = None,
) -> pd.DataFrame:
    """How one camera's P frames depart from its keyframes, measured at each of its
    ``keyframes`` (test frames) within ``tracks`` (``TRACKS`` rows of one camera; the membrane
    dots, IDs from 1001, are used), or only at those of them in ``measure``. Each keyframe is
    measured on the ``SIDE_FRAMES + FAR_FRAMES`` frames of the tracks on each side of it (up to
    the next keyframe that way), so the tracks may span a whole test.

    Each rigid body of ``bodies`` (name -> target IDs, :func:`rigid_bodies`) is measured too,
    as an offset only (:func:`_fit_body`), where at least ``MIN_TARGETS`` of its targets are seen.

    Returns one row per body, keyframe and side measured: ``body`` (``MEMBRANE`` or the rigid
    body's name), ``keyframe``, ``side`` (-1: the P frames
    before it, +1: after it), ``lag_frames`` (how many frames late those P frames show the
    dots) and ``sigma_frames`` (its standard error), the affine field's coefficients
    ``FIELD_COLUMNS`` (pixels, per ``FIELD_SCALE_PX`` pixels for the slopes: what the P frames
    show minus what the keyframe shows, besides the lag, with the sign reversed) each zeroed
    where within ``SIGNIFICANT_SIGMAS`` standard errors of zero, the standard errors of ``u0_px``
    and ``v0_px`` from the spread over the dots (``sigma_u0_px``, ``sigma_v0_px``) and from the
    frames' common jitter (``common_u0_px``, ``common_v0_px``), that jitter in one P frame
    (``jitter_u0_px``, ``jitter_v0_px``), ``dots`` used and ``speed_px`` (their RMS
    speed, pixels per frame). A rigid body's rows have no lag (NaN) and no slopes, and its speed
    is the length of its mean velocity, with its standard error ``sigma_speed_px`` (NaN for
    the membrane).
    """
    groups = {MEMBRANE: tracks[tracks["id"] >= FIRST_MEMBRANE_ID]}
    for name, ids in (bodies or {}).items():
        groups[name] = tracks[tracks["id"].isin(np.asarray(ids, np.int64))]
    found = [_estimate_group(name, part, keyframes, measure) for name, part in groups.items()]
    rows = pd.DataFrame([row for rows in found for row in rows], columns=list(LAG_COLUMNS))
    return rows.sort_values(LAG_ORDER, kind="stable", ignore_index=True)


def _estimate_group(
    name: str, tracks: pd.DataFrame, keyframes: np.ndarray, measure: np.ndarray | None
) -> list:
    """:func:`estimate_lag`'s rows of one group of targets (``name``: the membrane, fitted by
    :func:`_fit_side`, or a rigid body, by :func:`_fit_body`)."""
    membrane = name == MEMBRANE
    fit, least = (_fit_side, MIN_DOTS) if membrane else (_fit_body, MIN_TARGETS)
    ordered = tracks.sort_values("frame", kind="stable")
    f = ordered["frame"].to_numpy(np.int64)
    uf = np.unique(f)
    fences = np.unique(np.asarray(keyframes, np.int64))
    keys = np.intersect1d(fences, uf)
    if measure is not None:
        keys = np.intersect1d(keys, np.asarray(measure, np.int64))
    reach = SIDE_FRAMES + FAR_FRAMES
    rows = []
    for k in keys:
        i = int(np.searchsorted(uf, k))
        lo, hi = uf[max(0, i - reach)], uf[min(len(uf) - 1, i + reach)]
        near = ordered.iloc[np.searchsorted(f, lo) : np.searchsorted(f, hi, side="right")]
        frames, _, uv = _positions(near)
        sides = {side: _side_fit(uv, frames, fences, int(k), side, least) for side in (-1, 1)}
        seen = [got[1] for got in sides.values() if got is not None]
        if _motion_changes(*seen) if membrane else _body_motion_changes(*seen):
            continue  # a hold, a reversal or a change of rate at the keyframe: not a lag
        rows += [(name, int(k), side, *fit(*got)) for side, got in sides.items() if got is not None]
    return rows


def _motion_changes(*velocities: np.ndarray) -> bool:
    """Whether the dots' RMS speed on the two sides of a keyframe (each side's ``(n, 2)``
    velocities, from :func:`_side_fit`) differs by more than ``MAX_SPEED_RATIO``: the motion
    changed there (a hold, a reversal, a change of the loading rate), and the P frames'
    extrapolation to the keyframe cannot tell the change from a lag. At a change from
    0.0075 to 0.22 px per frame a keyframe read a lag of 10.6 frames (0.24 frames standard error),
    which moved the P frames before it by up to 1 px. With one side only, nothing to compare."""
    if len(velocities) < 2:
        return False
    rms = [float(np.sqrt((v * v).sum() / max(len(v), 1))) for v in velocities]
    low, high = min(rms), max(rms)
    return bool(high > MAX_SPEED_RATIO * low)


def estimate_lag_chunks(
    chunks: Iterable[pd.DataFrame], keyframes: np.ndarray, bodies: Mapping[str, Sequence[int]] | None = None
) -> pd.DataFrame:
    """:func:`estimate_lag` (with the rigid ``bodies``) over one camera's chunks of tracks, given
    in frame order (each chunk's ``TRACKS`` without its handover frame), at every keyframe of
    the test: the frames on
    both sides of a keyframe are used whichever chunks they are in, so every GOP is measured
    at both ends whatever the chunk size. Holds the current chunk and, of the earlier ones, only
    the frames still needed (the last ``SIDE_FRAMES + FAR_FRAMES`` frames, and those of the
    keyframes not yet measured)."""
    keys = np.unique(np.asarray(keyframes, np.int64))
    reach = SIDE_FRAMES + FAR_FRAMES
    wanted = np.array([i for ids in (bodies or {}).values() for i in ids], np.int64)
    held = pd.DataFrame()
    done: set[int] = set()
    out = []

    def measure(buf: pd.DataFrame, final: bool) -> None:
        uf = np.unique(buf["frame"].to_numpy(np.int64))
        ready = []
        for k in keys[np.isin(keys, uf)]:
            after = uf[uf > k]
            fence = keys[keys > k].min(initial=np.iinfo(np.int64).max)
            if int(k) not in done and (final or len(after) >= reach or fence <= uf[-1]):
                ready.append(int(k))
        if ready:
            out.append(estimate_lag(buf, keys, np.array(ready), bodies))
            done.update(ready)

    for chunk in chunks:
        part = chunk[(chunk["id"] >= FIRST_MEMBRANE_ID) | chunk["id"].isin(wanted)]
        held = part if held.empty else pd.concat([held, part], ignore_index=True)
        if held.empty:
            continue
        measure(held, final=False)
        uf = np.unique(held["frame"].to_numpy(np.int64))
        pending = keys[np.isin(keys, uf) & ~np.isin(keys, list(done))]
        keep_from = uf[max(0, len(uf) - reach - 1)]
        if len(pending):
            keep_from = min(keep_from, uf[max(0, int(np.searchsorted(uf, pending.min())) - reach)])
        held = held[held["frame"] >= keep_from]
    if not held.empty:
        measure(held, final=True)
    if not out:
        return pd.DataFrame(columns=list(LAG_COLUMNS))
    return pd.concat(out, ignore_index=True).sort_values(LAG_ORDER, kind="stable", ignore_index=True)
