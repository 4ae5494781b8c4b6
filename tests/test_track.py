"""Tracking (triaxtrack.track) and the per-timestep checks (triaxtrack.timesteps) on synthetic
frames: a grid of dark dots that deforms smoothly, with an occluding bar and a missing frame."""

import cv2
import numpy as np
import pandas as pd
import pytest
from test_image_quality import _dots  # exact discs, blurred and noised

from triaxtrack.completion import Candidates, DotGrid, grid_candidates
from triaxtrack.detect import detect_blobs
from triaxtrack.optics import Camera, project_air
from triaxtrack.timesteps import (
    camera_motion,
    handover_check,
    large_losses,
    observations_table,
    tracking_summary,
)
from triaxtrack.track import (
    TrackingConfig,
    measure_blobs,
    measure_targets,
    processed_frames,
    track_frames,
)
from triaxtrack.track_kernels import shape_changed
from triaxtrack.track_stage import chunk_frames

W, H = 360, 240
SS = 8  # supersampling of the renderer
DOT_R = 2.6  # px
SPACING = 10.0  # px
FRAMES = 30


def truth_positions(frame: int) -> tuple[np.ndarray, np.ndarray]:
    """IDs and (N, 2) centres: a grid that compresses vertically, bulges and shifts (2 px/frame)."""
    j, i = np.mgrid[0:14, 0:28]
    u0 = 40.0 + SPACING * i.ravel()
    v0 = 40.0 + SPACING * j.ravel()
    p = frame / (FRAMES - 1)
    u = u0 + 0.3 * frame + 3.0 * p * np.sin(np.pi * (v0 - 40) / 130) * (u0 - 180) / 140
    v = 120 + (v0 - 120) * (1 - 0.08 * p) + 0.5 * frame
    return 1001 + np.arange(u.size), np.c_[u, v]


def bar_columns(frame: int) -> tuple[float, float]:
    """A white occluding bar (a cell band in front of the membrane) sliding right, 3 px/frame."""
    return 100.0 + 3 * frame, 112.0 + 3 * frame


