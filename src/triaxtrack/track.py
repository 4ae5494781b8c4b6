"""Tracking: follow every labelled target of one camera from frame to frame (paper section 2.4).

The targets are labelled once, in the first recorded frame of a chunk (``triaxtrack.identify``);
from there each ID is carried forward without detecting or identifying the frame again:

1. **Predict** each target from its recent motion (constant velocity; a target that was not
   reported in the previous frame moves with its neighbours, see 4), then move the prediction by
   the motion the frame shows: the blobs found within their gate of their predictions are the
   targets' own, and their motion spreads from them to their neighbours across the grid
   (unwrapped as phase is: a blob one dot over is told from the target's own by its
   neighbours' motion), where it differs from the prediction by more than a quarter of a gate
   every target is measured again. So motion of up to about half the dot spacing is followed
   from a standing start (a chunk's first frames, a step of several frames), and a region that
   moves farther is dropped; but a region that moves by more than one spacing less a gate
   (0.7 of it) finds the next dot within its gate, as a grid moving back by the rest would, and
   is locked one dot over (a 4K render moving mid-height 0.72 rows a frame: 600 dots per
   camera; ``triaxtrack.simulate.largest_step_rows``; a real test moves a few thousandths of a
   row a frame). A first velocity is the first motion measured, not averaged with an unknown
   zero.
2. **Measure** it locally (:mod:`triaxtrack.window`): in a small window around the prediction
   the window's own white level (a trimmed mean of its brighter pixels) and pixel noise (held
   to the frame's) are measured; ink is darker than the white level by ``ink_fraction`` of it
   and by ``INK_NOISE_K`` times the noise (so a uniform change of light changes nothing), found
   within a disc of the dot's semi-major axis plus ``disc_margin_px`` that is re-centred on the
   blob (mean shift); the contrast-weighted centroid is taken over the blob grown by one pixel,
   as in detection, with its standard uncertainty ``sigma_px`` propagated from the pixel noise.
   The window is the search gate: the nearest detection to the prediction is the blob the disc
   converges on.
3. **Check**, and drop for this frame with a reason, never swap:

   * ``edge``: the window leaves the image;
   * ``lost``: no ink in the disc (occluded, out of view; or a window too dark to show a dot);
   * ``merged``: the blob runs on beyond its disc (it touches another dark feature; a dot that
     touches another target, as compressed rows do on soft footage, is measured apart from it,
     each on its side of the valley between them: :mod:`triaxtrack.window`);
   * ``shape``: its normalised mass (the summed contrast over the white level: the dot's area
     times its darkness, without the whole-pixel jumps of a thresholded area, unchanged by a
     uniform change of light) changed since it was last seen by more than the larger of
     ``mass_step`` and ``MASS_NOISE_K`` standard uncertainties, or since the chunk's first frame
     by more than the larger of ``mass_change`` and as many (partly hidden, or merged with
     another dark feature). The uncertainty is the larger of the one propagated from the pixel
     noise of the two windows and the camera's own robust scatter of that change over its
     targets in the frame (which holds what the window noise misses, such as compression) of
     the same class: measured apart from a touching target or not (a divided dot's mass ends at
     a valley line that moves with the noise: at 10 % strain on 720p footage its scatter was
     0.035-0.08 against the free dots' 0.016-0.025);
   * ``jump``: the centroid is farther than ``gate`` (a fraction of the distance to the nearest
     other detection at the chunk's first frame) from the prediction;
   * ``ambiguous``: two targets converge to within ``min_separation`` of that distance (one
     blob, two candidates): both are dropped;
   * ``drift``: its displacement since the chunk's first frame departs by more than
     ``max_flow_residual_px`` from the local affine motion of its neighbours (its own kind:
     membrane, cell, top or bottom pedestal), which a partly hidden or wrongly followed dot
     does and a smoothly deforming membrane does not.
   * ``disagrees``: at the chunk's first frame the tracker's centroid is farther than
     ``first_agreement_px`` from the identification's (the dot's surroundings confuse one of
     them, or most of it is hidden behind a band's edge): the target is left out of the chunk;
   * ``not_recorded``: the camera has no picture of the frame (frame map).

4. **Re-acquire**: a dropped target keeps a virtual position, moved by its neighbours' affine
   motion (or by its last velocity when too few neighbours are reported), and is measured again
   in every later frame; it is reported again as soon as every check passes, and only if enough
   of its neighbours are reported for the ``drift`` check to vouch for it (else
   ``unconfirmed``): a position extrapolated blind can sit on the next dot when the motion is
   fast (in a frame the camera did not record, nothing is measured and the prediction simply
   moves on). A blank frame in steady tracking (``BLANK_SHARE`` of the targets ``lost``, after
   ``STEADY_FRAMES`` frames with ``STEADY_SHARE`` reported: a glitched or black picture) is
   treated like a frame not recorded for the vouching, so every target comes back the next
   frame; a frame whose windows catch ink in the wrong places (fast motion) is not excused.

Velocities are per frame, also across frames not recorded. Pixels are distorted image
coordinates in OpenCV's convention (the centre of the top-left pixel is (0, 0)); frames are
test frames (``triaxtrack.frames``).
"""

