"""The codec's motion lag: measured at keyframes against synthetic truth, and removed."""

import json

import numpy as np
import pandas as pd
import pytest

from triaxtrack.codec_lag import (
    LAG_COLUMNS,
    correct_lag,
    corrected_tracks,
    estimate_lag,
    estimate_lag_chunks,
    lag_corrected,
    read_lags,
    write_lags,
)
from triaxtrack.codec_lag.correct import _coefficients

FRAMES = np.arange(61)
KEYS = np.array([0, 30, 60])


def _tracks(
    lag: float, noise: float, speed: float = 0.3, seed: int = 0, accel: float = 0.004
) -> tuple[pd.DataFrame, np.ndarray]:
    """400 dots on accelerating paths (pixels), P frames shown ``lag`` frames late, centroid
    noise ``noise`` px; returns (tracks, true positions (F, N, 2))."""
    rng = np.random.default_rng(seed)
    n = 400
    start = rng.uniform(100, 900, (n, 2))
    vel = speed * rng.normal(size=(n, 2))
    acc = accel * rng.normal(size=(n, 2))

    def at(t):
        return start + vel * t[:, None, None] + 0.5 * acc * t[:, None, None] ** 2

    t = FRAMES.astype(float)
    truth = at(t)
    shown = np.where(np.isin(FRAMES, KEYS)[:, None, None], truth, at(t - lag))
    uv = shown + rng.normal(0, noise, shown.shape)
    rows = pd.DataFrame({
        "camera": "cam01", "frame": np.repeat(FRAMES, n),
        "id": np.tile(np.arange(1001, 1001 + n), len(FRAMES)),
        "u_px": uv[:, :, 0].ravel(), "v_px": uv[:, :, 1].ravel(), "area_px": 20.0, "sigma_px": noise,
        "reason": "",
    })  # fmt: skip
    return rows, truth


def _along_velocity_error(tracks: pd.DataFrame, truth: np.ndarray, frames) -> float:
    """Mean error along the motion (pixels) over the given frames: negative = behind."""
    t = tracks.sort_values(["frame", "id"])
    uv = t[["u_px", "v_px"]].to_numpy().reshape(len(FRAMES), -1, 2)
    vel = np.gradient(truth, axis=0)
    e = ((uv - truth) * vel / np.linalg.norm(vel, axis=2, keepdims=True)).sum(axis=2)
    return float(e[list(frames)].mean())


def test_lag_measured_on_both_sides_of_every_keyframe():
    tracks, _ = _tracks(lag=0.025, noise=0.015)
    lags = estimate_lag(tracks, KEYS)
    assert sorted(zip(lags["keyframe"], lags["side"], strict=True)) == [(0, 1), (30, -1), (30, 1), (60, -1)]
    # unbiased within its own standard error (a velocity from the same frames would add ~0.02)
    assert np.all(np.abs(lags["lag_frames"] - 0.025) < 3 * lags["sigma_frames"])
    assert np.all(lags["sigma_frames"] < 0.005)


def test_correction_removes_the_lag_and_leaves_keyframes_alone():
    tracks, truth = _tracks(lag=0.03, noise=0.01)
    given = tracks.copy()
    p_frames = [f for f in FRAMES if f not in KEYS]
    before = _along_velocity_error(tracks, truth, p_frames)
    fixed, _ = lag_corrected(tracks, KEYS)
    pd.testing.assert_frame_equal(tracks, given)  # the input is not mutated
    after = _along_velocity_error(fixed, truth, p_frames)
    assert before == pytest.approx(-0.03 * 0.3 * np.sqrt(np.pi / 2), rel=0.2)  # mean speed x lag
    assert abs(after) < 0.1 * abs(before)
    keys = fixed["frame"].isin(KEYS)
    assert np.array_equal(fixed.loc[keys, "u_px"].to_numpy(), tracks.loc[keys, "u_px"].to_numpy())