def render(frame: int, noise: float = 1.0, seed: int = 0) -> np.ndarray:
    _, uv = truth_positions(frame)
    big = np.full((H * SS, W * SS), 220, np.uint8)
    for u, v in uv:
        c = (int(round(((u + 0.5) * SS - 0.5) * 16)), int(round(((v + 0.5) * SS - 0.5) * 16)))
        cv2.circle(big, c, int(DOT_R * SS * 16), 25, -1, cv2.LINE_AA, shift=4)
    img = cv2.resize(big, (W, H), interpolation=cv2.INTER_AREA).astype(np.float64)
    a, b = bar_columns(frame)
    img[:, int(np.ceil(a)) : int(np.floor(b)) + 1] = 235.0
    img += np.random.default_rng(seed + frame).normal(0, noise, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def first_labels(frame: int = 0) -> pd.DataFrame:
    """Labels as identification gives them: detected blobs, the nearest true dot's ID."""
    blobs = detect_blobs(render(frame))
    ids, uv = truth_positions(frame)
    d = np.hypot(*(blobs[["u_px", "v_px"]].to_numpy()[:, None] - uv[None]).transpose(2, 0, 1))
    near = d.argmin(axis=1)
    lab = np.where(d.min(axis=1) < 1.0, ids[near], -1)
    return blobs.assign(camera="cam01", frame=frame, id=lab)


@pytest.fixture(scope="module")
def tracked() -> pd.DataFrame:
    frames = ((k, None if k == 12 else render(k)) for k in range(FRAMES))
    return track_frames(frames, first_labels(), "cam01", range(FRAMES))


def test_reported_dots_are_their_own(tracked):
    ids, _ = truth_positions(0)
    errs, clear = [], []
    for k, g in tracked[tracked["reason"] == ""].groupby("frame"):
        t_ids, uv = truth_positions(k)
        t = pd.DataFrame(uv, index=t_ids, columns=["u", "v"]).loc[g["id"]]
        errs.append(np.hypot(*(g[["u_px", "v_px"]].to_numpy() - t[["u", "v"]].to_numpy()).T))
        a, b = bar_columns(k)
        clear.append((t["u"].to_numpy() < a - DOT_R - 1) | (t["u"].to_numpy() > b + DOT_R + 1))
    err, clear = np.concatenate(errs), np.concatenate(clear)
    assert err.max() < 1.0  # zero ID swaps: every reported dot is within 1 px of its own centre
    # sub-pixel accurate away from the bar (the renderer's dots are exact discs) ...
    assert np.median(err[clear]) < 0.03 and np.percentile(err[clear], 99) < 0.1
    # ... and a dot partly hidden by the bar is dropped before its centroid is far off
    assert np.percentile(err[~clear], 99) < 0.6


def test_the_first_frame_leaves_out_a_target_whose_centroids_disagree():
    """At the labelled frame a target whose identification centroid is farther than
    ``first_agreement_px`` from the tracker's is left out of the chunk (``disagrees``: on the
    demo, the visible sliver of a dot whose centre is behind a band); one within it is followed."""
    lab = first_labels()
    ids = lab["id"].to_numpy()
    near = np.flatnonzero(ids > 0)[:40:2]
    far = np.flatnonzero(ids > 0)[1:40:2]
    lab.loc[near, "u_px"] += 0.1
    lab.loc[far, "u_px"] += 0.4
    tr = track_frames(((k, render(k)) for k in range(3)), lab, "cam01", range(3))
    first = tr[tr["frame"] == 0].set_index("id")
    assert (first.loc[ids[near], "reason"] == "").all()
    assert (first.loc[ids[far], "reason"] == "disagrees").all()
    last = tr[(tr["frame"] == 2) & tr["id"].isin(ids[far])]
    assert (last["reason"] == "disagrees").all()  # for the whole chunk


def test_occluded_dots_are_dropped_and_picked_up_again(tracked):
    rep = tracked[tracked["reason"] == ""]
    first = set(rep.loc[rep["frame"] == 0, "id"])
    # a dot hidden by the bar at frame 20 but clear of it at 0 and 29
    ids, uv = truth_positions(20)
    a, b = bar_columns(20)
    hidden = set(ids[(uv[:, 0] > a + 1) & (uv[:, 0] < b - 1)])
    assert hidden
    at20 = set(rep.loc[rep["frame"] == 20, "id"])
    assert not (hidden & at20)
    reasons = tracked[(tracked["frame"] == 20) & tracked["id"].isin(hidden)]["reason"]
    assert reasons.isin(["lost", "shape", "merged", "drift", "jump"]).all()
    # the bar has moved on at the last frame: the dots it hid at frame 20 are back
    a, b = bar_columns(FRAMES - 1)
    ids29, uv29 = truth_positions(FRAMES - 1)
    clear = set(ids29[(uv29[:, 0] < a - 4) | (uv29[:, 0] > b + 4)])
    back = hidden & clear & first
    # picked up again once reported neighbours vouch for them
    assert back and back <= set(rep.loc[rep["frame"] == FRAMES - 1, "id"])


def test_dots_hidden_at_the_labelled_frame_are_taken_on_once_seen():
    """With the grid of IDs, the dots under the bar at the labelled frame (never labelled) are
    taken on from their reported neighbours once the bar has passed, each its own dot; without
    it they are never followed."""
    ids, uv = truth_positions(0)
    grid = DotGrid(ids.reshape(14, 28), aspect=1.0)  # a square grid seen face on
    frames = [(k, render(k)) for k in range(FRAMES)]
    tracks = track_frames(frames, first_labels(), "cam01", range(FRAMES), grid=grid)
    labelled = set(first_labels()["id"])
    a, b = bar_columns(0)
    hidden = set(ids[(uv[:, 0] > a - 2) & (uv[:, 0] < b + 2)]) - labelled
    assert len(hidden) >= 14  # a column of the grid at least
    a, b = bar_columns(FRAMES - 1)
    ids29, uv29 = truth_positions(FRAMES - 1)
    row = (ids29 - ids29.min()) // grid.ids.shape[1]
    inner = (row > 0) & (row < grid.ids.shape[0] - 1)  # between rows (interpolated, never extrapolated)
    clear = set(ids29[inner & ((uv29[:, 0] < a - 4) | (uv29[:, 0] > b + 4))])
    rep = tracks[tracks["reason"] == ""]
    last = set(rep.loc[rep["frame"] == FRAMES - 1, "id"])
    assert len(hidden & clear & last) >= 0.95 * len(hidden & clear)
    for k, g in rep[~rep["id"].isin(labelled)].groupby("frame"):
        true = pd.DataFrame(truth_positions(k)[1], index=ids, columns=["u", "v"]).loc[g["id"]]
        assert np.hypot(*(g[["u_px", "v_px"]].to_numpy() - true.to_numpy()).T).max() < 0.5, k
    plain = track_frames(frames, first_labels(), "cam01", range(FRAMES))
    assert not (set(plain["id"]) & hidden)


def _hidden_at_start(
    monkeypatch, hidden: np.ndarray, lo: np.ndarray, hi: np.ndarray, frames: int, bar=(W + 10.0, W + 20.0)
):
    """Track ``frames`` frames (the white ``bar`` still: columns, by default out of the picture)
    whose pixels ``lo``..``hi`` (u, v; inclusive) are white in frames 0-2, the dots ``hidden``
    (a mask over the grid) unlabelled at frame 0 as it left them, with completion; returns the
    reported rows, after checking that every taken-on dot is within 0.5 px of its truth."""
    import sys

    monkeypatch.setattr(sys.modules[__name__], "bar_columns", lambda frame: bar)
    ids, _ = truth_positions(0)

    def frame(k):
        img = render(k)
        if k < 3:
            img[int(lo[1]) : int(hi[1]) + 1, int(lo[0]) : int(hi[0]) + 1] = 220
        return k, img

    labels = first_labels()
    labels = labels.assign(id=np.where(labels["id"].isin(ids[hidden]), -1, labels["id"]))
    grid = DotGrid(ids.reshape(14, 28), aspect=1.0)
    tracks = track_frames([frame(k) for k in range(frames)], labels, "cam01", range(frames), grid=grid)
    rep = tracks[tracks["reason"] == ""]
    for k, g in rep[rep["id"].isin(ids[hidden])].groupby("frame"):
        true = pd.DataFrame(truth_positions(k)[1], index=ids, columns=["u", "v"]).loc[g["id"]]
        assert np.hypot(*(g[["u_px", "v_px"]].to_numpy() - true.to_numpy()).T).max() < 0.5, k
    return rep


def test_a_band_of_rows_hidden_at_the_labelled_frame_is_filled_row_by_row(monkeypatch):
    """Four rows under a strap for the first frames (wider than the neighbours that interpolate a
    dot reach): once it is gone they are taken on from their edges inward, each its own dot."""
    ids, uv0 = truth_positions(0)
    rows = (ids - ids.min()) // 28
    strap = (rows >= 5) & (rows <= 8)
    top, bottom = uv0[rows == 4, 1].max() + 4, uv0[rows == 9, 1].min() - 4
    rep = _hidden_at_start(monkeypatch, strap, np.array([0, top]), np.array([W, bottom]), 12)
    last = set(rep.loc[rep["frame"] == 11, "id"])
    inside = set(ids[strap & (uv0[:, 0] > 50) & (uv0[:, 0] < 300)])  # columns between seen ones
    assert len(inside & last) >= 0.95 * len(inside)


def test_a_row_half_under_a_strap_is_not_taken_on_until_clear(monkeypatch):
    """Four rows under a white band at the labelled frame; from frame 3 only a thin strip of it
    is left, across the upper half of the lowest row's dots (as a strap's edge lies across a row
    emerging from under it): the rows above are taken on, each its own dot, but not the
    half-hidden one (its centroid a pixel off), whose masses are half its neighbours'. Without
    the dots' printed sizes (no mass check against the neighbours) it is taken on instead."""
    import sys

    monkeypatch.setattr(sys.modules[__name__], "bar_columns", lambda frame: (W + 10.0, W + 20.0))
    ids, uv0 = truth_positions(0)
    rows = (ids - ids.min()) // 28
    strap = (rows >= 5) & (rows <= 8)

    def frame(k):
        img = render(k)
        uv = truth_positions(k)[1]
        edge = uv[rows == 8, 1].mean()  # the strap's lower edge from frame 3: across row 8
        top, low = (uv[rows == 4, 1].max() + 4, uv[rows == 9, 1].min() - 4) if k < 3 else (edge - 5, edge)
        img[int(top) : int(low) + 1, :] = 220
        return k, img

    labels = first_labels()
    labels = labels.assign(id=np.where(labels["id"].isin(ids[strap]), -1, labels["id"]))
    frames = [frame(k) for k in range(10)]

    def taken(size) -> tuple[set, set]:
        """The strap's dots reported at the last frame, and at any frame."""
        grid = DotGrid(ids.reshape(14, 28), aspect=1.0, size=size)
        tracks = track_frames(frames, labels, "cam01", range(10), grid=grid)
        rep = tracks[(tracks["reason"] == "") & tracks["id"].isin(ids[strap])]
        return set(rep.loc[rep["frame"] == 9, "id"]), set(rep["id"])

    last, ever = taken(np.ones((14, 28)))
    inside = (uv0[:, 0] > 50) & (uv0[:, 0] < 300)  # columns between seen ones
    assert len(last & set(ids[(rows == 7) & inside])) >= 0.95 * len(ids[(rows == 7) & inside])
    assert not ever & set(ids[rows == 8])
    # without: the half-hidden row is taken on (and then flickers on its mass), the row above not
    last, ever = taken(None)
    assert len(ever & set(ids[rows == 8])) >= 0.95 * 24 and not last & set(ids[rows == 7])


def test_a_box_hidden_at_the_labelled_frame_is_taken_on_within_two_frames_of_leaving(monkeypatch):
    """A box over six rows and eight columns at the labelled frame and the next two (an
    occluder, issue 20's fault): once it has gone (frame 3) the grid grows into it from its edges
    within one frame, so at least 95 % of its dots are reported from frame 4 on, each its own
    (a ring every two frames before: 24 of 48 at frame 4)."""
    ids, uv0 = truth_positions(0)
    rows, cols = (ids - ids.min()) // 28, (ids - ids.min()) % 28
    box = (rows >= 4) & (rows <= 9) & (cols >= 8) & (cols <= 15)
    rep = _hidden_at_start(monkeypatch, box, uv0[box].min(axis=0) - 4, uv0[box].max(axis=0) + 4, 8)
    hidden = set(ids[box])
    for k in (4, 5, 6, 7):
        assert len(hidden & set(rep.loc[rep["frame"] == k, "id"])) >= 0.95 * len(hidden), k


def test_a_large_box_hidden_at_the_labelled_frame_is_taken_on_and_kept(monkeypatch):
    """A box over ten rows and sixteen columns beside a white bar (issue 20's occlusion: a hand
    or a cable in front of a camera at the chunk's first frames): the grid grows into it from
    every edge within the frame, extrapolating a step beyond two reported rows or columns, so
    its dots are reported from frame 4 on (but for the column beside the bare bar, each the last
    of its row), and the tracker keeps them: those taken on together are each other's
    neighbours, placed at the reference frame on one smooth displacement field."""
    ids, uv0 = truth_positions(0)
    rows, cols = (ids - ids.min()) // 28, (ids - ids.min()) % 28
    box = (rows >= 2) & (rows <= 11) & (cols >= 6) & (cols <= 21)
    lo, hi = uv0[box].min(axis=0) - 4, uv0[box].max(axis=0) + 4
    rep = _hidden_at_start(monkeypatch, box, lo, hi, 10, bar=(hi[0] + 3, hi[0] + 22))
    hidden = set(ids[box & (cols < 21)])  # the last column, beside the bare bar, is its row's last
    for k in range(4, 10):  # 142 of 150 before: the columns beside the bar were never placed
        assert len(hidden & set(rep.loc[rep["frame"] == k, "id"])) >= 0.99 * len(hidden), k


def test_candidates_keep_their_streaks_when_others_are_taken_on():
    """A 6 x 6 grid followed but for a 2 x 2 patch (rows 2-3, columns 2-3) and a dot (4, 4):
    after the dot is taken on, the patch's dots keep the frames they had passed (they are taken
    on the frame after, not two frames later), and one reached only by growth stays a candidate
    while on a streak."""
    grid = np.arange(36).reshape(6, 6)
    patch = np.array([14, 15, 20, 21])
    followed = np.setdiff1d(grid.ravel(), np.r_[patch, 28])
    before = grid_candidates(grid, followed)
    assert set(before.ids) == {*patch, 28}
    passed = Candidates(before.ids, before.row, before.col, np.where(before.ids == 21, 0, 1))
    after = grid_candidates(grid, np.r_[followed, 28], passed)
    streak = dict(zip(after.ids.tolist(), after.streak.tolist(), strict=True))
    assert streak == {14: 1, 15: 1, 20: 1, 21: 0}
    hidden = np.setdiff1d(grid.ravel(), grid[1:5].ravel())  # rows 1-4 hidden: too few followed
    grown = Candidates(np.array([14]), np.array([2]), np.array([2]), np.array([1]))
    assert 14 not in grid_candidates(grid, hidden).ids
    assert 14 in grid_candidates(grid, hidden, grown).ids


def test_missing_frame_is_not_recorded_and_tracking_continues(tracked):
    f12 = tracked[tracked["frame"] == 12]
    assert (f12["reason"] == "not_recorded").all()
    n0 = (tracked[tracked["frame"] == 0]["reason"] == "").sum()
    n13 = (tracked[tracked["frame"] == 13]["reason"] == "").sum()
    assert n13 >= 0.85 * n0


def test_summary_counts_every_row(tracked):
    s = tracking_summary(tracked)
    per_frame = tracked.groupby("frame").size().to_numpy()
    assert s.drop(columns=["camera", "frame"]).sum(axis=1).eq(per_frame).all()


def test_merged_and_lost_blobs_are_flagged():
    img = np.full((60, 60), 220, np.uint8)
    cv2.circle(img, (20, 20), 3, 20, -1)
    cv2.circle(img, (24, 20), 3, 20, -1)  # touching its neighbour: one blob of two dots
    cv2.circle(img, (40, 40), 3, 20, -1)
    at = np.array([[20.0, 20.0], [40.2, 39.8], [10.0, 45.0], [1.0, 1.0]])
    uv, area, mass, reason = measure_blobs(img, at, np.full(4, 4.0))
    assert list(reason) == ["merged", "", "lost", "edge"]
    assert np.allclose(uv[1], [40, 40], atol=0.05)
    assert 25 <= area[1] <= 37 and mass[1] > 25 * 150


@pytest.mark.parametrize("pitch", [5.5, 6.0])
def test_touching_dots_are_measured_apart_and_a_dot_touching_an_edge_is_merged(pitch):
    """Two dots (radius 2.5 px) ``pitch`` apart, blurred by 1 px (one blob), both targets: each is
    measured on its side of the valley between them, within 0.25 px of its centre (0.06-0.22 px
    here: the other's fringe on its side); a dot beside a dark bar that is no target stays
    'merged'. (5 px apart the valley is 12 grey levels deep at a noise of 3-4: one blob.)"""
    centres = np.array([[20.3, 20.2], [20.3, 20.2 + pitch], [50.2, 40.1]])
    img = _dots(centres, 2.5, shape=(80, 1280), blur=1.0, noise=3.0, seed=1).astype(np.float32)
    img[30:50, 53:60] = np.minimum(img[30:50, 53:60], 40)  # a dark bar beside the third dot
    img = np.clip(np.round(cv2.GaussianBlur(img, (0, 0), 0.5)), 0, 255).astype(np.uint8)
    m = measure_targets(img, centres + [[0.3, -0.2], [-0.2, 0.3], [0.1, 0.1]], np.full(3, 3.5))
    assert list(m.reason) == ["", "", "merged"]
    assert (np.hypot(*(m.uv[:2] - centres[:2]).T) < 0.25).all()
    assert list(m.divided) == [True, True, False]


@pytest.mark.parametrize("radius, disc", [(3.0, 2.7), (2.5, 2.0)])
def test_a_dot_larger_than_its_disc_is_measured_whole(radius, disc):
    """Dots (blur 1 px, noise 4) followed in discs about a pixel too small for them (a soft dot's
    thresholded area at identification undersizes it), predicted up to 0.8 px off: those whose
    ink beyond the disc is faint are measured again in a disc a pixel wider, within 0.2 px (in
    their own disc alone they were read 0.5-2 px off: their ink beyond the disc counted as other
    ink, its fringe kept out of the weights); those whose ink beyond it is dark stay 'merged'
    (it may be two dots)."""
    rng = np.random.default_rng(2)
    centres = np.c_[20 + 25 * np.arange(80) + rng.uniform(-0.5, 0.5, 80), 30 + rng.uniform(-0.5, 0.5, 80)]
    img = _dots(centres, radius, shape=(60, 2048), blur=1.0, noise=4.0, seed=5)
    m = measure_targets(img, centres + rng.uniform(-0.8, 0.8, centres.shape), np.full(len(centres), disc))
    clean = m.reason == ""
    assert clean.sum() >= 5 and set(m.reason[~clean]) <= {"merged"}
    assert np.hypot(*(m.uv - centres).T)[clean].max() < 0.2


def test_a_divided_dots_mass_is_checked_against_the_scatter_of_its_own_class():
    """Touching dots' masses end at a valley line that moves with the noise: their frame-to-frame
    scatter (0.05 here) is their own. A 15 % change is 3 of their standard deviations (kept) but
    7 of the free dots' 0.02 and beyond ``mass_step`` (dropped); 30 % is beyond either."""
    rng = np.random.default_rng(3)
    free, div = 200, 40
    last = np.full(free + div, 10.0)
    change = np.r_[rng.normal(0, 0.02, free), rng.normal(0, 0.05, div)]
    change[[0, 1, free, free + 1]] = [0.15, 0.30, 0.15, 0.30]
    mass = last * (1 + change)
    divided = np.r_[np.zeros(free, bool), np.ones(div, bool)]
    n, zeros = len(mass), np.zeros(len(mass))
    args = (np.ones(n, bool), np.zeros(n, np.int64))
    shape = shape_changed(mass, zeros, last, zeros, last, zeros, *args, divided, 0.25, 0.1, 4.0, 20, 1.4826)
    assert list(shape[[0, 1, free, free + 1]]) == [True, True, False, True]
    assert shape[2:free].sum() <= 1 and shape[free + 2 :].sum() <= 1  # noise passes
    # without the class, the divided dot's 15 % is a drop as the free dot's is
    every = shape_changed(
        mass, zeros, last, zeros, last, zeros, *args, np.zeros(n, bool), 0.25, 0.1, 4.0, 20, 1.4826
    )
    assert every[free]


@pytest.mark.parametrize("radius", [9.5, 33.5])  # a window of 25 and of 73 columns (the two growings)
def test_the_blob_is_all_the_ink_connected_within_its_disc(radius):
    """A dot trailing a thin two-turn spiral inside its disc: the blob is all of it, however far
    round the way (the ink connected to the centre), and its centroid that of all its pixels
    (equally dark, on an exactly white ground)."""
    size = int(4 * radius)
    img = np.full((size, size), 200, np.uint8)
    c = size // 2
    cv2.circle(img, (c, c), int(radius // 4), 20, -1)
    t = np.linspace(0, 4 * np.pi, 400)
    r = radius // 4 + (radius - radius // 4 - 2.5) * t / t[-1]
    cv2.polylines(img, [np.c_[c + r * np.cos(t), c + r * np.sin(t)].round().astype(np.int32)], False, 20, 1)
    m = measure_targets(img, np.array([[c + 0.2, c - 0.1]]), np.array([radius]))
    ys, xs = np.nonzero(img == 20)
    assert m.reason[0] == "" and m.area[0] == len(xs)
    assert np.allclose(m.uv[0], [xs.mean(), ys.mean()], atol=1e-9)


def test_processed_frames_and_chunk_plan():
    assert processed_frames(5, 15.0, None).tolist() == [0, 1, 2, 3, 4]
    # one frame every 5 s at 15 fps, and always the last frame
    assert processed_frames(200, 15.0, 5.0).tolist() == [0, 75, 150, 199]
    lab = pd.DataFrame({"frame": [50, 50], "id": [1, 2]})
    fmap = pd.DataFrame({"frame": np.arange(120)})
    plan = chunk_frames(lab, fmap, 15.0, {"start": 50, "stop": 100}, TrackingConfig())
    assert (plan.first, plan.end, plan.handover) == (50, 101, 100)
    assert plan.report.tolist() == list(range(50, 101))
    last = chunk_frames(lab.assign(frame=100), fmap, 15.0, {"start": 100, "stop": 120}, TrackingConfig())
    assert (last.end, last.handover) == (120, -1)
    with pytest.raises(ValueError, match="labels.parquet"):
        chunk_frames(lab.assign(frame=3), fmap, 15.0, {"start": 50, "stop": 100}, TrackingConfig(),
                     "labels.parquet")  # fmt: skip


def test_handover_disagreement_is_counted():
    tracked = pd.DataFrame({"id": [1, 2, 3], "u_px": [10.0, 20.0, 30.0], "v_px": [5.0, 5.0, 5.0],
                            "reason": ["", "", "lost"]})  # fmt: skip
    labels = pd.DataFrame({"id": [1, 2, 4, -1], "u_px": [10.2, 27.0, 50.0, 1.0], "v_px": [5.0] * 4})
    h = handover_check(tracked, labels, 1.0)
    assert (h["both"], h["agree"], h["disagree"], h["tracked_only"], h["labelled_only"]) == (2, 1, 1, 0, 1)
    assert h["disagreeing_ids"] == [2]


def test_a_moved_camera_is_found():
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    cam = Camera("cam01", 640, 480, K, np.zeros(5), np.eye(3), np.array([0.0, 0.0, 300.0]))
    rng = np.random.default_rng(1)
    wall = pd.DataFrame(rng.uniform(-60, 60, (40, 3)), columns=["x_mm", "y_mm", "z_mm"])
    wall = wall.assign(id=np.arange(101, 141))
    uv = project_air(cam, wall[["x_mm", "y_mm", "z_mm"]].to_numpy())
    rows = []
    for frame in range(4):
        shift = 0.0 if frame < 2 else 0.8  # the camera is knocked between frames 1 and 2
        seen = {"u_px": uv[:, 0] + shift, "v_px": uv[:, 1], "area_px": 9.0, "reason": ""}
        rows.append(pd.DataFrame({"camera": "cam01", "frame": frame, "id": wall["id"], **seen}))
    motion, poses = camera_motion({"cam01": cam}, wall, pd.concat(rows), moved_px=0.3)
    assert motion["moved"].tolist() == [False, False, True, True]
    assert motion["drift_px"].iloc[0] < 1e-6 and motion["drift_px"].iloc[3] == pytest.approx(0.8, abs=1e-6)
    # a pixel shift of 0.8 px is a small turn of the camera: it is posed again at frames 2 and 3
    assert motion["reposed"].tolist() == [False, False, True, True]
    assert set(poses) == {("cam01", 2), ("cam01", 3)}
    moved = project_air(poses[("cam01", 2)], wall[["x_mm", "y_mm", "z_mm"]].to_numpy())
    assert np.abs(moved - np.c_[uv[:, 0] + 0.8, uv[:, 1]]).max() < 0.05


def test_a_knocked_camera_is_posed_again_from_its_cell_wall_targets():
    """A camera turned by 0.3 degrees and moved by 1 mm from frame 2 on: its new pose is found
    from the tracked cell-wall targets (centre within 0.05 mm); with too few targets it is not,
    and the frame is left out as before."""
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    dist = np.array([-0.2, 0.05, 0, 0, 0])
    cam = Camera("cam01", 640, 480, K, dist, np.eye(3), np.array([0.0, 0.0, 300.0]))
    knocked = cv2.Rodrigues(np.radians([0.3, -0.2, 0.1]))[0]
    bumped = Camera("cam01", 640, 480, K, cam.dist, knocked, np.array([1.0, -0.5, 300.5]))
    rng = np.random.default_rng(3)
    xyz = rng.uniform(-60, 60, (40, 3))
    wall = pd.DataFrame(xyz, columns=["x_mm", "y_mm", "z_mm"]).assign(id=np.arange(101, 141))
    rows = []
    for f in range(4):
        uv = project_air(cam if f < 2 else bumped, xyz)
        rows.append(pd.DataFrame({"camera": "cam01", "frame": f, "id": wall["id"], "u_px": uv[:, 0],
                                  "v_px": uv[:, 1], "area_px": 9.0, "reason": ""}))  # fmt: skip
    motion, poses = camera_motion({"cam01": cam}, wall, pd.concat(rows), moved_px=0.3)
    assert motion["moved"].tolist() == motion["reposed"].tolist() == [False, False, True, True]
    assert np.linalg.norm(poses[("cam01", 3)].center - bumped.center) < 0.05
    few = pd.concat(rows).groupby("frame").head(8)  # fewer than MIN_REPOSE_TARGETS tracked
    motion, poses = camera_motion({"cam01": cam}, wall, few, moved_px=0.3)
    assert motion["moved"].tolist() == [False, False, True, True]
    assert not motion["reposed"].any() and not poses


@pytest.mark.parametrize("speed", [3.0, 8.0])
def test_fast_motion_drops_dots_rather_than_swapping(monkeypatch, speed):
    """Dots moving 2-5 px a frame (a quarter to half their 10 px spacing), from a standing start:
    whatever is reported is its own dot; a region that locks one dot over is never confirmed."""
    import sys

    here = sys.modules[__name__]
    slow = truth_positions

    def fast(frame):
        ids, uv0 = slow(0)
        return ids, uv0 + (slow(frame)[1] - uv0) * speed

    monkeypatch.setattr(here, "truth_positions", fast)
    monkeypatch.setattr(here, "bar_columns", lambda frame: (W + 10.0, W + 20.0))  # no bar (off the image)
    tracks = track_frames(((k, render(k)) for k in range(FRAMES)), first_labels(), "cam01", range(FRAMES))
    rep = tracks[tracks["reason"] == ""]
    for k, g in rep.groupby("frame"):
        ids, uv = fast(k)
        t = pd.DataFrame(uv, index=ids, columns=["u", "v"]).loc[g["id"]]
        assert np.hypot(*(g[["u_px", "v_px"]].to_numpy() - t.to_numpy()).T).max() < 1.0, k
    assert len(rep) > FRAMES * 10  # and something is tracked


def test_motion_of_a_third_of_the_spacing_is_followed_from_a_standing_start(monkeypatch):
    """Dots moving 1.8-3.9 px a frame on a 10 px grid (a chunk's first frames, or a step of
    several frames), unevenly (the bottom slower): the motion the frame shows moves the
    predictions, so at least 95 % of the dots are kept at every frame, each its own dot."""
    import sys

    here = sys.modules[__name__]
    slow = truth_positions

    def fast(frame):
        ids, uv0 = slow(0)
        return ids, uv0 + (slow(frame)[1] - uv0) * 5.0

    monkeypatch.setattr(here, "truth_positions", fast)
    monkeypatch.setattr(here, "bar_columns", lambda frame: (W + 10.0, W + 20.0))  # no bar (off the image)
    n = 12
    step = np.diff(np.stack([fast(k)[1] for k in range(n)]), axis=0)
    assert 1.5 < np.linalg.norm(step, axis=2).min() and np.linalg.norm(step, axis=2).max() < 4.0
    tracks = track_frames(((k, render(k)) for k in range(n)), first_labels(), "cam01", range(n))
    rep = tracks[tracks["reason"] == ""]
    kept = rep.groupby("frame")["id"].nunique()
    assert kept.min() >= 0.95 * kept.loc[0], kept.to_dict()
    for k, g in rep.groupby("frame"):
        ids, uv = fast(k)
        t = pd.DataFrame(uv, index=ids, columns=["u", "v"]).loc[g["id"]]
        assert np.hypot(*(g[["u_px", "v_px"]].to_numpy() - t.to_numpy()).T).max() < 1.0, k


# --- degraded footage: noise, blur, uneven and changing light, compression ---------------------

D_SPACING = 12.0  # px
D_RADIUS = 3.0  # px: dots 6 px across
D_FRAMES = 12
D_WHITE = 180.0  # grey levels at the left edge; 30 % less at the right edge
D_INK = 0.2  # the dots' reflectance relative to the white membrane


def d_truth(frame: int) -> tuple[np.ndarray, np.ndarray]:
    """IDs and (N, 2) centres of a 16 x 26 grid moving 0.3 px/frame right and 0.15 down."""
    j, i = np.mgrid[0:16, 0:26]
    return 1001 + np.arange(i.size), np.c_[30.0 + D_SPACING * i.ravel() + 0.3 * frame,
                                           28.0 + D_SPACING * j.ravel() + 0.15 * frame]  # fmt: skip


def d_render(
    uv: np.ndarray, gain: float = 1.0, seed: int = 0, jpeg: int | None = 40, box: tuple | None = None
) -> np.ndarray:
    """Dark dots at ``uv`` on a white level falling 30 % left to right, an optional box
    ``(u0, v0, u1, v1, reflectance)`` in front, blurred (sigma 1 px), times ``gain``, sensor noise
    (sigma 4 grey levels), 8-bit, and JPEG at quality ``jpeg`` (a stand-in for video compression)."""
    big = np.full((H * SS, W * SS), 255, np.uint8)
    for u, v in uv:
        c = (int(round(((u + 0.5) * SS - 0.5) * 16)), int(round(((v + 0.5) * SS - 0.5) * 16)))
        cv2.circle(big, c, int(D_RADIUS * SS * 16), 0, -1, cv2.LINE_AA, shift=4)
    refl = D_INK + (1 - D_INK) * cv2.resize(big, (W, H), interpolation=cv2.INTER_AREA) / 255.0
    if box is not None:
        refl[box[1] : box[3], box[0] : box[2]] = box[4]
    img = cv2.GaussianBlur(D_WHITE * (1 - 0.3 * np.arange(W) / (W - 1))[None, :] * refl, (0, 0), 1.0)
    img = gain * img + np.random.default_rng(seed).normal(0, 4.0, img.shape)
    img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if jpeg:
        coded = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, jpeg])[1]
        img = cv2.imdecode(coded, cv2.IMREAD_GRAYSCALE)
    return img


def d_track(frames: list[np.ndarray]) -> pd.DataFrame:
    """Track degraded ``frames`` (of ``d_truth``) from the first frame's detections."""
    blobs = detect_blobs(frames[0])
    ids, uv = d_truth(0)
    d = np.hypot(*(blobs[["u_px", "v_px"]].to_numpy()[:, None] - uv[None]).transpose(2, 0, 1))
    lab = np.where(d.min(axis=1) < 1.0, ids[d.argmin(axis=1)], -1)
    labels = blobs.assign(camera="cam01", frame=0, id=lab)
    return track_frames(enumerate(frames), labels, "cam01", range(len(frames)))


def d_errors(tracks: pd.DataFrame) -> np.ndarray:
    """(M, 2) reported centroid minus truth, every reported row."""
    rep = tracks[tracks["reason"] == ""]
    out = []
    for k, g in rep.groupby("frame"):
        ids, uv = d_truth(int(k))
        out.append(g[["u_px", "v_px"]].to_numpy() - pd.DataFrame(uv, index=ids).loc[g["id"]].to_numpy())
    return np.concatenate(out)


def reported(tracks: pd.DataFrame, frame: int) -> set:
    return set(tracks.loc[(tracks["frame"] == frame) & (tracks["reason"] == ""), "id"])


def test_a_camera_knocked_by_most_of_a_spacing_is_followed_by_its_cell_wall_targets():
    """The whole picture moved (7.5, 2) px at frame 6 (a knock; the membrane dots are 12 px
    apart, so the nearest blob to each prediction is its neighbour's): the cell-wall targets
    (32-40 px apart, still) show the camera's move, every target is predicted with it, and the
    membrane dots are followed, each its own (at least 95 % kept; before, all dropped here, and
    on a 720p test 185 observations were locked one dot over)."""
    jump = np.array([7.5, 2.0])
    wall_ids = np.arange(101, 119)
    wall = np.c_[np.tile(20.0 + 40 * np.arange(9), 2), np.repeat([12.0, 44.0], 9)]

    def truth(k):
        ids, uv = d_truth(k)
        low = uv[:, 1] >= 76 + 0.15 * k  # the membrane's lower 12 rows
        moved = jump if k >= 6 else np.zeros(2)
        return np.r_[ids[low], wall_ids], np.r_[uv[low], wall] + moved

    frames = [d_render(truth(k)[1], seed=k, jpeg=None) for k in range(D_FRAMES)]
    blobs = detect_blobs(frames[0])
    ids, uv = truth(0)
    d = np.hypot(*(blobs[["u_px", "v_px"]].to_numpy()[:, None] - uv[None]).transpose(2, 0, 1))
    labelled = np.where(d.min(axis=1) < 1.0, ids[d.argmin(axis=1)], -1)
    labels = blobs.assign(camera="cam01", frame=0, id=labelled)
    # the walls' windows reach 10 px (labelled as larger targets), the membrane's 6 px
    labels.loc[labels["id"].between(101, 118), "area_px"] = 150.0
    tracks = track_frames(enumerate(frames), labels, "cam01", range(D_FRAMES))
    assert (tracks.loc[tracks["id"] < 1000, "reason"] == "").all()
    rep = tracks[(tracks["reason"] == "") & (tracks["id"] > 1000)]
    for k, g in rep.groupby("frame"):
        ids, uv = truth(int(k))
        err = g[["u_px", "v_px"]].to_numpy() - pd.DataFrame(uv, index=ids).loc[g["id"]].to_numpy()
        assert np.hypot(*err.T).max() < 0.5, k
    membrane = int((ids > 1000).sum())
    for k in range(6, D_FRAMES):
        assert len(reported(rep, k)) >= 0.95 * membrane, k


@pytest.mark.parametrize("jpeg", [None, 40])
def test_degraded_footage_keeps_its_dots(jpeg):
    """Noise, blur, a 30 % light gradient, JPEG and a 25 % flicker: dots are kept, never swapped."""
    gains = 1 + 0.25 * np.sin(2.0 * np.arange(D_FRAMES))
    tracks = d_track([d_render(d_truth(k)[1], gains[k], k, jpeg) for k in range(D_FRAMES)])
    first = reported(tracks, 0)
    assert len(first) >= 0.98 * len(d_truth(0)[0])
    assert len(first & reported(tracks, D_FRAMES - 1)) >= 0.99 * len(first)
    assert (tracks["reason"] == "").mean() >= 0.99
    err = np.hypot(*d_errors(tracks).T)
    assert err.max() < 1.0  # zero swaps: the nearest other dot is 12 px away
    assert np.sqrt(np.mean(err**2)) < 0.1
    rep = tracks[tracks["reason"] == ""]
    # an uncertainty with every observation (its calibration: test_centroid_uncertainty_is_calibrated;
    # JPEG's ringing raises some windows' noise)
    assert rep["sigma_px"].between(0.005, 0.5).all()


@pytest.mark.parametrize("gain", [0.6, 0.5])
def test_a_dimmed_frame_loses_nothing(gain):
    """One frame of the camera dimmed uniformly: every target reported on it and the next."""
    frames = [d_render(d_truth(k)[1], gain if k == 5 else 1.0, k, None) for k in range(8)]
    tracks = d_track(frames)
    first = reported(tracks, 0)
    assert reported(tracks, 5) == first and reported(tracks, 6) == first


def test_a_blank_frame_is_survived():
    """A glitched (blank) frame loses every target for that frame only; they come back at once."""
    frames = [d_render(d_truth(k)[1], 0.0 if k == 5 else 1.0, k) for k in range(8)]
    tracks = d_track(frames)
    first = reported(tracks, 0)
    assert not reported(tracks, 5)
    assert len(reported(tracks, 6) & first) >= 0.99 * len(first)
    assert np.hypot(*d_errors(tracks).T).max() < 1.0


@pytest.mark.parametrize("gain", [1.6, 2.0])
def test_an_exposure_jump_that_clips_the_white_misplaces_nothing(gain):
    """The camera's exposure jumps from frame 5 on and the white membrane clips at 255 (over the
    left part of the picture at 1.6, everywhere at 2.0): a target whose window clips is dropped
    (``shape``), never reported off its dot, and at least 95 % are reported again two frames
    later (issue 20's faults: cam11 at gain 1.6 from frame 2 reported 623 of its ~1700 targets
    there, flagged in quality.json)."""
    frames = [d_render(d_truth(k)[1], gain if k >= 5 else 1.0, k, None) for k in range(8)]
    assert (frames[5] == 255).mean() > 0.1
    tracks = d_track(frames)
    first = reported(tracks, 0)
    assert np.hypot(*d_errors(tracks).T).max() < 1.0
    assert set(tracks.loc[(tracks["frame"] == 5) & (tracks["reason"] != ""), "reason"]) <= {"shape"}
    assert len(reported(tracks, 7) & first) >= 0.95 * len(first)


@pytest.mark.parametrize("ink", [0.0, 1.0])
def test_a_half_covered_dot_is_dropped_and_comes_back(ink):
    """A black (or white) box over half of one dot in frames 4-6: dropped for its shape (a black
    box touching the dot's disc may also merge with it), reported again once the box has gone."""
    ids, uv = d_truth(0)
    target = 8 * 26 + 12  # mid-image
    frames = []
    for k in range(D_FRAMES):
        u, v = d_truth(k)[1][target]
        box = (int(np.floor(u)) + 1, int(np.floor(v - D_RADIUS)), int(np.ceil(u + D_RADIUS)) + 1,
               int(np.ceil(v + D_RADIUS)) + 1, ink) if 4 <= k <= 6 else None  # fmt: skip
        frames.append(d_render(d_truth(k)[1], 1.0, k, None, box))
    tracks = d_track(frames).set_index(["frame", "id"])["reason"]
    tid = ids[target]
    assert tracks[(3, tid)] == ""
    hidden = [tracks[(k, tid)] for k in (4, 5, 6)]
    assert all(r in (("shape",) if ink else ("shape", "merged")) for r in hidden), hidden
    assert tracks[(8, tid)] == "" and tracks[(D_FRAMES - 1, tid)] == ""


def test_centroid_uncertainty_is_calibrated():
    """On blurred dots at random sub-pixel positions with noise sigma 4 grey levels, the centroid
    error divided by its stated uncertainty has an RMS near 1, and the centroid is unbiased."""
    rng = np.random.default_rng(7)
    errs, sigmas = [], []
    for seed in range(6):
        _, uv = d_truth(0)
        uv = uv + rng.uniform(-0.5, 0.5, uv.shape)
        m = measure_targets(d_render(uv, 1.0, 100 + seed, None), uv, np.full(len(uv), D_RADIUS + 1))
        assert (m.reason == "").all()
        errs.append(m.uv - uv)
        sigmas.append(m.sigma_px)
    err, sig = np.concatenate(errs), np.concatenate(sigmas)
    z = np.sqrt(np.mean((err / sig[:, None]) ** 2))
    assert 0.7 <= z <= 1.4, z
    assert np.abs(err.mean(axis=0)).max() < 0.02


def test_mass_is_normalised_by_the_white_level():
    """A uniform change of brightness leaves the normalised mass and the ink as they were; the
    summed contrast (measure_blobs' mass) scales with it."""
    _, uv = d_truth(0)
    uv = uv[:50]
    bright = d_render(uv, 1.0, 1, None)
    dim = np.rint(bright * 0.5).astype(np.uint8)
    a, b = (measure_targets(g, uv, np.full(len(uv), D_RADIUS + 1)) for g in (bright, dim))
    assert (a.reason == "").all() and (b.reason == "").all()
    # far inside the mass checks' tolerance (mass_step 0.1): a blob's grown edge may gain or lose a
    # pixel at the 8-bit steps of the halved frame
    change = np.abs(b.mass / a.mass - 1)
    assert change.mean() < 0.015 and change.max() < 0.05
    assert (np.abs(a.area - b.area) <= np.maximum(2, 0.15 * a.area)).all()  # the same ink, to the 8-bit steps
    summed = [measure_blobs(g, uv, np.full(len(uv), D_RADIUS + 1))[2] for g in (bright, dim)]
    ratio = summed[1] / summed[0]
    assert abs(ratio.mean() - 0.5) < 0.0075 and np.abs(ratio - 0.5).max() < 0.025


def test_camera_frames_with_large_losses_are_flagged():
    """A camera-frame that reports under half of the camera's best frame is flagged, with its
    share; a camera that loses a few targets is not."""
    rows = [
        (cam, frame, target, "lost" if (cam == "b" and frame == 3 and target < 7) or target == 9 else "")
        for cam in ("a", "b") for frame in range(5) for target in range(10)
    ]  # fmt: skip
    tracks = pd.DataFrame(rows, columns=["camera", "frame", "id", "reason"])
    flagged = large_losses(tracks)
    assert flagged[["camera", "frame", "reported"]].values.tolist() == [["b", 3, 2]]
    assert flagged["share"].iloc[0] == pytest.approx(2 / 9)


def test_a_camera_that_loses_its_targets_for_most_of_the_test_is_flagged():
    """Issue 20 (a corrupt packet at frame 2 of cam10's video, 13 cameras x 6 frames): the decoder
    conceals the damage in frames 2-5, cam10 reports about 100 of its 1650 targets there, and
    quality.json flagged nothing, the camera's median frame being a damaged one."""
    reported = {"a": [10] * 6, "b": [10, 10, 1, 1, 1, 1]}
    rows = [
        (cam, frame, target, "" if target < n else "lost")
        for cam, counts in reported.items() for frame, n in enumerate(counts) for target in range(10)
    ]  # fmt: skip
    flagged = large_losses(pd.DataFrame(rows, columns=["camera", "frame", "id", "reason"]))
    assert flagged[["camera", "frame", "reported"]].values.tolist() == [["b", f, 1] for f in range(2, 6)]
    assert flagged["share"].tolist() == pytest.approx([0.1] * 4)


def test_observations_hold_the_pixels_the_triangulation_used():
    """A membrane dot offered to the triangulation at a pixel moved by the codec lag: its
    observation holds that pixel (so u_px + du_px is the reprojection); a cell-wall dot not
    offered keeps its tracked centroid; a target not reported is not an observation."""
    tracks = pd.DataFrame({
        "camera": "cam01", "frame": 3, "id": [101, 1001, 1002], "u_px": [10.0, 20.0, 30.0],
        "v_px": [5.0, 6.0, 7.0], "area_px": 20.0, "sigma_px": 0.02, "reason": ["", "", "lost"],
    })  # fmt: skip
    residuals = pd.DataFrame({
        "camera": ["cam01"], "frame": [3], "id": [1001], "u_px": [20.04], "v_px": [5.97],
        "du_px": [0.01], "dv_px": [-0.02], "used": [True], "reason": [""],
    })  # fmt: skip
    obs = observations_table(tracks, residuals).set_index("id")
    assert list(obs.index) == [101, 1001]
    assert obs.loc[1001, ["u_px", "v_px"]].tolist() == [20.04, 5.97] and obs.loc[1001, "used"]
    assert obs.loc[101, ["u_px", "v_px"]].tolist() == [10.0, 5.0] and not obs.loc[101, "used"]


def test_dots_taken_on_inside_a_patch_are_placed_on_one_smooth_displacement_field():
    """A grid of dots 6 px apart, displaced since the reference frame by a stretch, a shear and a
    bulge (quadratic), with a 7 x 7 hole its middle dots are taken on in: their reference
    places are where the reported dots' displacement field puts them, within 0.02 px; one
    median displacement misplaces them by up to 0.9 px, which the flow check (0.5 px) reads as
    drift."""
    from triaxtrack.neighbour_motion import reference_places

    j, i = np.mgrid[0:21, 0:21]
    ref = np.c_[6.0 * i.ravel(), 6.0 * j.ravel()]  # reference places, px

    def moved(p):
        u, v = p[:, 0], p[:, 1]
        return np.c_[u + 0.02 * v + 0.0004 * (v - 60) ** 2, v * 1.05 + 3.0]

    hole = (np.abs(i.ravel() - 10) <= 3) & (np.abs(j.ravel() - 10) <= 3)
    order = np.r_[np.nonzero(~hole)[0], np.nonzero(hole)[0]]  # the hole's dots are the new ones
    ref, last = ref[order], moved(ref)[order]
    n = int((~hole).sum())
    median = last[n:] - np.median(last[:n] - ref[:n], axis=0)
    got = reference_places(
        np.r_[ref[:n], median], last, np.r_[np.ones(n, bool), np.zeros(len(ref) - n, bool)], n,
        np.full(len(ref) - n, 18.0),
    )  # fmt: skip
    assert np.abs(median - ref[n:]).max() > 0.5
    assert np.abs(got[n:] - ref[n:]).max() < 0.02
    assert np.array_equal(got[:n], ref[:n])  # the others are left where they were