from __future__ import annotations

from collections.abc import Collection, Iterable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from triaxtrack.completion import Candidates, DotGrid, Found, complete_grid, grid_candidates
from triaxtrack.nearest import crowded, finite_rows, k_nearest
from triaxtrack.neighbour_motion import affine_flow, reference_places, unwrap_motion
from triaxtrack.track_kernels import advance, camera_shift, found_miss, shape_changed, spread_motion
from triaxtrack.tracking_config import TrackingConfig
from triaxtrack.window import WindowMeasure, disc_radius, measure_windows

REFERENCE_WIDTH = 3.0  # x spacing: the width of the displacement field that places a dot taken on
NEIGHBOURS = 12  # same-kind neighbours whose motion predicts a target's (local affine flow)
MIN_FLOW_NEIGHBOURS = 4  # fewer reported neighbours: no flow check, velocity prediction
MASS_NOISE_K = 4.0  # a mass change within 4 standard uncertainties is noise (two-sided 6e-5 a
# check: a noisy small dot is not dropped for noise alone; a half-hidden one loses ~50 % of its mass)
MIN_SCATTER_TARGETS = 20  # targets needed for the camera's own scatter of mass changes
MAD_TO_SIGMA = 1.4826  # median absolute deviation to standard deviation (normal noise)
BLANK_SHARE = 0.9  # a frame in which at least this share of the targets is 'lost' is blank ...
STEADY_SHARE = 0.9  # ... and excused if at least this share was reported in the frames before it
STEADY_FRAMES = 2  # ... for this many frames in a row (so that their velocity is measured)
FAR_NEIGHBOURS = 4.0  # x spacing: how far vouching neighbours are sought for a target found again
CONFIRM_PASSES = 5  # rounds in which targets found again are confirmed by their neighbours
VELOCITY_SMOOTHING = 0.5  # weight of the previous velocity (one noisy or biased frame moves it less)
# where the motion a frame shows moves some prediction by more than this share of its gate, the
# frame's targets are measured again from the moved predictions (else the move is only noise)
REPREDICT_SHARE = 0.25
MIN_WALL_TARGETS = 8  # cell-wall targets found that show a camera's own move
REASONS = (
    "edge", "lost", "merged", "shape", "jump", "ambiguous", "drift", "unconfirmed", "disagrees",
    "not_recorded",
)  # fmt: skip
# through the frame loop a reason is its code: its index in _NAMES (0: reported), the window
# kernel's codes (triaxtrack.window.REASON_CODES: '', 'edge', 'lost', 'merged') first
_NAMES = np.array(("", *REASONS), dtype=object)
_REASON_STR = pd.array(_NAMES, dtype="str")  # the table's column: taken by code, not each str converted
_OK, _EDGE, _LOST, _MERGED, _SHAPE, _JUMP, _AMBIGUOUS, _DRIFT = range(8)
_UNCONFIRMED, _DISAGREES, _NOT_RECORDED = range(8, 11)


def _norm(d: np.ndarray) -> np.ndarray:
    """(n,) the lengths of (n, 2) vectors, as ``np.linalg.norm(d, axis=1)`` (the same rounding)."""
    return np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])


def processed_frames(n_frames: int, fps: float, step_s: float | None) -> np.ndarray:
    """Test frames that are processed (reported): all, or the nearest frame to every multiple
    of ``step_s`` seconds; the first and the last frame always."""
    if n_frames <= 0:
        return np.zeros(0, np.int64)
    if step_s is None or step_s <= 0:
        return np.arange(n_frames, dtype=np.int64)
    k = np.rint(np.arange(0, (n_frames - 1) / fps + 1e-9, step_s) * fps).astype(np.int64)
    return np.unique(np.r_[k[k < n_frames], n_frames - 1])