@pytest.mark.parametrize("seed", range(5))
def test_dots_at_rest_are_not_moved(seed):
    tracks, _ = _tracks(lag=0.03, noise=0.015, speed=0.0, accel=0.0, seed=seed)
    fixed, lags = lag_corrected(tracks, KEYS)
    assert len(lags) == 4  # measured: no lag distinguishable from zero, so none applied
    assert np.abs(fixed[["u_px", "v_px"]] - tracks[["u_px", "v_px"]]).to_numpy().max() == 0


def test_no_keyframe_measured_means_no_correction():
    tracks, _ = _tracks(lag=0.03, noise=0.01)
    fixed, lags = lag_corrected(tracks, np.array([], np.int64))
    assert lags.empty
    assert fixed[tracks.columns].equals(tracks)
    assert (fixed[["codec_u_px", "codec_v_px"]] == 0).all().all()
    assert np.isnan(_coefficients(np.array([5]), np.array([0]), lags)).all()  # nothing measured


def test_a_field_across_the_image_is_removed_too():
    """P frames shrunk horizontally about the image centre (as the simulator's H.264 shows the
    membrane dots) besides lagging: the corrected P frames agree with the truth."""
    tracks, truth = _tracks(lag=0.02, noise=0.01)
    p = ~tracks["frame"].isin(KEYS)
    shrunk = tracks.assign(u_px=np.where(p, 500 + (tracks["u_px"] - 500) * (1 - 3e-4), tracks["u_px"]))
    fixed, lags = lag_corrected(shrunk, KEYS)
    assert np.allclose(lags["u_per_u"], 3e-4 * 1000, rtol=0.2)
    sel = fixed.sort_values(["frame", "id"])
    uv = sel[["u_px", "v_px"]].to_numpy().reshape(len(FRAMES), -1, 2)
    err = (uv - truth)[[f for f in FRAMES if f not in KEYS]]
    assert abs(err[..., 0].mean()) < 0.002 and np.sqrt((err**2).mean()) < 0.02


def test_a_first_p_frame_coded_unlike_the_rest_does_not_set_the_correction():
    """x265 codes the P frames just after a keyframe unlike the rest of the GOP: on realistic
    720p renders the membrane's horizontal shrink was 1.35 times the GOP's mean in the first P
    frame and half of it in the second. The departure measured at a keyframe is the one the
    whole GOP is corrected by, so it must stay near the GOP's mean: a quadratic through only the
    nearest five P frames weighs the first 1.8 times and read 1.7 times the mean."""
    tracks, _ = _tracks(lag=0.0, noise=0.01)
    f = tracks["frame"].to_numpy()
    since = f - np.array([KEYS[KEYS <= x].max() for x in f])
    scale = np.select([since == 0, since == 1, since == 2], [0.0, 1.4, 0.5], 1.0) * 3e-4
    shrunk = tracks.assign(u_px=500 + (tracks["u_px"] - 500) * (1 - scale))
    lags = estimate_lag(shrunk, KEYS)
    after = lags[lags["side"] > 0]
    mean = 3e-4 * 1000 * (1.4 + 0.5 + 27) / 29  # the GOP's mean shrink per FIELD_SCALE_PX
    assert np.all(np.abs(after["u_per_u"] - mean) < 0.2 * mean)


def _growing_shrink(tracks: pd.DataFrame, keys: np.ndarray, per_frame: float) -> pd.DataFrame:
    """P frames shrunk horizontally about u = 500 by ``per_frame`` for every frame since the
    last keyframe (the departure of a P frame from the picture grows along the GOP)."""
    f = tracks["frame"].to_numpy()
    since = f - np.array([keys[keys <= x].max() for x in f])
    return tracks.assign(u_px=500 + (tracks["u_px"] - 500) * (1 - per_frame * since))


