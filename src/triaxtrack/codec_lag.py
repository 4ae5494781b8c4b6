"""How inter-coded video frames depart from keyframes, measured at keyframes and removed from the
tracks.

An H.264/H.265 encoder codes a predicted (P) frame as the previous decoded frame moved by
quarter-pixel motion vectors plus a quantised residual. A dot that moves by a fraction of a
pixel per frame is therefore shown a little behind where it is: the residual that would move
it is partly quantised away, and the shortfall carries over from frame to frame. A keyframe
(an intra-coded frame) is coded from the picture alone and shows the dot where it is. Seen in
the tracks, every P frame's centroids lag the motion by a common fraction ``lag`` of a frame
(the picture is effectively taken ``lag`` frames earlier), and the trajectory steps forward at
every keyframe: 0.02-0.03 frames on the simulator's H.264 at crf 14 (0.005 px at 0.28 px per
frame). P frames also render the dots a little differently from a keyframe, which moves their
centroids by a smooth field across the image: on the simulator's H.264 the membrane dots of a
P frame sit closer to the specimen's axis, a horizontal scale of -0.6e-4 to -1.2e-4 on top of
the keyframe's own. Together they put a step of 0.01-0.03 % of the specimen's volume at each
keyframe.

The lag is measured per camera at each keyframe ``K`` from the camera's own tracks: on each
side of ``K``, a quadratic in time is fitted to every dot's centroids in the nearest
``SIDE_FRAMES`` P frames (all from the same GOP, so with one common lag), and evaluated at
``K``; there it gives the dot's position ``lag`` frames late, ``x(K) - lag x'(K)``, while the
keyframe shows ``x(K)``. The difference over all the membrane dots is fitted by least squares
as the lag times each dot's velocity ``x'`` plus an affine field of the image coordinates per
axis (seven coefficients, with their standard errors; a coefficient within
``SIGNIFICANT_SIGMAS`` of zero is taken as zero). The velocity is a straight line's slope
over the next ``FAR_FRAMES`` P frames beyond those (a velocity fitted to the same frames as
the extrapolation shares its noise, and biases the ratio by as much as the lag itself at
0.015 px of centroid noise); the quadratic absorbs the motion's own acceleration. A dot at rest
carries no weight, so a static test gives no correction. A keyframe where the motion changes
(the RMS speeds on its two sides differ by more than ``MAX_SPEED_RATIO``: a hold, a reversal, a
new loading rate) is not measured: extrapolated across the change, the P frames would read as
lagging by many frames.

Each P frame's membrane dots are then moved forward by ``lag x'`` (``x'`` the dot's velocity
from its own P-frame centroids around that frame, pixels per frame) and by the field, the
coefficients interpolated linearly in time across the GOP, from those measured just after its
keyframe to those measured just before the next (frames before the first keyframe given, or
after the last, take the missing end from the neighbouring GOP). What is left: a departure that
grows within the
last few frames of a GOP (x264's rate control spends fewer bits on frames no later frame
refers to) is measured only as its mean over the ``SIDE_FRAMES`` before the keyframe.
Keyframes are left as they are.

The other targets (the CTs and dots of the cell wall and the pedestals) are few per camera and
lie on rigid bodies, so their P frames are measured per body (``bodies``: the kit's surfaces
other than the membrane, :func:`rigid_bodies`) as a common offset ``(u0_px, v0_px)`` only, the
keyframe's centroids minus the P frames' quadratic extrapolated to it, with its standard error
from the spread over the body's targets. It is not a lag: on the simulator's H.264 the top cap's
CTs read 0.011 px lower than the keyframes in every P frame of a test where the cap moves 0.3 px
a frame (ahead of the motion), and 0.007 px higher (behind it) where it moves 0.005 px a frame;
uncorrected, that is 3 micrometres of the cap's height in every P frame. One keyframe's offset
rests on a few targets, so it is pooled, per body and side, over the camera's keyframes where
the body moves at a similar speed (within ``MAX_SPEED_RATIO``; a hold pools with holds), and
applied where the pooled offset is at least ``SIGNIFICANT_SIGMAS`` standard errors from zero
(a body at rest: none).

In the workflow, rule ``measure_codec_lag`` measures one camera at every keyframe of the test
over its chunks of tracks in order (:func:`estimate_lag_chunks`: a keyframe's two sides may lie
in different chunks, so a chunk shorter than the GOP is measured and corrected like any other)
and writes ``results/<test>/codec_lag/<camera>.json`` (:func:`write_lags`, :func:`read_lags`);
``triangulate_chunk`` corrects each chunk's tracks with every camera's file
(:func:`corrected_tracks`); :func:`run_measure_codec_lag` is that rule's stage. Frames are test
frames; pixels in OpenCV's convention.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike

SIDE_FRAMES = 5  # P frames extrapolated to the keyframe on each side (at least MIN_SIDE_FRAMES)
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
    "sigma_u0_px", "sigma_v0_px", "dots", "speed_px", "sigma_speed_px",
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
    """One side of keyframe ``k``: ``(d (n, 2), vel (n, 2), uv_k (n, 2))`` for the dots seen in
    every frame used: the keyframe's centroid minus the P frames' quadratic extrapolated to it,
    the velocity from the frames beyond, and the keyframe's centroid (None: fewer than
    ``least`` dots)."""
    side_frames = _side_frames(frames, keys, k, side)
    near, far = side_frames[:SIDE_FRAMES], side_frames[SIDE_FRAMES : SIDE_FRAMES + FAR_FRAMES]
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
    return at_k[ok] - fit, vel, at_k[ok]


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


def _fit_side(d: np.ndarray, vel: np.ndarray, at_k: np.ndarray) -> tuple:
    """The lag and field coefficients of one side's departures (see :func:`estimate_lag`), by
    backward elimination: the coefficient least distinguishable from zero (under
    ``SIGNIFICANT_SIGMAS`` standard errors) is dropped and the others fitted again, until all
    left are significant. The lag and the field are nearly collinear when the dots' velocity is
    itself a field across the image (a uniform axial strain moves them in proportion to their
    height): zeroing one of such a pair after a joint fit left half a correction, of the wrong
    size. Returns the lag, its standard error (from the last fit that held it), the field's six
    coefficients (0 where dropped), the dots and their RMS speed."""
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
        len(vel),
        speed,
        np.nan,
    )


def _fit_body(d: np.ndarray, vel: np.ndarray, at_k: np.ndarray) -> tuple:
    """A rigid body's offset on one side of a keyframe, in :func:`_fit_side`'s order: no lag
    (NaN), the mean departure of its targets ``d`` as the field's constant terms, their standard
    errors (the spread over the targets), the targets, and the body's speed with its standard
    error (:func:`_body_speed`)."""
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
    and ``v0_px`` (``sigma_u0_px``, ``sigma_v0_px``), ``dots`` used and ``speed_px`` (their RMS
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
    """:func:`estimate_lag` (with the rigid ``bodies``) over one camera's chunks of tracks, given in frame order (each
    chunk's ``TRACKS`` without its handover frame), at every keyframe of the test: the frames on
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


