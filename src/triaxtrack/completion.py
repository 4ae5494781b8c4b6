"""Labelling later from tracked neighbours (the paper's interpolation, section 2.4): a membrane
dot that was not labelled at a chunk's first frame (hidden by an occluder or a passing shadow,
cut by a band, or missed by identification) is taken on by the tracker once it can be seen.

Each frame, every such dot of the kit's membrane grid (but for its end rows) whose grid
neighbours within ``GRID_REACH`` rows and columns are reported on both sides, or in the next
two lines on one side, in rows and in columns alike, is predicted by the least-squares affine
map of their pixel positions over their grid offsets (row, column; columns wrap around the
specimen). A prediction is trusted where the neighbours fit that map within ``max_fit_px``
(RMS): the grid is locally affine on the image, which it is not across a band; where no
cell-wall target is reported within ``BAND_REACH`` spacings (a cell band's edge would cut its
image); and where the dot is seen within 60 degrees of face on (``MIN_VIEW_COS``: the fitted
column step over the row step against the kit's pitches; near a silhouette a centroid is
biased and the columns crowd). The dot's window is measured there
(:func:`triaxtrack.window.measure_windows`); a blob is its dot where it is clean (not merged,
lost or at the edge), within the gate of the prediction (``gate`` x the distance of its nearest
neighbour), no reported target sits within ``min_separation`` of that distance of it, its
normalised mass is within ``MASS_RATIO`` of the median reported dot's and, over its printed size,
like its reported grid neighbours' (:func:`_mass_like_neighbours`: within the tracker's
``mass_change`` or ``MASS_SCATTER_K`` times their scatter, so a dot partly hidden, as a row
emerging from under a strap is, waits until it is whole); a dot beyond two
reported columns must be seen within 60 degrees of face on by its own column step (from the dot
beside it) and must not be its row's last (:func:`_row_goes_on`: at a silhouette, seen through
the cell's lens, the column steps do not show how obliquely the last dot is seen, and its blob
takes in the dark edge's fringe). The dots that pass then count as reported for the
next ring within the same frame, so a patch hidden at the labelled frame (an occluder) grows
inward from its edges in one frame. A dot that passes in ``CONFIRM_FRAMES`` measured frames in
a row is taken on (streaks carry over the frames in which others are), its spacing (for the
tracker's checks) the shorter fitted step of the grid there. Pixels in OpenCV's convention.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numba
import numpy as np

from triaxtrack.kit import membrane_radius, target_table
from triaxtrack.kit_design import KitDesign
from triaxtrack.nearest import finite_rows, nearest_within
from triaxtrack.neighbour_motion import solve3
from triaxtrack.window import WindowMeasure

GRID_REACH = 2  # grid rows and columns on each side whose dots predict a dot's place
MIN_GRID_NEIGHBOURS = 6  # reported neighbours needed (at least one on each side in rows and columns)
MASS_RATIO = 3.0  # a blob whose mass is over this ratio from the median dot's is not a dot (large
# dots are about 1.6 times the small ones' area: within it; a fragment or a merged pair is not)
CONFIRM_FRAMES = 2  # measured frames in a row in which a dot must pass before it is taken on
GROWTH_ROUNDS = 30  # rings a hidden patch grows inward within one frame, at most
BAND_REACH = 2.0  # x its spacing: a dot this near a cell-wall target is beside (or behind) a cell
# band, whose edge cuts its image: identification, which knows the bands, labels it or not
# a dot's normalised mass over its printed size differs from its reported grid neighbours' median
# by at most the tracker's ``mass_change`` or this many times their scatter (the robust standard
# deviation of their logs, with the dot's own measurement noise), whichever is larger, as the
# tracker keeps a dot: one partly hidden (a row emerging from under a strap, its centroid 1-2 px
# off) or merged with something is not taken on
MASS_SCATTER_K = 4.0
MIN_MASS_NEIGHBOURS = 4  # reported neighbours with a mass needed for that scatter
MIN_VIEW_COS = 0.5  # a dot seen more obliquely than 60 degrees (its image squeezed across the
# columns to half) is not taken on: its centroid is biased there and its neighbours crowd it


class DotGrid(NamedTuple):
    """The kit's membrane dot grid of IDs (:class:`triaxtrack.volume.grid.MembraneGrid` is one
    frame's dots in 3-D): ``ids`` (rows, columns) int64, the ID of the dot in kit row r and
    column c at ``[r - 1, c - 1]`` (Eq. 4); ``aspect`` its column pitch over its row pitch on the
    undeformed membrane (a dot's image is foreshortened across the columns by the cosine of
    its view angle, so the image's column step over its row step is ``aspect`` times that)."""

    ids: np.ndarray
    aspect: float
    size: np.ndarray | None = None  # (rows, columns): each dot's printed area over the smaller dots'


def dot_grid(design: KitDesign) -> DotGrid:
    """The :class:`DotGrid` of a kit design (``membrane`` and ``specimen`` sections), with each
    dot's printed ``size`` from the kit's target table."""
    m = design.membrane
    rows, columns = int(m.rows), int(m.columns)
    ids = int(m.first_id) + np.arange(rows * columns, dtype=np.int64).reshape(rows, columns)
    aspect = (2 * np.pi * membrane_radius(design) / columns) / (design.specimen.height / rows)
    diameter = target_table(design).set_index("id")["diameter_mm"].reindex(ids.ravel()).to_numpy(float)
    size = (diameter / np.nanmin(diameter)) ** 2
    return DotGrid(ids, float(aspect), size.reshape(rows, columns))


class Candidates(NamedTuple):
    """The membrane dots not (yet) followed: their IDs, grid places and how many frames in a
    row each has passed."""

    ids: np.ndarray  # (m,) int64
    row: np.ndarray  # (m,) int64, 0-based
    col: np.ndarray  # (m,) int64, 0-based
    streak: np.ndarray  # (m,) int64


def grid_candidates(grid: np.ndarray, followed: np.ndarray, previous: Candidates | None = None) -> Candidates:
    """The dots of ``grid`` (:func:`dot_grid` ``ids``) whose IDs are not in ``followed`` but
    with at least ``MIN_GRID_NEIGHBOURS`` followed ones within ``GRID_REACH`` rows and columns
    (the others cannot be placed from followed dots; :func:`complete_grid` reaches them by
    growing from the dots it places), but for its end rows (beside the pedestals' dark faces,
    which a blurred dot merges with). With the ``previous`` candidates (after some were taken
    on), each keeps its streak, and those on a streak stay candidates (a patch's inner dots,
    reached by growth)."""
    seen = np.isin(grid, followed)
    near = _near_count(seen) - seen  # the dot itself is not its own neighbour
    pick = _inner(grid.shape) & ~seen & (near >= MIN_GRID_NEIGHBOURS)
    streak = np.zeros(grid.shape, np.int64)
    if previous is not None:
        streak[previous.row, previous.col] = previous.streak
        pick |= (streak > 0) & ~seen
    row, col = np.nonzero(pick)
    row, col = row.astype(np.int64), col.astype(np.int64)
    return Candidates(grid[row, col], row, col, streak[row, col])


def _inner(shape: tuple[int, ...]) -> np.ndarray:
    """All but the grid's end rows."""
    inner = np.zeros(shape, bool)
    inner[1:-1] = True
    return inner


def _near_count(mask: np.ndarray) -> np.ndarray:
    """Per grid cell, the cells of ``mask`` within ``GRID_REACH`` rows and columns (itself
    included; columns wrap around the specimen, rows do not): :func:`_box_count`, compiled (a
    numpy box sum took 2 x 5 shifted copies of the grid, 0.02-0.07 ms a call, a few calls a frame)."""
    return _box_count(np.ascontiguousarray(mask, np.bool_), GRID_REACH)


@numba.njit(cache=True)
def _box_count(mask: np.ndarray, reach: int) -> np.ndarray:
    """Per cell of ``mask`` (rows, columns), the True cells within ``reach`` rows (not wrapping)
    and columns (wrapping) of it, itself included: summed along the rows, then down the columns."""
    rows, cols = mask.shape
    along = np.zeros((rows, cols), np.int64)
    for r in range(rows):
        for c in range(cols):
            if mask[r, c]:
                for dc in range(-reach, reach + 1):
                    along[r, (c + dc) % cols] += 1
    near = np.zeros((rows, cols), np.int64)
    for r in range(rows):
        for dr in range(max(r - reach, 0), min(r + reach, rows - 1) + 1):
            for c in range(cols):
                near[r, c] += along[dr, c]
    return near


@numba.njit(cache=True)
def _spanned(side: np.ndarray, reach: int) -> bool:
    """Whether the reported neighbours per offset ``side`` (2 reach + 1: rows or columns)
    place a dot: between reported lines, or the next line beyond two reported ones."""
    if side[:reach].sum() > 0 and side[reach + 1 :].sum() > 0:
        return True
    return (side[reach - 1] > 0 and side[reach - 2] > 0) or (side[reach + 1] > 0 and side[reach + 2] > 0)


@numba.njit(cache=True, inline="always")
def _grid_neighbours(
    where: np.ndarray, r0: int, c0: int, reach: int, nj: np.ndarray, ndr: np.ndarray, ndc: np.ndarray
) -> int:
    """Into ``nj``, ``ndr``, ``ndc``: the dots (indices in ``where`` (rows, columns), -1: none)
    within ``reach`` rows and columns of node (``r0``, ``c0``), not itself, row by row, with their
    row and column offsets (columns wrap around the specimen, rows end); returns how many."""
    rows, cols = where.shape
    k = 0
    for dr in range(-reach, reach + 1):
        r = r0 + dr
        if r < 0 or r >= rows:
            continue
        for dc in range(-reach, reach + 1):
            j = where[r, (c0 + dc) % cols]
            if (dr == 0 and dc == 0) or j < 0:
                continue
            nj[k], ndr[k], ndc[k] = j, dr, dc
            k += 1
    return k


@numba.njit(cache=True)
def _interpolate(
    row: np.ndarray, col: np.ndarray, where: np.ndarray, uv: np.ndarray, radius: np.ndarray, reach: int,
    min_count: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Per candidate: (predicted uv (m, 2), fit RMS (m,), the nearest neighbour's distance (m,),
    the grid's spacing there (m,: the shorter fitted row or column step; the neighbours may all
    be two rows away),
    largest neighbour radius (m,), the fitted column step's length over the row step's (m,),
    and for a dot beyond two reported columns the place of the reported dot beside it in its
    row and the fitted row step (m, 3; NaN for a dot between reported columns)); NaN where
    fewer than ``min_count`` neighbours with a position in ``uv`` (indexed by ``where`` (rows,
    columns), -1: none), or not placed as the module docstring says (a dot beyond two reported
    columns needs the one beside it in its row: its own column step is measured from it, and
    :func:`_row_goes_on` steps on from it)."""
    m = len(row)
    pred = np.full((m, 2), np.nan)
    rms, near, rad, squeeze = np.full(m, np.nan), np.full(m, np.nan), np.full(m, np.nan), np.full(m, np.nan)
    step = np.full(m, np.nan)
    a, rhs = np.empty((3, 3)), np.empty((3, 2))
    size = (2 * reach + 1) ** 2
    du, dv, uu, vv = np.empty(size), np.empty(size), np.empty(size), np.empty(size)
    beside = np.full((m, 3), np.nan)
    nj, ndr, ndc = np.empty(size, np.int64), np.empty(size, np.int64), np.empty(size, np.int64)
    side = np.zeros(2 * reach + 1, np.int64)  # reported dots per row offset
    cside = np.zeros(2 * reach + 1, np.int64)  # reported dots per column offset
    for i in range(m):
        at_left = at_right = -1  # the reported dots beside it in its row
        k = 0
        side[:], cside[:] = 0, 0
        big = 0.0
        for t in range(_grid_neighbours(where, row[i], col[i], reach, nj, ndr, ndc)):
            j, dr, dc = nj[t], ndr[t], ndc[t]
            if not np.isfinite(uv[j, 0]):
                continue
            du[k], dv[k], uu[k], vv[k] = dr, dc, uv[j, 0], uv[j, 1]
            if dr == 0 and dc == -1:
                at_left = j
            if dr == 0 and dc == 1:
                at_right = j
            k += 1
            side[dr + reach] += 1
            cside[dc + reach] += 1
            big = max(big, radius[j])
        if k < min_count or not (_spanned(side, reach) and _spanned(cside, reach)):
            continue
        sr = sc = srr = src = scc = 0.0
        su = sv = sru = srv = scu = scv = 0.0
        for q in range(k):
            sr, sc, srr, src = sr + du[q], sc + dv[q], srr + du[q] ** 2, src + du[q] * dv[q]
            scc += dv[q] ** 2
            su, sv, sru, srv = su + uu[q], sv + vv[q], sru + du[q] * uu[q], srv + du[q] * vv[q]
            scu, scv = scu + dv[q] * uu[q], scv + dv[q] * vv[q]
        a[0, 0], a[0, 1], a[0, 2], rhs[0, 0], rhs[0, 1] = srr, src, sr, sru, srv
        a[1, 0], a[1, 1], a[1, 2], rhs[1, 0], rhs[1, 1] = src, scc, sc, scu, scv
        a[2, 0], a[2, 1], a[2, 2], rhs[2, 0], rhs[2, 1] = sr, sc, float(k), su, sv
        solve3(a, rhs)
        res, dist = 0.0, np.inf
        for q in range(k):
            eu = rhs[0, 0] * du[q] + rhs[1, 0] * dv[q] + rhs[2, 0] - uu[q]
            ev = rhs[0, 1] * du[q] + rhs[1, 1] * dv[q] + rhs[2, 1] - vv[q]
            res += eu * eu + ev * ev
            dist = min(dist, np.hypot(uu[q] - rhs[2, 0], vv[q] - rhs[2, 1]))
        pred[i, 0], pred[i, 1] = rhs[2, 0], rhs[2, 1]
        step_row, step_col = np.hypot(rhs[0, 0], rhs[0, 1]), np.hypot(rhs[1, 0], rhs[1, 1])
        rms[i], near[i], rad[i] = np.sqrt(res / k), dist, big
        step[i] = min(step_row, step_col)
        squeeze[i] = step_col / step_row
        if not (cside[:reach].sum() > 0 and cside[reach + 1 :].sum() > 0):  # beyond two columns
            j = at_left if at_left >= 0 else at_right
            if j < 0:
                pred[i] = np.nan
                continue
            beside[i, 0], beside[i, 1], beside[i, 2] = uv[j, 0], uv[j, 1], step_row
    return pred, rms, near, step, rad, squeeze, beside


def _row_goes_on(
    gray: np.ndarray, measure, meas: WindowMeasure, beside: np.ndarray, radius: np.ndarray,
    typical: float, gate: float, cell_uv: np.ndarray | None,
) -> np.ndarray:  # fmt: skip
    """Per measured dot (``meas``, k rows, placed beyond two reported columns), whether its row
    goes on a column step beyond it, away from the reported dot ``beside`` it in its row
    ((k, 2)): a clean dot not smaller than ``typical`` / ``MASS_RATIO`` lies within ``gate`` of
    a step there, or a reported cell-wall target (``cell_uv`` (c, 2)) within a step (a band in
    front). At a silhouette the next column's dot, if any, is a sliver merged with the dark
    beyond; identification does not label a row's last dot beside a dark edge either."""
    step = np.linalg.norm(meas.uv - beside, axis=1)
    probe = 2 * meas.uv - beside
    far = measure(gray, probe, radius)
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = (
            (far.reason == "")
            & (np.linalg.norm(far.uv - probe, axis=1) <= gate * step)
            & (far.mass >= typical / MASS_RATIO)
        )
    if cell_uv is not None and len(cell_uv):
        ok |= nearest_within(cell_uv, probe, step)[0] <= step
    return ok


class Found(NamedTuple):
    """The candidates taken on in one frame, and their measurement there."""

    ids: np.ndarray  # (k,) int64
    spacing: np.ndarray  # (k,) the grid's spacing there (the shorter fitted step), pixels
    radius: np.ndarray  # (k,) disc radius, pixels
    meas: WindowMeasure  # their windows' measurement (k rows)


def complete_grid(
    gray: np.ndarray,
    cand: Candidates,
    grid_index: np.ndarray,
    uv: np.ndarray,
    radius: np.ndarray,
    mass: np.ndarray,
    measure,
    *,
    aspect: float,
    gate: float,
    min_separation: float,
    max_fit_px: float,
    cell_uv: np.ndarray | None = None,
    grid_ids: np.ndarray | None = None,
    size: np.ndarray | None = None,
    mass_change: float = 0.25,
) -> tuple[Candidates, Found]:
    """One frame of completion (module docstring): the candidates with their streaks updated,
    and the ones taken on. ``grid_index`` (rows, columns): the followed target's row in ``uv``
    (n, 2: reported centroids this frame, NaN where not), ``radius`` (n,) and ``mass`` (n,:
    normalised, NaN where not reported) of each dot of the grid, -1 where none; ``measure``:
    ``(gray, uv (k, 2), radius (k,)) -> WindowMeasure`` (k may be 0); ``aspect``: the grid's
    (:class:`DotGrid`); ``cell_uv`` (c, 2): the cell-wall targets reported this frame;
    ``grid_ids`` (rows, columns): the grid's IDs (:class:`DotGrid` ``ids``), without which the
    grid does not grow within the frame; ``size`` (rows, columns): its dots' printed sizes
    (:class:`DotGrid` ``size``), with which a dot's mass must be like its neighbours' within
    ``mass_change`` (:func:`_mass_like_neighbours`).

    Within the frame the grid grows inward ring by ring (at most ``GROWTH_ROUNDS``): a candidate
    that passes places the next, as a reported dot would. So a patch hidden at the labelled
    frame (an occluder) is taken on within ``CONFIRM_FRAMES`` frames of being seen again, where
    it took a ring every ``CONFIRM_FRAMES`` frames from its edges (and a patch wider than the
    neighbours reach, only from its corners: 36 % of a box of 223 dots on a 13-camera test). A
    taken-on dot's spacing is the grid's fitted step (its nearest neighbour when placed may have
    been two rows away: the tracker then took its neighbours for the same dot, "ambiguous")."""
    typical = np.nanmedian(mass) if np.isfinite(mass).any() else np.nan
    ids, row, col, streak0 = cand
    passed = np.zeros(len(ids), bool)
    measured = np.zeros(len(ids), bool)  # a blob that failed is not measured again this frame
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, WindowMeasure]] = []  # (which, step, rad, meas)
    index, at, rad_of, mass_of = grid_index.copy(), uv, radius, mass
    known = uv[finite_rows(uv)]
    for _ in range(GROWTH_ROUNDS):
        which = np.nonzero(~passed & ~measured)[0]
        pred, rms, near, step, rad, squeeze, beside = _interpolate(
            row[which], col[which], index, at, rad_of, GRID_REACH, MIN_GRID_NEIGHBOURS
        )
        tried = finite_rows(pred) & (rms <= max_fit_px) & (squeeze >= MIN_VIEW_COS * aspect)
        if cell_uv is not None and len(cell_uv) and tried.any():  # not beside a cell band
            d, _ = nearest_within(cell_uv, np.nan_to_num(pred), BAND_REACH * near)
            tried &= d > BAND_REACH * near
        k = np.nonzero(tried)[0]
        if not len(k):
            break
        meas = measure(gray, pred[k], rad[k])
        measured[which[k]] = True
        ok = _passes(gray, measure, meas, pred[k], near[k], beside[k], rad[k], known, typical,
                     gate=gate, min_separation=min_separation, aspect=aspect, cell_uv=cell_uv)  # fmt: skip
        if size is not None:
            ok &= _mass_like_neighbours(meas, row[which[k]], col[which[k]], index, mass_of, size, mass_change)
        if not ok.any() or grid_ids is None:
            break
        new = which[k[ok]]
        passed[new] = True
        parts.append((new, step[k[ok]], rad[k[ok]], WindowMeasure(*(a[ok] for a in meas))))
        # the passed dots place the next ring, as reported dots; the dots beside them that are
        # no candidate yet join
        index[row[new], col[new]] = len(at) + np.arange(len(new))
        at, rad_of, mass_of = np.r_[at, meas.uv[ok]], np.r_[rad_of, rad[k[ok]]], np.r_[mass_of, meas.mass[ok]]
        known = np.r_[known, meas.uv[ok]]
        er, ec = _joining(index, row, col, new)
        ids, row, col = np.r_[ids, grid_ids[er, ec]], np.r_[row, er], np.r_[col, ec]
        streak0 = np.r_[streak0, np.zeros(len(er), np.int64)]
        passed, measured = np.r_[passed, np.zeros(len(er), bool)], np.r_[measured, np.zeros(len(er), bool)]
    streak = np.where(passed, streak0 + 1, 0)
    sel = passed & (streak >= CONFIRM_FRAMES)
    found = _found(ids, sel, parts)
    keep = ~sel & ((np.arange(len(ids)) < len(cand.ids)) | passed)  # a new dot stays if it passed
    return Candidates(ids[keep], row[keep], col[keep], streak[keep]), found