CELL_WALL, MEMBRANE = 2, 3  # target_kind of a cell-wall target and of a membrane dot


def target_kind(ids: np.ndarray) -> np.ndarray:
    """Kind of a Table 1 ID for the neighbour flow: 0 top pedestal (1-16), 1 bottom pedestal
    (17-32), 2 cell (101-580), 3 membrane (1001 on)."""
    ids = np.asarray(ids)
    return np.select([ids <= 16, ids <= 32, ids < 1000], [0, 1, 2], 3)


@dataclass
class _State:
    """Per target: the reference (chunk's first frame) and the current estimate."""

    ids: np.ndarray
    kind: np.ndarray  # (n,) target_kind of each ID
    ref_uv: np.ndarray  # (n, 2) centroid at the chunk's first frame (NaN: not measured there)
    ref_mass: np.ndarray  # (n,) normalised blob mass there (summed contrast / white level)
    ref_smass: np.ndarray  # (n,) its standard uncertainty
    last_mass: np.ndarray  # (n,) normalised blob mass when last reported
    last_smass: np.ndarray  # (n,) its standard uncertainty
    radius: np.ndarray  # (n,) disc radius, pixels
    spacing: np.ndarray  # (n,) distance to the nearest other detection at the first frame
    neighbours: np.ndarray  # (n, NEIGHBOURS) same-kind neighbours (index n: none)
    pred: np.ndarray  # (n, 2) where each target is expected in the next frame
    last_uv: np.ndarray  # (n, 2) where it was last reported
    last_vel: np.ndarray  # (n, 2) its velocity then, pixels per frame
    timed: np.ndarray  # (n,) whether that velocity was measured (else zero: not yet known)
    blind: np.ndarray  # (n,) frames measured and not reported since it was last reported
    since: np.ndarray  # (n,) frames (of any kind) from when it was last reported to this one
    steady: int = 0  # frames in a row in which STEADY_SHARE of the targets were reported
    median_of: np.ndarray | None = None  # the spacing array whose median is median_spacing ...
    median_spacing: float = np.nan  # ... (:func:`_median_spacing`)


def _neighbours(uv: np.ndarray, kinds: np.ndarray) -> np.ndarray:
    n = len(uv)
    out = np.full((n, NEIGHBOURS), n, np.int64)
    for kind in np.unique(kinds):
        idx = np.nonzero(kinds == kind)[0]
        if len(idx) < 2:
            continue
        k = min(NEIGHBOURS + 1, len(idx))
        _, nb = k_nearest(uv[idx], uv[idx], k)
        nb = idx[nb[:, 1:]]
        out[idx, : nb.shape[1]] = nb
    return out


def _init_state(labels: pd.DataFrame, cfg: TrackingConfig) -> _State:
    """State from one frame's labels (all detections: the unlabelled ones give the spacing)."""
    # the columns as arrays (filtering the table would copy every column, the text ones too)
    uv_all = np.stack([labels["u_px"].to_numpy(np.float64), labels["v_px"].to_numpy(np.float64)], axis=1)
    id_all = labels["id"].to_numpy(np.int64)
    labelled = np.nonzero(id_all > 0)[0]
    ids, first = np.unique(id_all[labelled], return_index=True)  # each ID's first row, by ID
    own = labelled[first]
    uv = uv_all[own]
    if len(uv_all) >= 2:
        d, _ = k_nearest(uv_all, uv, 2)
        spacing = d[:, 1]
    else:
        spacing = np.full(len(uv), np.inf)
    radius = disc_radius(
        labels["area_px"].to_numpy()[own], labels["roundness"].to_numpy()[own], cfg.disc_margin_px
    )
    n, kind = len(ids), target_kind(ids)
    return _State(
        ids=ids, kind=kind, ref_uv=np.full((n, 2), np.nan), ref_mass=np.full(n, np.nan),
        ref_smass=np.zeros(n), last_mass=np.full(n, np.nan), last_smass=np.zeros(n), radius=radius,
        spacing=spacing, neighbours=_neighbours(uv, kind), pred=uv.copy(), last_uv=uv.copy(),
        last_vel=np.zeros((n, 2)), timed=np.zeros(n, bool), blind=np.zeros(n, np.int64),
        since=np.ones(n, np.int64),
    )  # fmt: skip