@pytest.mark.parametrize(("first", "last"), [(0, 60), (15, 60), (0, 45)])
def test_a_departure_growing_along_the_gop_is_removed_in_every_p_frame(first, last):
    """The P frames' departure measured on each side of a keyframe differs: each P frame is
    corrected by the two measured around it, interpolated in time. A chunk that starts or ends
    within a GOP (frames ``first..last``) takes that GOP's missing end from its other GOP."""
    tracks, truth = _tracks(lag=0.0, noise=0.01)
    shrunk = _growing_shrink(tracks, KEYS, 2e-5)  # 0.23 px at u 900 by the GOP's last frame
    frames = FRAMES[first : last + 1]
    chunk = shrunk[shrunk["frame"].isin(frames)]
    fixed, lags = lag_corrected(chunk, KEYS[np.isin(KEYS, frames)])
    assert {k for k, s in zip(lags["keyframe"], lags["side"], strict=True) if s < 0} == {30, 60} & set(frames)

    def rms(t: pd.DataFrame) -> np.ndarray:  # per frame, of the u error (pixels)
        u = t.sort_values(["frame", "id"])["u_px"].to_numpy().reshape(len(frames), -1)
        return np.sqrt(((u - truth[frames, :, 0]) ** 2).mean(axis=1))

    p = ~np.isin(frames, KEYS)
    assert rms(chunk)[p].max() > 0.1  # the departure this corrects
    assert rms(fixed)[p].max() < 0.02  # 0.01 px of centroid noise


@pytest.mark.parametrize("size", [7, 10, 45])
def test_chunks_shorter_than_a_gop_are_measured_and_corrected_from_both_ends(size, tmp_path):
    """Chunks of ``size`` frames (7 and 10: most hold no keyframe of the 30-frame GOPs): the
    camera's departures are measured over its chunks in order (:func:`estimate_lag_chunks`),
    as on the whole test at once, written and read back, and each chunk corrected from them."""
    tracks, truth = _tracks(lag=0.02, noise=0.01)
    shrunk = _growing_shrink(tracks, KEYS, 2e-5)
    starts = range(0, len(FRAMES), size)
    chunks = [shrunk[shrunk["frame"].between(a, a + size - 1)] for a in starts]
    whole = estimate_lag(shrunk, KEYS)
    lags = estimate_lag_chunks(iter(chunks), KEYS)
    pd.testing.assert_frame_equal(lags, whole, check_dtype=False)
    path = tmp_path / "cam01.json"
    write_lags(path, "cam01", KEYS, lags)
    camera, got = read_lags(path)
    assert camera == "cam01" and np.array_equal(got.keyframes, KEYS) and got.bodies == {}
    pd.testing.assert_frame_equal(got.lags, lags, check_dtype=False)
    fixed = pd.concat([corrected_tracks(c, {camera: got}) for c in chunks])
    u = fixed.sort_values(["frame", "id"])[["u_px", "v_px"]].to_numpy().reshape(len(FRAMES), -1, 2)
    err = np.sqrt(((u - truth) ** 2).sum(axis=2).mean(axis=1))
    assert err[~np.isin(FRAMES, KEYS)].max() < 0.025  # 0.014 px of centroid noise


def test_a_bad_lag_file_names_itself(tmp_path):
    path = tmp_path / "cam01.json"
    path.write_text("{}")
    with pytest.raises(ValueError, match="cam01.json: not a codec-lag file"):
        read_lags(path)
    old = {"camera": "cam01", "keyframes": [0], "bodies": {}, "columns": list(LAG_COLUMNS[:-3]), "lags": []}
    path.write_text(json.dumps(old))  # a file of an earlier version, with fewer columns
    with pytest.raises(ValueError, match="cam01.json: .*run rule measure_codec_lag again"):
        read_lags(path)