def _mass_like_neighbours(
    meas: WindowMeasure, row: np.ndarray, col: np.ndarray, where: np.ndarray, mass: np.ndarray,
    size: np.ndarray, change: float,
) -> np.ndarray:  # fmt: skip
    """(k,) bool: whether each measured candidate (``meas``, at grid ``row``, ``col``) has the
    mass of its reported grid neighbours within ``GRID_REACH`` (``where``: grid -> row of
    ``mass``, -1: none), each over its printed ``size``: its own over their median differs from
    1 by at most the larger of ``change`` and ``MASS_SCATTER_K`` x the scatter (the robust
    standard deviation of their logs, and its own measurement's relative noise). True where
    fewer than ``MIN_MASS_NEIGHBOURS`` neighbours have a mass (the other checks decide)."""
    centre, spread = _neighbour_log_mass(row, col, where, mass, size, GRID_REACH)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = meas.mass / size[row, col] / np.exp(centre)
        noise = np.hypot(spread, meas.sigma_mass / meas.mass)
        like = np.abs(ratio - 1) <= np.fmax(change, MASS_SCATTER_K * noise)
    return like | ~np.isfinite(centre)


@numba.njit(cache=True)
def _neighbour_log_mass(
    row: np.ndarray, col: np.ndarray, where: np.ndarray, mass: np.ndarray, size: np.ndarray, reach: int
) -> tuple[np.ndarray, np.ndarray]:
    """Per candidate: the median and the robust standard deviation (1.4826 x the median absolute
    deviation) of log(mass / size) over its grid neighbours within ``reach`` rows and columns
    that have a finite ``mass`` (indexed by ``where``; columns wrap around); NaN where fewer than
    ``MIN_MASS_NEIGHBOURS``."""
    m = len(row)
    cols = where.shape[1]
    centre, spread = np.full(m, np.nan), np.full(m, np.nan)
    vals = np.empty((2 * reach + 1) ** 2)
    nj, ndr, ndc = np.empty(len(vals), np.int64), np.empty(len(vals), np.int64), np.empty(len(vals), np.int64)
    for i in range(m):
        k = 0
        for t in range(_grid_neighbours(where, row[i], col[i], reach, nj, ndr, ndc)):
            j = nj[t]
            if not np.isfinite(mass[j]) or mass[j] <= 0:
                continue
            vals[k] = np.log(mass[j] / size[row[i] + ndr[t], (col[i] + ndc[t]) % cols])
            k += 1
        if k < MIN_MASS_NEIGHBOURS:
            continue
        med = np.median(vals[:k])
        centre[i] = med
        spread[i] = 1.4826 * np.median(np.abs(vals[:k] - med))
    return centre, spread