def _coefficients(
    frames: np.ndarray, keyframes: np.ndarray, lags: pd.DataFrame, rise: bool = False
) -> np.ndarray:
    """(F, 7) lag and field coefficients of each of ``frames``: 0 at keyframes; in a P frame
    interpolated linearly in time across its GOP, from the departure measured just after the
    GOP's keyframe to that measured just before the next keyframe. A GOP with one of its
    keyframes not in ``keyframes`` (before the first given, or after the last: the workflow
    gives every keyframe of the test) takes the missing end from the neighbouring GOP (a
    recorder's GOPs are alike: the departure after the next keyframe, or before the previous
    one) and its length from the keyframe spacing; with one keyframe only, the side measured
    is held. NaN where nothing is measured. A lag
    within ``SIGNIFICANT_SIGMAS`` standard errors of zero counts as 0.

    With ``rise`` (a rigid body's offsets), the departure moves from the GOP's start to its end
    no faster than the body itself moves: ``1 - exp(-t s / |b - a|)`` of the way at ``t``
    frames into the GOP, ``s`` the body's speed (pixels per frame), ``|b - a|`` the change of
    offset (pixels). The codec holds a slow body back until it has moved about as far as the
    departure: on the simulator's H.264 the top cap moving 0.001 px a frame departs by 0.008 px
    after some 10 frames, one moving 0.3 px a frame at the first P frame."""
    frames = np.asarray(frames, np.int64)
    keys = np.sort(np.asarray(keyframes, np.int64))
    lag = lags["lag_frames"].where(lags["lag_frames"].abs() > SIGNIFICANT_SIGMAS * lags["sigma_frames"], 0.0)
    cols = [*FIELD_COLUMNS, "speed_px"]
    vec = np.c_[lag.to_numpy(), lags[cols].to_numpy(np.float64)] if len(lags) else np.zeros((0, 8))
    sides = list(zip(lags["keyframe"].astype(int), lags["side"], strict=True))
    after = {k: vec[i] for i, (k, s) in enumerate(sides) if s > 0}
    before = {k: vec[i] for i, (k, s) in enumerate(sides) if s < 0}
    gop = int(np.median(np.diff(keys))) if len(keys) > 1 else None
    out = np.full((len(frames), 8), np.nan)
    for i, f in enumerate(frames):
        if np.isin(f, keys):
            out[i] = 0.0
            continue
        earlier, later = keys[keys < f], keys[keys > f]
        prev = int(earlier.max()) if len(earlier) else None
        nxt = int(later.min()) if len(later) else None
        a = after.get(prev) if prev is not None else after.get(nxt)  # the GOP's start
        b = before.get(nxt) if nxt is not None else before.get(prev)  # and its end
        if prev is not None and nxt is not None:
            span, t = nxt - prev, f - prev
        elif gop is not None:  # before the first keyframe or after the last: a GOP as long as the others
            span, t = gop, (f - prev if prev is not None else gop - (nxt - f))
        else:
            span, t = None, None
        if a is not None and b is not None and span is not None:
            out[i] = a + (b - a) * (_rise(t, a, b) if rise else np.clip(t / span, 0.0, 1.0))
        elif a is not None or b is not None:
            out[i] = a if a is not None else b
    return out[:, :7]