def test_corrected_tracks_of_several_cameras_keep_their_rows():
    """Two cameras' tracks with the same index labels (joined without resetting it), one with a
    lag file, one without: every row stays where it was, only the first camera's P frames move."""
    tracks, _ = _tracks(lag=0.03, noise=0.01)
    both = pd.concat([tracks, tracks.assign(camera="cam02")])  # duplicate index labels
    lags = estimate_lag(tracks, KEYS)
    fixed = corrected_tracks(both, {"cam01": (KEYS, lags)})
    assert len(fixed) == len(both) and fixed.index.equals(both.index)
    n = len(tracks)
    expected, _ = lag_corrected(tracks, KEYS)
    np.testing.assert_allclose(fixed.iloc[:n][["u_px", "v_px"]], expected[["u_px", "v_px"]])
    pd.testing.assert_frame_equal(fixed.iloc[n:][both.columns], both.iloc[n:])
    assert (fixed.iloc[n:][["codec_u_px", "codec_v_px"]] == 0).all().all()  # nothing known of cam02


def test_a_lag_along_a_velocity_field_linear_in_the_image_is_removed():
    """Dots moving in proportion to their height (a uniform axial strain: the velocity is itself
    a field across the image, collinear with the lag term): P frames shown 0.3 frames late are
    corrected, whichever of the two collinear terms the fit keeps."""
    rng = np.random.default_rng(3)
    n = 600
    u0, v0 = rng.uniform(200, 1000, n), rng.uniform(100, 600, n)
    bottom, strain = 650.0, 2e-3  # the fixed pedestal's image row; strain per frame

    def at(t):
        return np.stack(
            [np.broadcast_to(u0, (len(t), n)), bottom - (bottom - v0) * (1 - strain * t[:, None])], axis=2
        )

    t = FRAMES.astype(float)
    truth = at(t)
    shown = np.where(np.isin(FRAMES, KEYS)[:, None, None], truth, at(t - 0.3))
    uv = shown + rng.normal(0, 0.01, shown.shape)
    tracks = pd.DataFrame({
        "camera": "cam01", "frame": np.repeat(FRAMES, n), "id": np.tile(1001 + np.arange(n), len(FRAMES)),
        "u_px": uv[:, :, 0].ravel(), "v_px": uv[:, :, 1].ravel(), "area_px": 20.0, "sigma_px": 0.01,
        "reason": "",
    })  # fmt: skip
    fixed, _ = lag_corrected(tracks, KEYS)
    p = ~np.isin(FRAMES, KEYS)
    before = np.abs((shown - truth)[p, :, 1]).mean()
    got = fixed.sort_values(["frame", "id"])["v_px"].to_numpy().reshape(len(FRAMES), n)
    after = np.abs(got[p] - truth[p, :, 1]).mean()
    assert before > 0.1 and after < 0.15 * before


def test_a_hold_and_a_reversal_within_a_gop_are_not_moved_by_the_ramp_before_them():
    """A ramp, a hold and a slow reversal in one chunk (a loading history's kinks), P frames shown
    half a frame late: the correction moves each P frame by the lag times the velocity there, so
    the hold's frames (clear of the kinks by the velocity window) stay where they are and the
    reversal's are moved forward along it. A velocity fitted over the whole chunk moved the hold
    by 0.04-0.05 px."""
    rng = np.random.default_rng(3)
    n, lag = 300, 0.5
    direction = rng.normal(size=(n, 2)) * 0.3  # pixels per unit of the history
    start = rng.uniform(100, 900, (n, 2))

    def history(t):  # ramp to 15, hold to 35, then back at a fifth of the ramp's rate
        return np.where(t < 15, t, np.where(t < 35, 15.0, 15.0 - 0.2 * (t - 35)))

    t = FRAMES.astype(float)
    truth = start + history(t)[:, None, None] * direction
    shown = np.where(
        np.isin(FRAMES, KEYS)[:, None, None], truth, start + history(t - lag)[:, None, None] * direction
    )
    uv = shown + rng.normal(0, 0.005, shown.shape)
    tracks = pd.DataFrame({
        "camera": "cam01", "frame": np.repeat(FRAMES, n),
        "id": np.tile(np.arange(1001, 1001 + n), len(FRAMES)), "u_px": uv[:, :, 0].ravel(),
        "v_px": uv[:, :, 1].ravel(), "area_px": 20.0, "sigma_px": 0.005, "reason": "",
    })  # fmt: skip
    lags = pd.DataFrame(
        [
            ("membrane", k, s, lag, 0.01, *[0.0] * 12, n, 0.3, np.nan)
            for k, s in [(0, 1), (30, -1), (30, 1), (60, -1)]
        ],
        columns=list(LAG_COLUMNS),
    )
    fixed = correct_lag(tracks, KEYS, lags).sort_values(["frame", "id"])
    err = fixed[["u_px", "v_px"]].to_numpy().reshape(len(FRAMES), n, 2) - truth
    hold = [24, 25, 26, 27]  # P frames 9 or more frames from the kinks at 15 and 35
    rms = np.sqrt((err**2).sum(axis=2).mean(axis=1))  # per frame, pixels
    assert rms[hold].max() < 0.010  # the centroid noise is 0.007 px (u and v); was 0.036-0.051
    reversal = [46, 47, 48, 49, 50, 51, 52]  # lagging 0.5 x 0.085 px before the correction
    assert rms[reversal].max() < 0.012  # was 0.020-0.045