def _passes(
    gray: np.ndarray,
    measure: Callable[[np.ndarray, np.ndarray, np.ndarray], WindowMeasure],
    meas: WindowMeasure,
    pred: np.ndarray,
    near: np.ndarray,
    beside: np.ndarray,
    rad: np.ndarray,
    known: np.ndarray,
    typical: float,
    *,
    gate: float,
    min_separation: float,
    aspect: float,
    cell_uv: np.ndarray | None,
) -> np.ndarray:
    """(k,) bool: which of k candidates measured at ``meas`` (predicted at ``pred`` (k, 2),
    grid spacing ``near`` (k,), the dot beside each in its row ``beside`` (k, 3: u, v, its
    step), radius ``rad`` (k,)) pass: found near the prediction, not on a ``known`` target,
    of the ``typical`` mass, not seen too obliquely, and, beside a dot, their row goes on
    (:func:`_row_goes_on`). Arguments as :func:`complete_grid`'s."""
    ok = (meas.reason == "") & (np.linalg.norm(meas.uv - pred, axis=1) <= gate * near)
    if len(known) and ok.any():  # not on a reported target (nor one taken on this round)
        d, _ = nearest_within(known, np.nan_to_num(meas.uv), min_separation * near)
        ok &= d >= min_separation * near
    with np.errstate(invalid="ignore", divide="ignore"):
        ok &= np.abs(np.log(meas.mass / typical)) <= np.log(MASS_RATIO)
        # beyond two columns: its own column step (from the dot beside it in its row) shows
        # how obliquely it is seen (the fitted step is the columns' behind it), and it is not
        # its row's last dot (at a silhouette, that one takes in the dark edge's fringe, and
        # the cell's lens may stretch the columns there: their step does not show it)
        own = np.linalg.norm(meas.uv - beside[:, :2], axis=1) / beside[:, 2]
        ok &= ~(own < MIN_VIEW_COS * aspect)
    good = np.nonzero(ok & np.isfinite(beside[:, 0]))[0]  # the others need no probe
    if len(good):
        sub = WindowMeasure(*(a[good] for a in meas))
        ok[good] = _row_goes_on(gray, measure, sub, beside[good, :2], rad[good], typical, gate, cell_uv)
    return ok