def measure_targets(
    gray: np.ndarray, uv_px: np.ndarray, radius_px: np.ndarray, cfg: TrackingConfig | None = None
) -> WindowMeasure:
    """The dark blobs nearest (N, 2) predicted pixel positions, each measured against its own
    window's white level and noise (:func:`triaxtrack.window.measure_windows`): centroid, ink
    area, normalised mass and their uncertainties, and '' or 'edge', 'lost', 'merged'."""
    cfg = cfg or TrackingConfig()
    return measure_windows(gray, uv_px, radius_px, cfg.ink_fraction, cfg.disc_margin_px)


def measure_blobs(
    gray: np.ndarray, uv_px: np.ndarray, radius_px: np.ndarray, cfg: TrackingConfig | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`measure_targets` as ``(uv (N, 2), area (N,), mass (N,), reason (N,) object)``:
    the centroid (NaN unless the reason is ''), the blob's ink area in pixels, its mass in grey
    levels x pixels (the summed contrast: the normalised mass times the window's white level)."""
    m = measure_targets(gray, uv_px, radius_px, cfg)
    return m.uv, m.area, np.nan_to_num(m.mass * m.white), m.reason


def _affine_flow(
    state: _State, disp: np.ndarray, ok: np.ndarray, neighbours: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Each target's displacement predicted by the affine motion of its reported neighbours:
    ``(pred (n, 2), valid (n,))`` from the displacements ``disp`` (n, 2) of the ``ok`` ones.
    ``neighbours`` (n, k) indices (n: none) replace the fixed ``state.neighbours``."""
    nb = state.neighbours if neighbours is None else neighbours
    return affine_flow(state.ref_uv, disp, ok, nb, MIN_FLOW_NEIGHBOURS)


def _frame_motion(state: _State, pred: np.ndarray, meas: WindowMeasure, gate: float) -> np.ndarray:
    """(n, 2) the move of each target's prediction ``pred`` that the frame shows, zero where it
    is found within its gate (it is measured already) or its motion is not known beyond doubt.

    A blob found within its gate of the prediction is the target's own (a seed); from the seeds
    the motion spreads to their neighbours, round by round, as their median motion, and a found
    blob is taken as the target's own where it, or the neighbouring dot it may be (a grid looks
    the same one dot over), moves within the gate of that median: the motion is unwrapped from
    where it is small (the fixed pedestal, the cap's coded targets far apart) across the grid,
    as phase is. A motion that departs from its neighbours' median by more than the gate is not
    known. Where no target moves within its gate of its prediction (a region moving by half the
    dot spacing or more from a standing start), nothing is known and targets are dropped, never
    locked one dot over."""
    found = meas.code == _OK
    miss = found_miss(meas.uv, pred, found)
    tol = gate * state.spacing
    motion, known = unwrap_motion(miss, found, pred, state.neighbours, tol, MIN_FLOW_NEIGHBOURS)
    return spread_motion(motion, known, miss, found, tol)


def _camera_motion(state: _State, pred: np.ndarray, meas: WindowMeasure, gate: float) -> np.ndarray:
    """(2,) the camera's own move this frame: the median departure from their predictions of the
    cell-wall targets found clean within their gate (the cell does not move; at least
    ``MIN_WALL_TARGETS``, agreeing within a quarter of their gate), else zero. A camera knocked
    by about one membrane dot spacing shows the membrane the same one dot over everywhere, which
    its own motion cannot tell from no motion (a 720p camera moved (3, 2) px, its dots 4.5 px
    apart: 185 observations locked one dot over); the cell-wall targets, further apart, are
    found moved."""
    wall = (state.kind == CELL_WALL) & (meas.code == _OK) & np.isfinite(state.ref_mass)
    return camera_shift(wall, meas.uv, pred, state.spacing, gate, MIN_WALL_TARGETS, 0.25)


def _corrected_prediction(
    state: _State, gray: np.ndarray, cfg: TrackingConfig, pred: np.ndarray, meas: WindowMeasure
) -> tuple[np.ndarray, WindowMeasure]:
    """The predictions ``pred`` (n, 2) moved by the motion the frame shows (:func:`_frame_motion`)
    and the measurement ``meas`` with the targets whose prediction moved by more than
    ``REPREDICT_SHARE`` of their gate measured again from there. A constant-velocity prediction
    misses by the whole motion at a chunk's first frames (no velocity yet), after a step of
    several frames and when the motion changes; in steady tracking nothing moves."""
    shift = _frame_motion(state, pred, meas, cfg.gate)
    again = _norm(shift) > REPREDICT_SHARE * cfg.gate * state.spacing
    again &= np.isfinite(state.ref_mass)
    if again.any():
        new = measure_targets(gray, np.where(again[:, None], pred + shift, np.nan), state.radius, cfg)
        pick = [again[:, None] if a.ndim == 2 else again for a in meas]
        meas = WindowMeasure(*(np.where(c, b, a) for c, a, b in zip(pick, meas, new, strict=True)))
    return pred + shift, meas


def _vouchers(state: _State, vouch: np.ndarray, which: np.ndarray) -> np.ndarray:
    """(n, NEIGHBOURS) neighbours of the targets ``which`` among the vouching ones of their kind,
    within ``FAR_NEIGHBOURS`` times their spacing (index n: none); other rows empty."""
    n = len(state.ids)
    out = np.full((n, NEIGHBOURS), n, np.int64)
    kinds = state.kind
    for kind in np.unique(kinds[which]):
        pool = np.nonzero(vouch & (kinds == kind) & finite_rows(state.ref_uv))[0]
        rows = np.nonzero(which & (kinds == kind))[0]
        if len(pool) == 0 or len(rows) == 0:
            continue
        k = min(NEIGHBOURS, len(pool))
        d, j = cKDTree(state.ref_uv[pool]).query(np.nan_to_num(state.ref_uv[rows]), k=k)
        d, j = d.reshape(len(rows), k), j.reshape(len(rows), k)
        near = d <= FAR_NEIGHBOURS * state.spacing[rows, None]
        out[rows, :k] = np.where(near, pool[np.minimum(j, len(pool) - 1)], n)
    return out


def _extrapolate(state: _State) -> tuple:
    """A frame with no picture: the predictions move on by their velocities, nothing is measured
    (``not_recorded``) and ``blind`` stays as it is (no failed measurement). As :func:`_step`."""
    n = len(state.ids)
    state.pred = state.pred + state.last_vel
    state.since = state.since + 1
    nan = np.full(n, np.nan)
    return np.c_[nan, nan], np.zeros(n), nan, np.full(n, _NOT_RECORDED)


def _set_reference(
    state: _State, meas: WindowMeasure, pred: np.ndarray, reason: np.ndarray, cfg: TrackingConfig
) -> None:
    """At the chunk's first frame a target whose centroid (``meas``) is farther than
    ``first_agreement_px`` from the identification's (``pred``) is left out of the chunk
    (``disagrees`` in ``reason``); the others' centroids and normalised masses become the reference."""
    agree = (reason == _OK) & (_norm(meas.uv - pred) <= cfg.first_agreement_px)
    reason[(reason == _OK) & ~agree] = _DISAGREES
    state.ref_uv = np.where(agree[:, None], meas.uv, np.nan)
    state.ref_mass = np.where(agree, meas.mass, np.nan)
    state.ref_smass = np.where(agree, meas.sigma_mass, 0.0)
    state.last_mass, state.last_smass = state.ref_mass, state.ref_smass


def _check_measured(
    state: _State, meas: WindowMeasure, pred: np.ndarray, reason: np.ndarray, cfg: TrackingConfig
) -> None:
    """Drop (in ``reason``) the measured targets whose normalised mass changed too much since the
    chunk's first frame or the last frame (``shape``), whose centroid (``meas``) is beyond the gate
    from ``pred`` (``jump``), and two targets on one blob (``ambiguous``: both); module docstring."""
    uv, measured = meas.uv, reason == _OK
    shape = shape_changed(
        meas.mass, meas.sigma_mass, state.ref_mass, state.ref_smass, state.last_mass, state.last_smass,
        measured, state.blind, meas.divided, cfg.mass_change, cfg.mass_step, MASS_NOISE_K,
        MIN_SCATTER_TARGETS, MAD_TO_SIGMA,
    )  # fmt: skip
    reason[shape] = _SHAPE
    jump = measured & (_norm(uv - pred) > cfg.gate * state.spacing)
    reason[jump & (reason == _OK)] = _JUMP
    cand = np.nonzero(reason == _OK)[0]  # two targets on one blob: both dropped
    reason[cand[crowded(uv[cand], cfg.min_separation * state.spacing[cand])]] = _AMBIGUOUS


def _check_flow(
    state: _State, uv: np.ndarray, reason: np.ndarray, cfg: TrackingConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Drop (in ``reason``) the targets whose displacement since the chunk's first frame departs by
    more than ``max_flow_residual_px`` from their neighbours' affine motion (``drift``), and those
    found again that no reported neighbour vouches for (``unconfirmed``). Only targets reported in
    the previous frame (or before a blank one) vouch at first: targets found again must not confirm
    one another (a whole region can lock one dot over at once); each one that passes then vouches
    in turn, so confirmation spreads from the steadily tracked targets into a region that
    reappears. Returns the neighbours' predicted displacements (n, 2) and where there is one (n,)."""
    ok = reason == _OK
    disp = uv - state.ref_uv
    vouch = ok & (state.blind == 0)
    flow, valid = _affine_flow(state, disp, vouch)
    drift = vouch & valid & (_norm(disp - flow) > cfg.max_flow_residual_px)
    vouch &= ~drift
    if drift.any():  # they must not steer their neighbours' flow
        flow, valid = _affine_flow(state, disp, vouch)
    pending = ok & (state.blind > 0)
    for _ in range(CONFIRM_PASSES):
        check = pending & valid
        if not check.any():
            break
        off = check & (_norm(disp - flow) > cfg.max_flow_residual_px)
        drift |= off
        pending &= ~check
        if (check & ~off).any():  # new vouchers: the flow changes
            vouch |= check & ~off
            flow, valid = _affine_flow(state, disp, vouch)
    far = pending & finite_rows(state.ref_uv)
    if far.any():  # no vouchers among its nearest: the nearest vouching ones within reach
        far_flow, far_valid = _affine_flow(state, disp, vouch, _vouchers(state, vouch, far))
        check = far & far_valid
        off = check & (_norm(disp - far_flow) > cfg.max_flow_residual_px)
        drift |= off
        pending &= ~check
        flow = np.where(check[:, None], far_flow, flow)
        valid |= check
    reason[drift] = _DRIFT
    reason[pending] = _UNCONFIRMED  # found again, but no reported neighbours can vouch for it
    return flow, valid


def _advance(state: _State, meas: WindowMeasure, pred: np.ndarray, reason: np.ndarray, ok: np.ndarray,
             flow: np.ndarray, valid: np.ndarray, first: bool) -> None:  # fmt: skip
    """Advance the state past a measured frame (``ok``: reported; else ``reason``): the reported
    targets' last position, mass and velocity (pixels per frame, smoothed once known), the frames
    since each was reported, and the next predictions: constant velocity, a dropped target moved
    with its neighbours (``flow`` where ``valid``), or else blind. A blank frame (a glitched,
    blanked or over-exposed picture: no ink where almost every target should be) in steady
    tracking is a failure of the picture, not of each target: like a frame not recorded it does
    not count against them, so those reported before it still vouch after it. A frame whose
    windows catch ink in the wrong places is not blank: its predictions may be wrong, and blind
    extrapolation would carry them on."""
    live = max(np.isfinite(state.ref_mass).sum(), 1)
    excused = (reason == _LOST).sum() >= BLANK_SHARE * live and state.steady >= STEADY_FRAMES
    state.steady = state.steady + 1 if ok.sum() >= STEADY_SHARE * live else 0
    # velocities, smoothed once known; the next frame: constant velocity, a dropped target moved
    # with its neighbours or else blind, one found but not yet confirmed where it was found (the
    # best guess); in a blank frame, as in a frame not recorded, the prediction moves on
    s = state
    s.last_uv, s.last_vel, s.last_mass, s.last_smass, s.timed, s.blind, s.since, s.pred = advance(
        meas.uv, meas.mass, meas.sigma_mass, ok, reason == _UNCONFIRMED, flow, valid, s.ref_uv, pred,
        s.last_uv, s.last_vel, s.last_mass, s.last_smass, s.timed, s.blind, s.since, bool(excused), first,
        VELOCITY_SMOOTHING,
    )  # fmt: skip


def _median_spacing(state: _State) -> float:
    """``np.median(state.spacing)``, taken again only when the spacing array is replaced (targets
    taken on): the same every frame in between."""
    if state.median_of is not state.spacing:
        state.median_of, state.median_spacing = state.spacing, float(np.median(state.spacing))
    return state.median_spacing


def _step(state: _State, gray: np.ndarray | None, cfg: TrackingConfig, first: bool) -> tuple:
    """Track one frame: returns (uv (n, 2), area (n,), sigma_px (n,), reason (n,): codes, indices
    in ``_NAMES``) and advances the state."""
    if gray is None:  # no picture: extrapolate
        return _extrapolate(state)
    pred = state.pred
    # targets left out of the chunk at its first frame are not measured again (NaN: 'lost')
    probe = pred if first else np.where(np.isfinite(state.ref_mass)[:, None], pred, np.nan)
    meas = measure_targets(gray, probe, state.radius, cfg)
    if not first:  # the camera's own motion (a knock), then the motion the frame shows
        shift = _camera_motion(state, pred, meas, cfg.gate)
        if shift.any() and np.hypot(*shift) > REPREDICT_SHARE * cfg.gate * _median_spacing(state):
            pred = pred + shift
            meas = measure_targets(gray, probe + shift, state.radius, cfg)
        pred, meas = _corrected_prediction(state, gray, cfg, pred, meas)
    reason = meas.code.copy()
    if first:  # the tracker's centroid must agree with the detection's, or the target is left out
        _set_reference(state, meas, pred, reason, cfg)
    reason[~np.isfinite(state.ref_mass)] = _DISAGREES
    _check_measured(state, meas, pred, reason, cfg)
    flow, valid = _check_flow(state, meas.uv, reason, cfg)
    ok = reason == _OK
    _advance(state, meas, pred, reason, ok, flow, valid, first)
    sigma = np.where(ok, meas.sigma_px, np.nan)
    return np.where(ok[:, None], meas.uv, np.nan), meas.area, sigma, reason


def track_frames(
    frames: Iterable[tuple[int, np.ndarray | None]],
    labels: pd.DataFrame,
    camera: str,
    report: Collection[int],
    cfg: TrackingConfig | None = None,
    grid: DotGrid | None = None,
) -> pd.DataFrame:
    """Follow the labelled targets of ``labels`` (one camera's frame, ``LABELS`` columns; the
    unlabelled detections, id -1, only set each target's spacing) through ``frames``
    (``(test frame, grey image or None)`` in order, starting at the labels' frame). With the
    kit's membrane ``grid`` (:func:`triaxtrack.completion.dot_grid`), the membrane dots not
    labelled are taken on once they can be seen between reported neighbours
    (:mod:`triaxtrack.completion`), and reported from then on.

    Returns a ``TRACKS`` table: one row per followed target per frame in ``report`` (the
    labels' frame included, re-measured by the tracker so that every frame has the same
    centroid estimator), ``sigma_px`` the standard uncertainty of each coordinate of a reported
    centroid (NaN where not reported), pixels.
    """
    cfg = cfg or TrackingConfig()
    state = _init_state(labels, cfg)
    cand = grid_candidates(grid.ids, state.ids) if grid is not None else None
    report = set(int(k) for k in report)
    parts: list[tuple] = []
    for i, (k, gray) in enumerate(frames):
        if i == 0 and gray is None:
            raise ValueError(f"{camera}: no picture of the labelled frame {k}")
        uv, area, sigma, reason = _step(state, gray, cfg, first=i == 0)
        if cand is not None and grid is not None and gray is not None:
            cand, found = _complete(state, gray, cand, grid, uv, cfg)
            if len(found.ids):  # reported in this frame: the candidates around them join
                cand = grid_candidates(grid.ids, state.ids, cand)
                new = found.meas
                uv, area, sigma = np.r_[uv, new.uv], np.r_[area, new.area], np.r_[sigma, new.sigma_px]
                reason = np.r_[reason, np.full(len(found.ids), _OK)]
        if int(k) in report:
            parts.append((int(k), state.ids, uv, area, sigma, reason))
    if not parts:
        cols = ("camera", "frame", "id", "u_px", "v_px", "area_px", "reason", "sigma_px")
        return pd.DataFrame({c: [] for c in cols})
    frame, ids, uv, area, sigma, reason = zip(*parts, strict=True)  # one table at the end, not one a frame
    uv = np.concatenate(uv)
    return pd.DataFrame({
        "camera": camera, "frame": np.repeat(np.array(frame, np.int64), [len(i) for i in ids]),
        "id": np.concatenate(ids), "u_px": uv[:, 0], "v_px": uv[:, 1],
        "area_px": np.concatenate(area), "reason": _REASON_STR.take(np.concatenate(reason)),
        "sigma_px": np.concatenate(sigma),
    })  # fmt: skip


def _complete(
    state: _State, gray: np.ndarray, cand: Candidates, grid: DotGrid, uv: np.ndarray, cfg: TrackingConfig
) -> tuple[Candidates, Found]:
    """One frame of :func:`triaxtrack.completion.complete_grid` from the targets reported in it
    (``uv`` (n, 2), NaN where not), the dots taken on added to ``state`` (:func:`_adopt`)."""
    flat = state.ids - grid.ids.flat[0]
    member = (flat >= 0) & (flat < grid.ids.size)
    index = np.full(grid.ids.size, -1, np.int64)
    index[flat[member]] = np.nonzero(member)[0]
    reported = finite_rows(uv)
    mass = np.where(reported, state.last_mass, np.nan)
    cand, found = complete_grid(
        gray, cand, index.reshape(grid.ids.shape), uv, state.radius, mass,
        lambda g, p, r: measure_targets(g, p, r, cfg), aspect=grid.aspect, gate=cfg.gate,
        min_separation=cfg.min_separation, max_fit_px=cfg.max_flow_residual_px,
        cell_uv=uv[reported & (state.kind == CELL_WALL)], grid_ids=grid.ids, size=grid.size,
        mass_change=cfg.mass_change,
    )  # fmt: skip
    if len(found.ids):
        _adopt(state, found, reported)
    return cand, found


def _adopt(state: _State, found: Found, reported: np.ndarray) -> None:
    """Add the dots ``found`` to ``state`` as targets reported in this frame: their neighbours
    the nearest of the membrane targets ``reported`` (n,) in it and of the dots found with them,
    their reference place where the reported dots' displacement field since the chunk's first
    frame puts them (:func:`~triaxtrack.neighbour_motion.reference_places`), their velocity the
    median of their nearest reported dots'."""
    n, m = len(state.ids), len(found.ids)
    uv = found.meas.uv
    in_pool = reported & (state.kind == MEMBRANE) & finite_rows(state.ref_uv)
    pool = np.nonzero(in_pool)[0]
    k = min(NEIGHBOURS, len(pool))
    disp, vel = np.zeros((m, 2)), np.zeros((m, 2))  # (disp: where too few reported to place them)
    if k:
        _, j = k_nearest(state.last_uv[pool], uv, k)
        j = pool[j]
        disp = np.median(state.last_uv[j] - state.ref_uv[j], axis=1)
        vel = np.median(state.last_vel[j], axis=1)
    # neighbours: the nearest reported dots and dots taken on with it (inside a patch, the
    # nearest reported ones are all on one side, spacings away: their affine motion there is an
    # extrapolation whose noise the flow check reads as drift)
    every = np.r_[pool, n + np.arange(m)]
    k = min(NEIGHBOURS, len(every) - 1)
    nb_new = np.full((m, NEIGHBOURS), n + m, np.int64)
    if k:
        _, j = k_nearest(np.r_[state.last_uv[pool], uv], uv, k + 1)
        nb_new[:, :k] = every[j[:, 1:]]
    state.neighbours = np.r_[np.where(state.neighbours >= n, n + m, state.neighbours), nb_new]
    mass, smass = found.meas.mass, found.meas.sigma_mass
    grow = {  # per new target: (field, value)
        "ids": found.ids, "kind": target_kind(found.ids), "ref_uv": uv - disp, "ref_mass": mass,
        "ref_smass": smass, "last_mass": mass, "last_smass": smass, "radius": found.radius,
        "spacing": found.spacing, "pred": uv + vel, "last_uv": uv, "last_vel": vel,
        "timed": np.full(m, bool(k)), "blind": np.zeros(m, np.int64), "since": np.ones(m, np.int64),
    }  # fmt: skip
    for name, value in grow.items():
        old = getattr(state, name)
        setattr(state, name, np.concatenate([old, np.asarray(value, old.dtype)]))
    # where their reported neighbours' displacement field puts them (a smooth field: the
    # tracker's flow check compares dots taken on together with each other from the next frame)
    reported_now = np.r_[in_pool, np.zeros(m, bool)]
    state.ref_uv = reference_places(
        state.ref_uv, state.last_uv, reported_now, n, REFERENCE_WIDTH * found.spacing
    )