def test_a_change_of_rate_at_a_keyframe_is_not_read_as_a_lag():
    """Slow reloading, then a ramp 30 times as fast from half a frame before keyframe 30 (as at
    a loading history's knot): the P frames before it, extrapolated to it, fall behind it by the
    new motion; that keyframe is not measured, and no P frame is moved by more than the noise."""
    rng = np.random.default_rng(5)
    n = 300
    direction = rng.normal(size=(n, 2))
    start = rng.uniform(100, 900, (n, 2))
    t = FRAMES.astype(float)
    history = np.where(t < 29.5, 0.0075 * t, 0.0075 * 29.5 + 0.22 * (t - 29.5))
    uv = start + history[:, None, None] * direction + rng.normal(0, 0.005, (len(FRAMES), n, 2))
    tracks = pd.DataFrame({
        "camera": "cam01", "frame": np.repeat(FRAMES, n),
        "id": np.tile(np.arange(1001, 1001 + n), len(FRAMES)), "u_px": uv[:, :, 0].ravel(),
        "v_px": uv[:, :, 1].ravel(), "area_px": 20.0, "sigma_px": 0.005, "reason": "",
    })  # fmt: skip
    fixed, lags = lag_corrected(tracks, KEYS)
    assert 30 not in lags["keyframe"].tolist()
    assert {0, 60} <= set(lags["keyframe"].tolist())
    moved = np.hypot(fixed["u_px"] - tracks["u_px"], fixed["v_px"] - tracks["v_px"])
    assert moved.max() < 0.02


def _rigid_tracks(
    camera: str, speed: float, departure, noise: float, seed: int, jitter: np.ndarray | None = None
) -> tuple[pd.DataFrame, np.ndarray]:
    """One camera's tracks of a top cap (IDs 1-5, moving ``speed`` px a frame down the image)
    and a fixed pedestal (IDs 17-21), with the cap's P frames shown ``departure(t)`` px lower
    (``t`` frames since the GOP's keyframe) and by ``jitter`` (F,) more (the whole cap, every
    frame), ``noise`` px of centroid noise; returns (tracks,
    the cap's true positions (F, 5, 2))."""
    rng = np.random.default_rng(seed)
    cap = rng.uniform(200, 800, (5, 2)) + np.c_[np.zeros(len(FRAMES)), speed * FRAMES][:, None, :]
    fixed = np.broadcast_to(rng.uniform(200, 800, (5, 2)), cap.shape)
    since = FRAMES - np.array([KEYS[KEYS <= f].max() for f in FRAMES])
    lift = departure(since) + (0 if jitter is None else jitter)
    shown = cap + np.c_[np.zeros(len(FRAMES)), lift][:, None, :]
    uv = np.concatenate([shown, fixed], axis=1) + rng.normal(0, noise, (len(FRAMES), 10, 2))
    rows = pd.DataFrame({
        "camera": camera, "frame": np.repeat(FRAMES, 10),
        "id": np.tile([1, 2, 3, 4, 5, 17, 18, 19, 20, 21], len(FRAMES)),
        "u_px": uv[:, :, 0].ravel(), "v_px": uv[:, :, 1].ravel(), "area_px": 20.0, "sigma_px": noise,
        "reason": "",
    })  # fmt: skip
    return rows, cap