def _joining(
    index: np.ndarray, row: np.ndarray, col: np.ndarray, new: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(rows, columns) of the grid's inner cells beside the candidates ``new`` just placed
    (``row``, ``col``: every candidate's) that hold neither a dot (``index`` < 0) nor a candidate."""
    placed = np.zeros(index.shape, bool)
    placed[row[new], col[new]] = True
    listed = np.zeros(index.shape, bool)
    listed[row, col] = True
    er, ec = np.nonzero((_near_count(placed) > 0) & (index < 0) & ~listed & _inner(index.shape))
    return er, ec


def _found(ids: np.ndarray, sel: np.ndarray, parts: list) -> Found:
    """The candidates ``sel`` (of ``ids``) taken on, with their measurements from the growth's
    rounds ``parts`` ((candidate indices, the grid's spacing, radius, WindowMeasure)),
    in candidate order."""
    if not parts:
        e = np.zeros(0)
        none = WindowMeasure(np.zeros((0, 2)), e, e, e, e, e, e, np.zeros(0, np.int64), np.zeros(0, bool))
        return Found(ids[:0], e, e, none)
    which = np.concatenate([p[0] for p in parts])
    order = np.argsort(which)
    take = sel[which[order]]
    rows = order[take]
    spacing = np.concatenate([p[1] for p in parts])[rows]
    rad = np.concatenate([p[2] for p in parts])[rows]
    meas = WindowMeasure(
        *(np.concatenate([getattr(p[3], f) for p in parts])[rows] for f in WindowMeasure._fields)
    )
    return Found(ids[which[rows]], spacing, rad, meas)
