"""The P frames' departure, measured at keyframes (:mod:`triaxtrack.codec_lag.measure`),
interpolated across each GOP and taken off the tracks (see :mod:`triaxtrack.codec_lag`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from triaxtrack.codec_lag.files import LagFile
from triaxtrack.codec_lag.measure import (
    FIELD_COLUMNS,
    FIELD_SCALE_PX,
    FIRST_MEMBRANE_ID,
    MEMBRANE,
    MIN_VELOCITY_FRAMES,
    SIGNIFICANT_SIGMAS,
    VELOCITY_FRAMES,
    _positions,
    _speeds_differ,
    estimate_lag,
)

MIN_SPREAD_KEYFRAMES = 3  # keyframes (of one side) whose scatter gives a pooled offset's standard error
POOL_KEYFRAMES = 5  # a rigid body's offset is pooled over this many keyframes either side
LEFT_COLUMNS = ("left_u0_px", "left_v0_px")  # a pooled offset's uncertainty left in the P frames
CODEC_COLUMNS = ("codec_u_px", "codec_v_px")  # per observation: what its P frame's offset leaves


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
    and frames with nothing measured are left as they are.

    The copy has two more columns, ``codec_u_px, codec_v_px``: for a rigid body's target in a P
    frame, the standard uncertainty of its offset left after the correction (the rows'
    ``left_u0_px, left_v0_px`` of :func:`pooled_offsets`, interpolated across the GOP as the
    offsets are), an error every camera shares since the offset is pooled over them; 0
    elsewhere (the membrane's departure, fitted on thousands of dots per camera, is not counted
    here)."""
    out = tracks.copy()
    out[list(CODEC_COLUMNS)] = 0.0
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
        one = np.unique(out.loc[on, "id"].to_numpy(np.int64))
        if coef.any():
            _move(out, on, frames, one, np.broadcast_to(coef[:, None, :], (len(frames), len(one), 2)))
        if all(c in rows.columns for c in LEFT_COLUMNS):
            left = rows.assign(u0_px=rows[LEFT_COLUMNS[0]], v0_px=rows[LEFT_COLUMNS[1]])
            unc = np.nan_to_num(_coefficients(frames, keyframes, left, rise=True))[:, [1, 4]]
            fi = np.searchsorted(frames, out.loc[on, "frame"].to_numpy(np.int64))
            out.loc[on, list(CODEC_COLUMNS)] = unc[fi]
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
    out = {camera: t.assign(**dict.fromkeys(LEFT_COLUMNS, 0.0)) for camera, t in tables.items()}
    cols = ["u0_px", "v0_px", *LEFT_COLUMNS]
    for _, rows in every.groupby("body"):
        pooled = _pooled_offsets(rows)
        for camera, part in pooled.groupby("camera"):
            mine = out[str(camera)]
            at = mine.index[mine["body"] == part["body"].iloc[0]]
            mine.loc[at, cols] = part[cols].to_numpy()
    return out


def _pooled_offsets(rows: pd.DataFrame) -> pd.DataFrame:
    """One rigid body's rows of :func:`estimate_lag` (any cameras) with each side's offset
    ``(u0_px, v0_px)`` replaced by its mean over the rows of that side within ``POOL_KEYFRAMES``
    keyframes either side where the body moved at a similar speed (:func:`_speeds_differ`: a
    hold pools with holds), zeroed where within ``SIGNIFICANT_SIGMAS`` standard errors of zero;
    ``left_u0_px, left_v0_px`` what that leaves in the P frames (:func:`_pooled_value`), with a
    P frame's own departure from the offset (the rows' ``jitter_*``, RMS) in quadrature: one
    offset corrects every P frame, which each depart from it by the frames' common jitter (on
    the demo 0.004-0.005 px in the top cap's v, against a pooled standard error of 0.001-0.002).
    The mean's variance: with ``MIN_SPREAD_KEYFRAMES`` distinct keyframes or more, the scatter
    of their means (over the cameras) over their number, whatever the cameras share (but no
    less than the targets' spread over every row); with fewer, the rows' spread over their
    targets averaged down over every row, and their frames' common jitter only over the
    distinct keyframes (the cameras may share it: one keyframe seen by 13 cameras is then one
    sample of it). Each row looks at a window of keyframes, so a test of thousands of GOPs
    pools in time proportional to its rows.
    """
    out = rows.reset_index(drop=True).copy()
    order = np.lexsort((out["keyframe"].to_numpy(), out["side"].to_numpy()))
    srt = out.iloc[order].reset_index(drop=True)
    side, key = srt["side"].to_numpy(), srt["keyframe"].to_numpy(np.int64)
    speed, speed_se = srt["speed_px"].to_numpy(np.float64), srt["sigma_speed_px"].to_numpy(np.float64)
    cols = [("u0_px", "sigma_u0_px", "common_u0_px"), ("v0_px", "sigma_v0_px", "common_v0_px")]
    mean = srt[[c[0] for c in cols]].to_numpy(np.float64)  # (R, 2)
    own2 = np.nan_to_num(srt[[c[1] for c in cols]].to_numpy(np.float64) ** 2)
    shared2 = np.nan_to_num(srt[[c[2] for c in cols]].to_numpy(np.float64) ** 2)
    jitter2 = np.nan_to_num(srt[["jitter_u0_px", "jitter_v0_px"]].to_numpy(np.float64) ** 2)
    pooled, left = np.zeros_like(mean), np.zeros_like(mean)
    for s in np.unique(side):
        lo_s, hi_s = np.searchsorted(side, s, "left"), np.searchsorted(side, s, "right")
        keys = np.unique(key[lo_s:hi_s])
        for i in range(lo_s, hi_s):
            j = int(np.searchsorted(keys, key[i]))
            first, last = keys[max(0, j - POOL_KEYFRAMES)], keys[min(len(keys) - 1, j + POOL_KEYFRAMES)]
            lo = lo_s + int(np.searchsorted(key[lo_s:hi_s], first, "left"))
            hi = lo_s + int(np.searchsorted(key[lo_s:hi_s], last, "right"))
            near = np.arange(lo, hi)
            near = near[~_speeds_differ(speed[i], speed_se[i], speed[near], speed_se[near])]
            pooled[i], left[i] = _pooled_value(mean[near], own2[near], shared2[near], key[near])
            # and a P frame's own departure from the offset (the jitter, which the cameras may share)
            left[i] = np.hypot(left[i], np.sqrt(jitter2[near].mean(axis=0)))
    out.loc[order, "u0_px"], out.loc[order, "v0_px"] = pooled[:, 0], pooled[:, 1]
    out.loc[order, LEFT_COLUMNS[0]], out.loc[order, LEFT_COLUMNS[1]] = left[:, 0], left[:, 1]
    return out