BODIES = {"pedestal_top": [1, 2, 3, 4, 5], "pedestal_bottom": [17, 18, 19, 20, 21]}


def _cap_error(tracks: pd.DataFrame, cap: np.ndarray) -> np.ndarray:
    """Mean v error of the cap's targets per frame (pixels)."""
    t = tracks[tracks["id"] <= 5].sort_values(["frame", "id"])
    return (t["v_px"].to_numpy().reshape(len(FRAMES), 5) - cap[..., 1]).mean(axis=1)


def test_a_rigid_body_offset_in_p_frames_is_removed_and_a_fixed_body_left_alone():
    """The top cap's CTs read 0.011 px ahead in every P frame (the simulator's H.264 at 0.3 px a
    frame): measured per body at the keyframes, pooled, taken off; the fixed pedestal's
    targets, with no offset, are not moved at all."""
    tracks, cap = _rigid_tracks("cam01", 0.3, lambda t: np.where(t > 0, 0.011, 0.0), 0.003, 0)
    fixed, lags = lag_corrected(tracks, KEYS, BODIES)
    p = ~np.isin(FRAMES, KEYS)
    assert abs(_cap_error(tracks, cap)[p].mean() - 0.011) < 0.002  # the departure this corrects
    assert abs(_cap_error(fixed, cap)[p].mean()) < 0.002
    bottom = tracks["id"] >= 17
    assert np.array_equal(fixed.loc[bottom, "v_px"].to_numpy(), tracks.loc[bottom, "v_px"].to_numpy())
    assert set(lags["body"]) == {"pedestal_top", "pedestal_bottom"}  # no membrane dots: no rows


def test_a_slow_body_departure_rises_across_the_gop_and_is_pooled_over_cameras():
    """A cap moving 0.0012 px a frame departs 0.008 px behind, reached only after some frames
    (the departure rises no faster than the cap moves): 13 cameras' offsets pooled (one camera's
    rests on 5 targets), each P frame corrected by the rising curve, not a straight line."""
    speed, depth = 0.0012, -0.008

    def departure(t):
        return depth * (1 - np.exp(-t * speed / abs(depth)))

    cams = [_rigid_tracks(f"cam{i:02d}", speed, departure, 0.002, i) for i in range(13)]
    tracks = pd.concat([t for t, _ in cams], ignore_index=True)
    lags = {
        f"cam{i:02d}": (KEYS, estimate_lag(t, KEYS, bodies=BODIES), BODIES) for i, (t, _) in enumerate(cams)
    }
    fixed = corrected_tracks(tracks, lags)
    p = ~np.isin(FRAMES, KEYS)
    before = np.mean([_cap_error(t, cap) for t, cap in cams], axis=0)
    after = np.mean(
        [_cap_error(fixed[fixed["camera"] == t["camera"].iloc[0]], cap) for t, cap in cams], axis=0
    )
    assert np.abs(before[p]).max() > 0.006
    assert np.abs(after[p]).max() < 0.002
    chunks = [tracks[tracks["frame"].between(a, a + 9)] for a in range(0, len(FRAMES), 10)]
    by_chunk = pd.concat([corrected_tracks(c, lags) for c in chunks]).sort_index()
    pd.testing.assert_frame_equal(by_chunk, fixed)  # each chunk pools only the keyframes near it