def _rise(t: int, a: np.ndarray, b: np.ndarray) -> float:
    """How far a rigid body's offset has moved from the GOP's start ``a`` to its end ``b``
    (:func:`_coefficients`'s rows: offsets at 1 and 4, speed at 7) ``t`` frames into the GOP."""
    change = float(np.hypot(b[1] - a[1], b[4] - a[4]))
    speed = 0.5 * (a[7] + b[7])
    return 1.0 if change == 0 else float(1.0 - np.exp(-max(t, 0) * speed / change))


def _velocity(frames: np.ndarray, uv: np.ndarray, keyframes: np.ndarray) -> np.ndarray:
    """Each dot's velocity (pixels per frame) at each frame: the slope of a least-squares line
    through its reported P-frame centroids within ``VELOCITY_FRAMES`` frames either side (NaN
    with fewer than ``MIN_VELOCITY_FRAMES``). Local, so that a test's holds, reversals and
    changes of rate within a chunk are followed (a quadratic over a whole chunk of a ramp, a hold
    and an unload gave velocities wrong by a third of the ramp's, moving P frames by 0.03 px);
    over P frames only, since a keyframe shows the dot where it is and the P frames ``lag``
    frames behind, a step the line would take for motion; smooth, since the correction
    multiplies it by the lag, which on nearly static dots can be several frames."""
    t = frames.astype(np.float64)
    ok = np.isfinite(uv).all(axis=2) & ~np.isin(frames, np.asarray(keyframes, np.int64))[:, None]
    y = np.nan_to_num(uv)
    s0, s1, s2 = (np.zeros(ok.shape) for _ in range(3))  # sums of w, w dt, w dt^2
    sy, sty = np.zeros(uv.shape), np.zeros(uv.shape)  # sums of w y, w dt y
    f = len(t)
    for d in range(-VELOCITY_FRAMES, VELOCITY_FRAMES + 1):  # processed frames are >= 1 frame apart
        i = np.arange(max(0, -d), min(f, f - d))  # frame i's neighbour i + d
        dt = (t[i + d] - t[i])[:, None]
        w = ok[i + d] & (np.abs(dt) <= VELOCITY_FRAMES)
        s0[i] += w
        s1[i] += w * dt
        s2[i] += w * dt * dt
        sy[i] += w[..., None] * y[i + d]
        sty[i] += (w * dt)[..., None] * y[i + d]
    det = s0 * s2 - s1 * s1
    good = (s0 >= MIN_VELOCITY_FRAMES) & (det > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        slope = (s0[..., None] * sty - s1[..., None] * sy) / det[..., None]
    return np.where(good[..., None], slope, np.nan)


def correct_lag(
    tracks: pd.DataFrame,
    keyframes: np.ndarray,
    lags: pd.DataFrame,
    bodies: Mapping[str, Sequence[int]] | None = None,
) -> pd.DataFrame:
    """A copy of one camera's ``tracks`` with every P frame's reported membrane dots moved by
    the frame's departure from the keyframes (:func:`estimate_lag`, interpolated in time by
    :func:`_coefficients`): forward along the dot's velocity by the lag, and back by the
    affine field; and the targets of each rigid body of ``bodies`` by its rows' offset
    ``(u0_px, v0_px)`` (give them pooled: :func:`pooled_offsets`). Keyframes, other targets
    and frames with nothing measured are left as they are."""
    out = tracks.copy()
    rep = (out["reason"] == "").to_numpy()
    mem = (tracks["id"] >= FIRST_MEMBRANE_ID).to_numpy()
    frames, ids, uv = _positions(tracks[mem])
    coef = np.nan_to_num(_coefficients(frames, keyframes, lags[lags["body"] == MEMBRANE]))
    if coef.any():
        vel = np.nan_to_num(_velocity(frames, uv, keyframes))
        x = np.nan_to_num(uv) / FIELD_SCALE_PX
        c = coef[:, None, :]
        shift = np.stack([
            c[..., 0] * vel[..., 0] + c[..., 1] + c[..., 2] * x[..., 0] + c[..., 3] * x[..., 1],
            c[..., 0] * vel[..., 1] + c[..., 4] + c[..., 5] * x[..., 0] + c[..., 6] * x[..., 1],
        ], axis=-1)  # fmt: skip
        _move(out, mem & rep, frames, ids, shift)
    for name, body_ids in (bodies or {}).items():
        rows = lags[lags["body"] == name]
        on = out["id"].isin(np.asarray(body_ids, np.int64)).to_numpy() & rep
        if not on.any() or rows.empty:
            continue
        frames = np.unique(out.loc[on, "frame"].to_numpy(np.int64))
        coef = np.nan_to_num(_coefficients(frames, keyframes, rows, rise=True))[:, [1, 4]]
        if coef.any():
            one = np.unique(out.loc[on, "id"].to_numpy(np.int64))
            _move(out, on, frames, one, np.broadcast_to(coef[:, None, :], (len(frames), len(one), 2)))
    return out


def _move(
    out: pd.DataFrame, rows: np.ndarray, frames: np.ndarray, ids: np.ndarray, shift: np.ndarray
) -> None:
    """Add ``shift`` (F, N, 2: pixels, per frame of ``frames`` and ID of ``ids``) to the
    centroids of ``out``'s selected ``rows`` (a copy being built by :func:`correct_lag`)."""
    fi = np.searchsorted(frames, out.loc[rows, "frame"].to_numpy(np.int64))
    ii = np.searchsorted(ids, out.loc[rows, "id"].to_numpy(np.int64))
    s = shift[fi, ii]
    out.loc[rows, "u_px"] = out.loc[rows, "u_px"].to_numpy() + s[:, 0]
    out.loc[rows, "v_px"] = out.loc[rows, "v_px"].to_numpy() + s[:, 1]


def pooled_offsets(lags: Mapping[str, pd.DataFrame]) -> dict[str, pd.DataFrame]:
    """Each camera's rows of :func:`estimate_lag` (camera -> table) with every rigid body's
    offsets pooled over all the cameras (:func:`_pooled_offsets`); the membrane's rows as they
    are. One keyframe's offset in one camera rests on a few targets (about 5 of the top cap's
    CTs: 0.002-0.003 px standard error against a departure of 0.005-0.01 px); the departure is
    the codec's response to the motion, alike in cameras of one recorder seeing the body move
    at a similar speed."""
    tables = {camera: t.reset_index(drop=True) for camera, t in lags.items()}
    rigid = [t[t["body"] != MEMBRANE].assign(camera=camera) for camera, t in tables.items()]
    every = pd.concat(rigid, ignore_index=True) if rigid else pd.DataFrame(columns=["body", "camera"])
    out = {camera: t.copy() for camera, t in tables.items()}
    for _, rows in every.groupby("body"):
        pooled = _pooled_offsets(rows)
        for camera, part in pooled.groupby("camera"):
            mine = out[str(camera)]
            at = mine.index[mine["body"] == part["body"].iloc[0]]
            mine.loc[at, ["u0_px", "v0_px"]] = part[["u0_px", "v0_px"]].to_numpy()
    return out


def _pooled_offsets(rows: pd.DataFrame) -> pd.DataFrame:
    """One rigid body's rows of :func:`estimate_lag` (any cameras) with each side's offset
    ``(u0_px, v0_px)`` replaced by its mean over the rows of that side where the body moved at a
    similar speed (:func:`_speeds_differ`: a hold pools with holds), weighted by their targets,
    and zeroed where within ``SIGNIFICANT_SIGMAS`` standard errors of zero (the targets' scatter
    pooled over those rows)."""
    out = rows.copy()
    v, sv = (rows[c].to_numpy(np.float64)[:, None] for c in ("speed_px", "sigma_speed_px"))
    side = rows["side"].to_numpy()
    n = rows["dots"].to_numpy(np.float64)
    peers = (side[:, None] == side[None, :]) & ~_speeds_differ(v, sv, v.T, sv.T)  # (R, R)
    for value, sigma in (("u0_px", "sigma_u0_px"), ("v0_px", "sigma_v0_px")):
        mean = rows[value].to_numpy(np.float64)
        scatter2 = rows[sigma].to_numpy(np.float64) ** 2 * n  # each row's targets' variance
        pooled = np.zeros(len(rows))
        for i, peer in enumerate(peers):
            m = float((n[peer] * mean[peer]).sum() / n[peer].sum())
            var = ((n[peer] - 1) * scatter2[peer]).sum() / max((n[peer] - 1).sum(), 1)
            pooled[i] = m if abs(m) >= SIGNIFICANT_SIGMAS * np.sqrt(var / n[peer].sum()) else 0.0
        out[value] = pooled
    return out


def lag_corrected(
    tracks: pd.DataFrame, keyframes: np.ndarray, bodies: Mapping[str, Sequence[int]] | None = None
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """One camera's ``tracks`` with the codec's motion lag measured at its ``keyframes`` (test
    frames) and removed (and the offsets of the rigid ``bodies``): ``(corrected tracks, lags)``
    (:func:`estimate_lag`'s table)."""
    lags = estimate_lag(tracks, keyframes, bodies=bodies)
    return correct_lag(tracks, keyframes, pooled_offsets({"": lags})[""], bodies), lags


# ---------------------------------------------------------------- the per-camera lag file


def write_lags(
    path: str | Path,
    camera: str,
    keyframes: np.ndarray,
    lags: pd.DataFrame,
    note: str = "",
    bodies: Mapping[str, Sequence[int]] | None = None,
) -> None:
    """Write one camera's measured departures (``results/<test>/codec_lag/<camera>.json``):
    its keyframes (test frames, every one of the test), :func:`estimate_lag`'s rows (null
    where NaN), the rigid ``bodies`` they were measured on (name -> target IDs) and a ``note``
    (why nothing is measured or applied, if so)."""
    rows = lags[list(LAG_COLUMNS)].astype({"body": str}).to_numpy(object).tolist()
    doc = {
        "camera": camera,
        "keyframes": [int(k) for k in np.asarray(keyframes, np.int64)],
        "columns": list(LAG_COLUMNS),
        "lags": [[_json_value(v) for v in row] for row in rows],
        "bodies": {str(name): [int(i) for i in ids] for name, ids in (bodies or {}).items()},
        "note": note,
    }
    Path(path).write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n")


def _json_value(v: object) -> object:
    """A table cell as JSON: numbers as Python numbers, NaN as null, strings as they are."""
    if isinstance(v, str):
        return v
    x = float(v)  # type: ignore[arg-type]
    return None if np.isnan(x) else (int(x) if x.is_integer() and abs(x) < 2**53 else x)


class LagFile(NamedTuple):
    """One camera's file of :func:`write_lags`, as :func:`correct_lag` takes it."""

    keyframes: np.ndarray
    lags: pd.DataFrame
    bodies: dict[str, list[int]]


def read_lags(path: str | Path) -> tuple[str, LagFile]:
    """``(camera, LagFile(keyframes, lags, bodies))`` of a file written by :func:`write_lags`."""
    try:
        doc = json.loads(Path(path).read_text())
        lags = pd.DataFrame(doc["lags"], columns=doc["columns"])
        keys = np.asarray(doc["keyframes"], np.int64)
        camera = str(doc["camera"])
        bodies = {str(k): [int(i) for i in v] for k, v in doc["bodies"].items()}
        if list(lags.columns) != list(LAG_COLUMNS):
            raise ValueError(f"columns {list(lags.columns)}, expected {list(LAG_COLUMNS)}")
        numbers = [c for c in LAG_COLUMNS if c != "body"]
        lags = lags.astype({"body": str, **dict.fromkeys(numbers, np.float64)})
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
        raise ValueError(f"{path}: not a codec-lag file ({err})") from None
    return camera, LagFile(
        keys, lags.astype({"keyframe": np.int64, "side": np.int64, "dots": np.int64}), bodies
    )


def read_lag_files(paths: Iterable[str | Path]) -> dict[str, LagFile]:
    """Camera -> its :class:`LagFile` of several files written by :func:`write_lags` (the
    argument of :func:`corrected_tracks`)."""
    return dict(map(read_lags, paths))


def corrected_tracks(tracks: pd.DataFrame, lags: Mapping[str, LagFile | tuple]) -> pd.DataFrame:
    """A copy of ``tracks`` (``TRACKS`` rows of any cameras, e.g. one chunk's) with each camera's
    P frames corrected by :func:`correct_lag` from its ``(keyframes, lags[, bodies])`` in
    ``lags`` (every keyframe of the test, so a GOP cut by the chunk is corrected from both its
    ends), the rigid bodies' offsets pooled over the cameras (:func:`pooled_offsets`); cameras
    not in ``lags`` are left as they are."""
    out = tracks.copy()
    pooled = pooled_offsets({camera: got[1] for camera, got in lags.items()})
    for camera, pos in tracks.groupby("camera", sort=False).indices.items():
        if camera in lags:
            keys, _, *bodies = lags[camera]
            fixed = correct_lag(tracks.iloc[pos], keys, pooled[camera], *bodies)
            out.iloc[pos, out.columns.get_indexer(["u_px", "v_px"])] = fixed[["u_px", "v_px"]].to_numpy()
    return out


def run_measure_codec_lag(
    *,
    camera: str,
    tracks: Sequence[str | Path],
    video: str | Path,
    frames: str | Path,
    kit: str | Path,
    lags: str | Path,
) -> None:
    """Rule measure_codec_lag: :func:`estimate_lag_chunks` of one ``camera`` over its chunks'
    ``tracks`` in order, at every keyframe of its ``video`` (frame map ``frames``), with the
    rigid bodies of the ``kit`` folder's design, written to ``lags`` (:func:`write_lags`, with a
    note when nothing could be measured); prints the rows."""
    from triaxtrack.frames import keyframe_test_frames
    from triaxtrack.kit import load_kit_design, target_table
    from triaxtrack.tables import FRAME_MAP, TRACKS, read_table

    fmap = read_table(frames, FRAME_MAP)
    keys = keyframe_test_frames(video, fmap, 0, len(fmap))
    bodies = rigid_bodies(target_table(load_kit_design(kit)))
    found = estimate_lag_chunks((read_table(path, TRACKS) for path in tracks), keys, bodies)
    note = "" if len(found) else "not measured: no keyframe with enough P frames on either side"
    write_lags(lags, camera, keys, found, note, bodies)
    print(f"{camera}: P frames against keyframes {keys.tolist()} (triaxtrack.codec_lag):")
    print(note or found.to_string(index=False))