def _pooled_value(
    mean: np.ndarray, own2: np.ndarray, shared2: np.ndarray, key: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The pooled offset (2,) of rows (``mean``, their squared standard errors from the targets'
    spread ``own2`` and from the frames' common jitter ``shared2``, (n, 2), at keyframes ``key``),
    zeroed per axis where within ``SIGNIFICANT_SIGMAS`` standard errors of zero (see
    :func:`_pooled_offsets`), and the standard uncertainty (2,) it leaves in the P frames: its
    standard error ``se`` where applied; where not, the offset not taken off as well,
    ``sqrt(m^2 + se^2)`` (a known bias left uncorrected counts in full)."""
    n = len(mean)
    _, at = np.unique(key, return_inverse=True)
    k = int(at.max()) + 1
    per_key = np.stack([np.bincount(at, mean[:, a], k) / np.bincount(at, minlength=k) for a in range(2)], 1)
    m = mean.mean(axis=0)
    if k >= MIN_SPREAD_KEYFRAMES:  # the keyframes' own scatter says how well
        se = np.sqrt(np.maximum(per_key.var(axis=0, ddof=1) / k, own2.mean(axis=0) / n))
    else:  # too few to tell: the jitter taken as shared by every camera
        se = np.sqrt(own2.mean(axis=0) / n + shared2.mean(axis=0) / k)
    applied = np.abs(m) >= SIGNIFICANT_SIGMAS * se
    return np.where(applied, m, 0.0), np.where(applied, se, np.hypot(m, se))


def lag_corrected(
    tracks: pd.DataFrame, keyframes: np.ndarray, bodies: Mapping[str, Sequence[int]] | None = None
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """One camera's ``tracks`` with the codec's motion lag measured at its ``keyframes`` (test
    frames) and removed (and the offsets of the rigid ``bodies``): ``(corrected tracks, lags)``
    (:func:`estimate_lag`'s table)."""
    lags = estimate_lag(tracks, keyframes, bodies=bodies)
    return correct_lag(tracks, keyframes, pooled_offsets({"": lags})[""], bodies), lags


def _rows_near(keyframes: np.ndarray, lags: pd.DataFrame, first: int, last: int) -> pd.DataFrame:
    """A camera's ``lags`` with the rigid bodies' rows kept only at its ``keyframes`` from
    ``POOL_KEYFRAMES + 1`` before the last one at or before frame ``first`` to as many after the
    first one at or after ``last``: all that the correction of frames ``first..last`` needs,
    pooling windows included. A test of thousands of GOPs is then pooled per chunk in
    milliseconds (all of a 1.1 h test's rows at once: 7.7 s)."""
    keys = np.unique(np.asarray(keyframes, np.int64))
    if len(keys) == 0:
        return lags
    before = int(np.searchsorted(keys, first, "right")) - 1
    after = int(np.searchsorted(keys, last, "left"))
    lo = keys[max(0, before - POOL_KEYFRAMES - 1)]
    hi = keys[min(len(keys) - 1, after + POOL_KEYFRAMES + 1)]
    k = lags["keyframe"].to_numpy(np.int64)
    return lags[(lags["body"] == MEMBRANE).to_numpy() | ((k >= lo) & (k <= hi))]


def corrected_tracks(tracks: pd.DataFrame, lags: Mapping[str, LagFile | tuple]) -> pd.DataFrame:
    """A copy of ``tracks`` (``TRACKS`` rows of any cameras, e.g. one chunk's) with each camera's
    P frames corrected by :func:`correct_lag` from its ``(keyframes, lags[, bodies])`` in
    ``lags`` (every keyframe of the test, so a GOP cut by the chunk is corrected from both its
    ends), the rigid bodies' offsets pooled over the cameras (:func:`pooled_offsets`), with
    :func:`correct_lag`'s ``codec_u_px, codec_v_px`` (0 for cameras not in ``lags``, which are
    left as they are)."""
    out = tracks.assign(**dict.fromkeys(CODEC_COLUMNS, 0.0))
    if tracks.empty:
        return out
    span = (int(tracks["frame"].min()), int(tracks["frame"].max()))
    pooled = pooled_offsets({camera: _rows_near(got[0], got[1], *span) for camera, got in lags.items()})
    for camera, pos in tracks.groupby("camera", sort=False).indices.items():
        if camera in lags:
            keys, _, *bodies = lags[camera]
            fixed = correct_lag(tracks.iloc[pos], keys, pooled[camera], *bodies)
            cols = ["u_px", "v_px", *CODEC_COLUMNS]
            out.iloc[pos, out.columns.get_indexer(cols)] = fixed[cols].to_numpy()
    return out