def test_a_jitter_common_to_every_camera_is_not_read_as_an_offset():
    """The cap's targets jump together by 0.04 px from frame to frame in all 13 cameras at once
    (as on a realistic 720p render), with no offset: with one keyframe, the 13 cameras hold one
    sample of that jitter, so the quadratic extrapolated to the keyframe (0.1 px off) is not
    significant and nothing is applied."""
    jitter = np.random.default_rng(99).normal(0, 0.04, len(FRAMES))
    keys = np.array([0])
    cams = [_rigid_tracks(f"cam{i:02d}", 0.3, lambda t: 0 * t, 0.002, i, jitter) for i in range(13)]
    tracks = pd.concat([t for t, _ in cams], ignore_index=True)
    lags = {t["camera"].iloc[0]: (keys, estimate_lag(t, keys, bodies=BODIES), BODIES) for t, _ in cams}
    measured = pd.concat([got[1] for got in lags.values()])
    top = measured[measured["body"] == "pedestal_top"]
    assert abs(top["v0_px"].mean()) > 3 * np.sqrt((top["sigma_v0_px"] ** 2).mean() / len(top))  # spread alone
    fixed = corrected_tracks(tracks, lags)
    assert np.abs(fixed["v_px"] - tracks["v_px"]).max() == 0
    # what is not taken off is carried as the P frames' uncertainty, in full
    p, cap = ~fixed["frame"].isin(keys), fixed["id"] <= 5
    assert (fixed.loc[p & cap, "codec_v_px"] >= abs(top["v0_px"].mean())).all()
    assert (fixed.loc[~p, "codec_v_px"] == 0).all()  # keyframes show the targets where they are


def test_an_offset_taken_off_leaves_its_standard_error_in_the_p_frames():
    """The cap's 0.011 px offset is taken off; what each P-frame observation carries is the
    pooled offset's standard error, well below the offset; keyframes and membrane dots carry 0."""
    tracks, _ = _rigid_tracks("cam01", 0.3, lambda t: np.where(t > 0, 0.011, 0.0), 0.003, 0)
    fixed, _ = lag_corrected(tracks, KEYS, BODIES)
    p, cap = ~fixed["frame"].isin(KEYS), fixed["id"] <= 5
    left = fixed.loc[p & cap, "codec_v_px"]
    assert 0 < left.min() and left.max() < 0.011 / 3
    assert (fixed.loc[~p, ["codec_u_px", "codec_v_px"]] == 0).all().all()
    dots, _ = _tracks(0.03, 0.005)
    assert (lag_corrected(dots, KEYS)[0][["codec_u_px", "codec_v_px"]] == 0).all().all()  # membrane: 0


def test_a_p_frames_own_jitter_about_the_offset_is_carried_in_its_uncertainty():
    """One pooled offset (0.011 px) corrects every P frame, and each P frame departs from it by
    the frames' common jitter (0.003 px here, the same in all 13 cameras): the uncertainty each
    P-frame observation carries holds that jitter on top of the offset's standard error (0.0043
    px when written; the standard error alone, from the keyframes' scatter, 0.0032), and the
    cap's corrected P frames lie within 2 of it at nearly every frame."""
    jitter = np.random.default_rng(7).normal(0, 0.003, len(FRAMES))
    cams = [
        _rigid_tracks(f"cam{i:02d}", 0.3, lambda t: np.where(t > 0, 0.011, 0.0), 0.002, i, jitter)
        for i in range(13)
    ]
    tracks = pd.concat([t for t, _ in cams], ignore_index=True)
    lags = {t["camera"].iloc[0]: (KEYS, estimate_lag(t, KEYS, bodies=BODIES), BODIES) for t, _ in cams}
    fixed = corrected_tracks(tracks, lags)
    p = ~np.isin(FRAMES, KEYS)
    one = fixed[fixed["camera"] == "cam00"]
    left = one[(one["id"] <= 5) & ~one["frame"].isin(KEYS)]["codec_v_px"]
    assert left.min() > 1.2 * 0.003
    err = np.mean([_cap_error(fixed[fixed["camera"] == t["camera"].iloc[0]], cap) for t, cap in cams], axis=0)
    assert np.mean(np.abs(err[p]) <= 2 * left.median()) > 0.9
