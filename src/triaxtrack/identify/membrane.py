"""The membrane's dot grid: regions grown from the pedestal CTs, their IDs, and the grid-neighbour
checks on membrane IDs.

From each pedestal CT pair (top CT C, bottom CT C + 16) a seed dot near the pair's line starts a
2-D walk of the grid (:func:`~triaxtrack.identify.grid.grow_grid`): each next dot is predicted
from its labelled grid neighbours (straight continuation and parallelograms) and accepted only
when exactly one detected dot lies within the gate. The larger dots (every fourth row and
column, Eqs. 2-3) give the grid's phase by their area (:func:`_grid_phase`); the pedestal CTs
give the column and row offsets (:mod:`~triaxtrack.identify.anchors`). ID = (r - 1) * 64 + c +
1000 (Eq. 4). A region no pedestal CT fixes (beyond a longitudinal stripe's band) is fixed across
the band from a fixed neighbour (:func:`_bridge`). The dots beside a band (its blurred edge in
their image) are kept out of the regions and taken on afterwards from the labelled grid around
them (:func:`_label_beside_band`). A labelled dot that lies off the smooth lines of its grid
column and row by more than the centroid noise of the frame's dots of its size (an edge's fringe
or a neighbour in its centroid) is unlabelled (:func:`_off_grid`).
"""

from __future__ import annotations

from collections import Counter

import numpy as np
import pandas as pd

from triaxtrack.identify.anchors import _axis_down, _membrane_region_offsets, _MembraneView, _pedestal_anchors
from triaxtrack.identify.grid import NEIGHBOURS, _grow_region, _Pool, ellipse_radius, grow_grid
from triaxtrack.identify.state import UNLABELLED, IdentifyParams, _assign, _Frame
from triaxtrack.kit_design import KitDesign, MembraneDesign

PHASE_SIGMAS = 5.0  # the larger dots' class stands out from the others by this many standard errors
STAND_OUT = 0.75  # ... and this share of its dots (two at least) each stand out from them


def _grid_phase(grid: dict, area: np.ndarray, p: IdentifyParams) -> tuple[int, int] | None:
    """(row, col) residues mod 4 of the larger dots, from each dot's log area over its
    neighbours'. The class of the larger dots must stand out from the next best by
    ``phase_margin``, from the other classes' dots together by ``PHASE_SIGMAS`` standard errors
    of the difference of means (the scatter pooled within the classes; one class of 16 out by 5
    by chance: about 5e-6), and ``STAND_OUT`` of its dots (two at least) each from them by half
    ``phase_margin``: so two larger dots fix a strip two columns wide beside a band where they
    stand far out of the noise, and neither a region's noise nor one outlier is read as a phase
    (while a few larger dots partly hidden or merged do not hide a region's)."""
    la = {node: np.log(area[k]) for node, k in grid.items()}
    excess: list[list[float]] = [[] for _ in range(16)]
    for (i, j), v in la.items():
        # only opposite neighbours in pairs: the dots' size changes across the image (towards a
        # silhouette, along the axis) and a pair's mean cancels that change to first order
        nb = [
            0.5 * (la[(i - di, j - dj)] + la[(i + di, j + dj)])
            for di, dj in ((1, 0), (0, 1))
            if (i - di, j - dj) in la and (i + di, j + dj) in la
        ]
        if nb:
            excess[4 * (i % 4) + j % 4].append(v - float(np.mean(nb)))
    counts = np.array([len(e) for e in excess])
    mean = np.array([np.mean(e) if e else -np.inf for e in excess])
    order = np.argsort(mean)[::-1]
    b = order[0]
    rest = np.concatenate([np.asarray(e) for k, e in enumerate(excess) if k != b and e] or [np.zeros(0)])
    if counts[b] < 2 or len(rest) < 2 or mean[b] - mean[order[1]] < p.phase_margin:
        return None
    out = np.asarray(excess[b]) - rest.mean() >= 0.5 * p.phase_margin
    if out.sum() < max(2, STAND_OUT * len(out)):
        return None  # the class's mean an outlier's: too few of its dots larger
    spread = np.concatenate([np.asarray(e) - np.mean(e) for e in excess if len(e) >= 2])
    dof = len(spread) - int((counts >= 2).sum())
    if dof < 2:
        return None
    sigma = float(np.sqrt(np.sum(spread**2) / dof))
    if mean[b] - rest.mean() < PHASE_SIGMAS * sigma * np.sqrt(1 / counts[b] + 1 / len(rest)):
        return None
    return int(b // 4), int(b % 4)


def _label_membrane(f: _Frame, pool: _Pool, centres: dict, design: KitDesign, p: IdentifyParams) -> None:
    rc = design.coded_target.centre_radius
    anchors = _pedestal_anchors(centres, design)
    axis = _axis_down(anchors)
    area = f.blobs.area_px.to_numpy()
    size_ratio = _size_ratio(design.membrane)
    regions = []
    z_from_face = design.pedestal_targets.stripes[0].z_from_face
    for an in anchors:
        if an.top is not None and an.bottom is not None:
            down = an.bottom[0] - an.top[0]
            down /= np.linalg.norm(down)
            start_at = 0.5 * (an.top[0] + an.bottom[0])
        else:
            centre, mp = an.first_ct()
            sign = 1.0 if an.top is not None else -1.0
            down = axis
            # a point on the membrane a quarter of its height from the CT's pedestal face
            depth_mm = design.specimen.height / 4 + z_from_face
            start_at = centre + sign * down * depth_mm * ellipse_radius(mp[None], down[None])[0] / rc
        _, start = pool.tree.query(start_at)
        regions += _grow_region(pool, int(start), down, p.gate, size_ratio)
    # then the dots no pedestal CT led to (beyond a longitudinal stripe's band): their regions
    # are fixed across the band below. Strips two columns wide are seeded last, from what the
    # wider regions left
    # (between the pedestals' CTs; a pedestal out of the picture, a close camera's, bounds
    # nothing: the image's edge does)
    tops = [a.top[0] @ axis for a in anchors if a.top is not None]
    bottoms = [a.bottom[0] @ axis for a in anchors if a.bottom is not None]
    if tops or bottoms:
        s = f.pos @ axis
        lo, hi = np.mean(tops) if tops else -np.inf, np.mean(bottoms) if bottoms else np.inf
        for narrow in (False, True):
            for k in np.nonzero(pool.free & (s > lo) & (s < hi))[0]:
                regions += _grow_region(pool, int(k), axis, p.gate, size_ratio, narrow)
    ctx = _MembraneView.of(regions, anchors, axis, f.pos, design)
    phases = [_grid_phase(g, area, p) if len(g) >= p.min_region_dots else None for g in regions]
    fixed: dict[int, tuple[int, int]] = {}
    reasons: dict[int, str] = {}
    for ri, grid in enumerate(regions):
        res = _membrane_region_offsets(grid, phases[ri], anchors, f.pos, design, p, ctx)
        if isinstance(res, str):
            reasons[ri] = res
        else:
            fixed[ri] = res
    # a region with no pedestal CT of its own (beyond a longitudinal stripe's band, towards a
    # silhouette) is fixed across the band from a fixed neighbour, where the phase of the larger
    # dots leaves exactly one choice
    changed = True
    while changed:
        changed = False
        for ri in [r for r in reasons if phases[r] is not None]:
            for rj, off in list(fixed.items()):
                res = _bridge(regions[ri], phases[ri], regions[rj], off, f.pos, axis, design)
                if res is not None:
                    fixed[ri] = res
                    del reasons[ri]
                    changed = True
                    break
    for ri, grid in enumerate(regions):
        name = f"membrane_region_{ri}"
        if ri in reasons:
            f.reason[np.fromiter(grid.values(), int)] = reasons[ri]
            continue
        ids = _grid_ids(grid, *fixed[ri], design.membrane)
        for node, k in grid.items():
            if node in ids:
                _assign(f, k, ids[node], name, 0.9)
            else:
                f.reason[k] = "beyond the membrane's rows"


def _bridge(grid, phase, other, other_off, pos, axis, design: KitDesign) -> tuple[int, int] | None:
    """(column offset, row offset) of ``grid`` from a fixed neighbouring region ``other``.

    Rows are matched along the specimen's axis between the two regions' facing columns; the
    number of columns hidden between them is estimated from the gap and the columns' spacing,
    and must be the one value within 1.5 columns of that estimate, and at most
    ``BRIDGE_MAX_HIDDEN``, that puts this region's larger dots on the design's larger columns
    and rows.
    """
    m = design.membrane
    step, first = m.large_step, m.large_first
    right = np.array([axis[1], -axis[0]])
    a_nodes = np.array(list(grid.keys()))
    b_nodes = np.array(list(other.keys()))
    a_xy = pos[np.fromiter(grid.values(), int)]
    b_xy = pos[np.fromiter(other.values(), int)]
    side = np.sign(np.median(a_xy @ right) - np.median(b_xy @ right))
    if side == 0:
        return None
    # facing columns: this region's column nearest the other, and the other's nearest this one
    a_col = {int(j): float(np.median(a_xy[a_nodes[:, 1] == j] @ right)) for j in np.unique(a_nodes[:, 1])}
    b_col = {int(j): float(np.median(b_xy[b_nodes[:, 1] == j] @ right)) for j in np.unique(b_nodes[:, 1])}
    # grid columns run along `right` (see _seed_grid): the facing ones are the extreme columns
    # with enough rows (a sparse outer column, broken up beside the band, is passed over)
    ja = _facing_column(grid, min(a_col) if side > 0 else max(a_col), int(side))
    jb = _facing_column(other, max(b_col) if side > 0 else min(b_col), -int(side))
    if ja is None or jb is None:
        return None
    ja2, jb2 = ja + int(side), jb - int(side)  # one column further in, to measure the spacing
    # each row's facing dot and its slope there (from the next column in), extrapolated to the
    # middle of the gap from both sides: a row images as an arc, and extrapolating its tangent
    # by the same distance from either side cancels the arc's curvature
    mid = 0.5 * (a_col[ja] + b_col[jb])
    ends_a = _row_ends(grid, pos, ja, ja2, axis, right, mid)
    ends_b = _row_ends(other, pos, jb, jb2, axis, right, mid)
    if len(ends_a) < BRIDGE_MIN_ROWS or len(ends_b) < BRIDGE_MIN_ROWS:
        return None
    ib = np.array(list(ends_b))
    zb = np.array([ends_b[i][0] for i in ib])
    pitch = np.median(np.abs(np.diff(zb[np.argsort(ib)])))
    shifts, gaps = [], []
    for i, (z, gap_a, _) in ends_a.items():
        k = int(np.argmin(np.abs(zb - z)))
        if abs(zb[k] - z) < 0.35 * pitch:
            shifts.append(int(ib[k]) - i)
            gaps.append(gap_a + ends_b[int(ib[k])][1])
    if len(shifts) < BRIDGE_MIN_ROWS:
        return None
    values, counts = np.unique(shifts, return_counts=True)
    if counts.max() < 0.8 * len(shifts):
        return None
    di = int(values[np.argmax(counts)])
    # the columns' spacing row by row (a column's median across a curved strip is not its place)
    spacing = 0.5 * sum(float(np.median([e[2] for e in ends.values()])) for ends in (ends_a, ends_b))
    n_est = float(np.median(gaps)) / spacing  # columns from jb to ja
    c_off_b, r_off_b = other_off
    r_off = r_off_b + di
    pi, pj = phase
    if (pi + r_off - first) % step:
        return None  # the rows across the band do not put the larger dots on larger rows
    c_b = jb + c_off_b  # column number (unwrapped) of the other's facing column
    fits = [
        n for n in range(1, min(int(n_est) + 3, BRIDGE_MAX_HIDDEN + 1))
        if abs(n - n_est) < 1.5 and (pj + c_b + side * n - ja - first) % step == 0
    ]  # fmt: skip
    if len(fits) != 1:
        return None
    c_off = int((c_b + side * fits[0] - ja) % m.columns)
    return c_off, r_off


BRIDGE_MIN_ROWS = 5  # rows matched across a band to fix a region from its neighbour
# a band 5 mm wide hides 1-5 membrane columns behind it (the bridges of five tests and two renders);
# regions farther apart do not face each other across one band: bridged over the whole region
# between (a 4K camera at a 290 mm ring, from one silhouette strip to the other, 78 columns
# over), the columns counted from their spacing at its edges came 12 columns off
BRIDGE_MAX_HIDDEN = 8
BRIDGE_MAX_INWARD = 2  # columns a facing column may lie in from a region's extreme one
# a facing column holds at least this share of the rows of the region's fullest column: an outer
# column broken up beside the band holds a few rows, too few to match across it (a 720p camera
# of the tilted 420 mm ring took one with 7 rows of 60 once its dots were centred on the raw
# pixels, where it had held 4, and matched 1 row where the column next in matched 25)
BRIDGE_MIN_SHARE = 0.5


def _facing_column(grid: dict, extreme: int, inward: int) -> int | None:
    """The column nearest a band, from ``extreme`` (the region's outermost) ``inward`` (+1 or -1),
    whose rows have dots beside the next column in: at least ``BRIDGE_MIN_ROWS`` of them and
    ``BRIDGE_MIN_SHARE`` of the region's fullest column's rows; None if none within
    ``BRIDGE_MAX_INWARD`` columns."""
    fullest = max(Counter(j for _, j in grid).values(), default=0)
    for j in range(extreme, extreme + inward * (BRIDGE_MAX_INWARD + 1), inward):
        rows = sum((i, j + inward) in grid for i, jj in grid if jj == j)
        if rows >= max(BRIDGE_MIN_ROWS, BRIDGE_MIN_SHARE * fullest):
            return j
    return None


def _row_ends(
    grid: dict, pos: np.ndarray, j: int, j2: int, axis: np.ndarray, right: np.ndarray, mid: float
) -> dict[int, tuple[float, float, float]]:
    """Row -> (position along ``axis`` extrapolated to ``mid`` across it, distance across from
    column ``j``'s dot to ``mid``, distance across from it to column ``j2``'s) for the rows with
    dots in columns ``j`` and ``j2``."""
    out = {}
    for (i, jj), k in grid.items():
        if jj != j or (i, j2) not in grid:
            continue
        p, q = pos[k], pos[grid[(i, j2)]]
        dr = (p - q) @ right
        if abs(dr) < 1e-9:
            continue
        slope = ((p - q) @ axis) / dr
        out[int(i)] = (float(p @ axis + slope * (mid - p @ right)), abs(mid - p @ right), abs(dr))
    return out


# a dot beside a band is labelled where its image's radius is at least this many times the reach
# of the band's blurred edge (the fringe reaches into under 40 % of it): at 720p (radius 2 px,
# lens blur 1 px) the tracker's centroids of such dots were 0.14 px off at the median against
# 0.08 px for the other membrane dots (nvr-13cam-720p-r420-tilt), at 1080p (3.2 px) 0.075 against
# 0.068 px, at 4K (7 px) 0.055 against 0.060 px
BESIDE_MIN_BLURS = 2.5


def _label_beside_band(
    f: _Frame, pool: _Pool, beside: np.ndarray, image: np.ndarray, blur: float, m: MembraneDesign,
    p: IdentifyParams,
) -> None:  # fmt: skip
    """Label the membrane dots ``beside`` a longitudinal stripe's band, which the regions'
    growth and their bridges across the bands (:func:`_label_membrane`) did not see, by
    extending the labelled grid onto them alone (:func:`~triaxtrack.identify.grid.grow_grid`:
    each predicted from its labelled neighbours, taken when it is the only dot within the gate),
    so that the regions and their IDs are as without them. A dot is taken only where its
    ``image`` (per blob, its radius, pixels) is at least ``BESIDE_MIN_BLURS`` times the reach of
    the band's blurred edge ``blur`` (pixels), and its row neighbours lie at least twice its
    image and blur away: nearer, as columns crowd towards a silhouette, the one behind the band
    runs into it (at 1080p a merged blob 1.1 px off)."""
    member = np.nonzero(_is_membrane(f.ids, m))[0]
    cand = beside & (f.ids == UNLABELLED) & (image >= BESIDE_MIN_BLURS * blur)
    if not len(member) or not cand.any():
        return
    k = f.ids[member] - m.first_id
    rows, cols = k // m.columns, k % m.columns
    # columns unwrapped around the specimen, the seam in the widest gap between labelled ones
    used = np.unique(cols)
    cut = used[(np.argmax(np.diff(np.r_[used, used[0] + m.columns])) + 1) % len(used)]
    cols = (cols - cut) % m.columns + cut
    seed = {(int(r), int(c)): int(b) for r, c, b in zip(rows, cols, member, strict=True)}
    taken = set(f.ids[member].tolist())
    free = pool.free.copy()
    pool.free[:] = cand
    grid = grow_grid(pool, seed, p.gate, _size_ratio(m))
    pool.free[:] = free
    uv = f.blobs[["u_px", "v_px"]].to_numpy()
    for (r, c), b in grid.items():
        tid = r * m.columns + c % m.columns + m.first_id
        row = [np.linalg.norm(uv[grid[(r, c + dc)]] - uv[b]) for dc in (-1, 1) if (r, c + dc) in grid]
        clear = bool(row) and min(row) >= 2 * (image[b] + blur)
        if (r, c) not in seed and 0 <= r < m.rows and tid not in taken and clear:
            _assign(f, b, tid, "membrane_beside_band", 0.9)
            taken.add(tid)


def _size_ratio(m: MembraneDesign) -> float:
    """The membrane's larger dots' printed area over its smaller ones'."""
    return (m.large_dot_diameter / m.small_dot_diameter) ** 2


def _grid_ids(grid: dict, c_off: int, r_off: int, m: MembraneDesign) -> dict:
    """Node -> membrane ID (Eq. 4) for a region with known offsets; nodes beyond the rows left out."""
    out = {}
    for i, j in grid:
        r, c = i + r_off, (j + c_off - 1) % m.columns + 1
        if 1 <= r <= m.rows:  # beyond: not a membrane dot (a pedestal edge fragment, ...)
            out[(i, j)] = (r - 1) * m.columns + c + m.first_id - 1
    return out


def _is_membrane(ids: np.ndarray, m: MembraneDesign) -> np.ndarray:
    """Which of ``ids`` are membrane dot IDs (Eq. 4) of the design's membrane ``m``."""
    k = np.asarray(ids, np.int64) - m.first_id
    return (k >= 0) & (k < m.rows * m.columns)


def _grid_neighbour(ids: np.ndarray, m: MembraneDesign, dr: int, dc: int) -> np.ndarray:
    """The membrane ID ``dr`` rows and ``dc`` columns (around the specimen) from each of ``ids``
    (membrane IDs); 0 beyond the end rows."""
    k = np.asarray(ids, np.int64) - m.first_id
    row, col = k // m.columns + dr, (k % m.columns + dc) % m.columns
    return np.where((row >= 0) & (row < m.rows), row * m.columns + col + m.first_id, 0)


def _over_neighbours(ids: np.ndarray, values: np.ndarray, m: MembraneDesign) -> np.ndarray:
    """Each membrane dot's value (roundness, area) over the median of its labelled grid
    neighbours' (row and column, around the specimen); NaN where it has none or is not a
    membrane dot."""
    ids = np.asarray(ids, np.int64)
    values = np.asarray(values, np.float64)
    member = _is_membrane(ids, m)
    of = pd.Series(values[member], index=ids[member])
    of = of[~of.index.duplicated()]
    out = np.full(len(ids), np.nan)
    if member.any():
        nb = np.stack(
            [of.reindex(_grid_neighbour(ids[member], m, dr, dc)).to_numpy() for dr, dc in NEIGHBOURS]
        )
        has = np.isfinite(nb).any(axis=0)
        ratio = np.full(member.sum(), np.nan)
        ratio[has] = values[member][has] / np.nanmedian(nb[:, has], axis=0)
        out[member] = ratio
    return out


def _without_cross_support(ids: np.ndarray, m: MembraneDesign) -> np.ndarray:
    """Which of ``ids`` are membrane dots with no labelled grid neighbour in the rows above or
    below (row r - 1 or r + 1, same column): labels a row's chain alone gives. Towards a
    silhouette the columns crowd and a row's chain can run on past the row's last visible dot
    onto a sliver or the pedestal's fringe where the rows next to it have already ended (an end
    row's dots 1.1 px off at 720p and 2.7 px at 1080p, the only wrong IDs on nine clean and
    realistic first frames); every other dot of a region has a neighbour in the next row."""
    ids = np.asarray(ids, np.int64)
    member = _is_membrane(ids, m)
    labelled = ids[member]
    above = np.isin(_grid_neighbour(ids, m, -1, 0), labelled)
    below = np.isin(_grid_neighbour(ids, m, 1, 0), labelled)
    return member & ~(above | below)


def _membrane_row_ends(ids: np.ndarray, m: MembraneDesign) -> tuple[np.ndarray, np.ndarray]:
    """Which of ``ids`` are membrane dots whose row neighbour on either side (column c - 1 or
    c + 1, around the specimen) is not among ``ids``, and which of those are in an end row
    (along a pedestal) with every missing neighbour's own neighbour towards the middle rows
    among ``ids``: a gap in the row where a dot was lost, not the row's end at a silhouette."""
    ids = np.asarray(ids, np.int64)
    member = _is_membrane(ids, m)
    labelled = ids[member]
    row = (ids - m.first_id) // m.columns
    inward = np.where(row == 0, 1, -1)
    end_row = member & ((row == 0) | (row == m.rows - 1))
    ends = np.zeros(len(ids), bool)
    gap = end_row.copy()
    for s in (-1, 1):
        missing = member & ~np.isin(_grid_neighbour(ids, m, 0, s), labelled)
        ends |= missing
        beyond = np.where(inward > 0, _grid_neighbour(ids, m, 1, s), _grid_neighbour(ids, m, -1, s))
        gap &= ~missing | np.isin(beyond, labelled)
    return ends, ends & gap


# a membrane dot is checked against the smooth lines of its grid column and row: a cubic (towards
# a silhouette a column's spacing changes fast, as the sine of the view angle) through its
# labelled neighbours up to this many rows (columns) away, at least one on each side
OFF_GRID_REACH = 3
OFF_GRID_DEGREE = 3
# ... and is off the grid where it lies farther from a line than this many times the median
# distance of the frame's dots of its size (their centroid noise: a median is about 1.2 standard
# uncertainties of a 2-D distance, so 3.5 medians are 4.1 sigma, a chance of 2e-4 for a dot whose
# centroid is only noisy). On the dim test (1080p, 26 chunk starts, 39,541 labelled membrane
# dots; medians 0.09-0.15 px, up to twice that for the smallest dots) the four dots more than
# 1 px off were grazing dots at a silhouette: two merged with its fringe (1.5-1.6 px off) were
# 10-11 medians of their size off, two faint ones 1.0 px off were 3.6 and 3.1 (the second not
# found). Of the other labels at every chunk start, 0.04-0.09 % are found (dim, 260 mm, 1080p
# and 4K tests), 0.2-0.4 px off at the median against 0.05-0.10 px for all labels
OFF_GRID_MEDIANS = 3.5
# ... and at least this far (pixels), whatever the noise: as close as the tracker's centroid must
# agree with the identification's (TrackingConfig.first_agreement_px), far under the 1 px that
# makes an ID wrong. On the clean demo the medians are 0.02-0.03 px, and without it 3.5 of them
# took 0.4 % of the demo's labels (0.11 px off at the median) and 0.5 % at 4K (0.24 px)
OFF_GRID_FLOOR_PX = 0.25
OFF_GRID_CLASSES = 10  # size classes of the dots, each with its own median distance ...
OFF_GRID_CLASS_DOTS = 100  # ... of at least this many dots
OFF_GRID_ROUNDS = 3  # the lines refitted without the dots found off them, this many times at most


def _line_residuals(
    ids: np.ndarray, pos: np.ndarray, m: MembraneDesign, along_column: bool, lines: np.ndarray
) -> np.ndarray:
    """(N,) distance (pixels) of each membrane dot from the cubic through its labelled grid
    neighbours (among ``lines``) within ``OFF_GRID_REACH`` along its column (``along_column``) or
    its row (around the specimen), fitted to their ``pos``, over the distance's spread for a
    given centroid noise (which depends on where the neighbours lie); NaN for a dot without
    neighbours on both sides and four in all, or not a membrane dot (or labelled twice)."""
    offsets = np.r_[-OFF_GRID_REACH:0, 1 : OFF_GRID_REACH + 1]
    member = _is_membrane(ids, m)
    at = pd.DataFrame(pos[member], index=ids[member])
    once = ~at.index.duplicated(keep=False)
    single = member.copy()
    single[member] = once
    at = at[once & lines[member]]
    steps = [(d, 0) if along_column else (0, d) for d in offsets]
    nb = np.stack([at.reindex(_grid_neighbour(ids, m, *step)).to_numpy() for step in steps], axis=1)
    has = np.isfinite(nb).all(axis=2) & member[:, None]
    fitted = (
        has[:, :OFF_GRID_REACH].any(axis=1) & has[:, OFF_GRID_REACH:].any(axis=1)
        & (has.sum(axis=1) > OFF_GRID_DEGREE) & single
    )  # fmt: skip
    design = (offsets[:, None] ** np.arange(OFF_GRID_DEGREE + 1))[None] * has[..., None]
    normal = np.einsum("nki,nkj->nij", design, design)
    normal[~fitted] = np.eye(OFF_GRID_DEGREE + 1)
    inverse = np.linalg.inv(normal)
    # the line's value at the dot (the fit's constant term), and its spread: it carries the
    # neighbours' noise, amplified by where they lie, sqrt(1 + (normal^-1)_00) times a centroid's
    at_dot = np.einsum("nj,nkj,nkd->nd", inverse[:, 0], design, np.where(has[..., None], nb, 0.0))
    spread = np.sqrt(1.0 + inverse[:, 0, 0])
    return np.where(fitted, np.linalg.norm(pos - at_dot, axis=1) / spread, np.nan)


def _off_grid(ids: np.ndarray, pos: np.ndarray, area: np.ndarray, m: MembraneDesign) -> np.ndarray:
    """Which of ``ids`` are membrane dots whose ``pos`` (undistorted pixels) lies off the smooth
    lines of their grid column or row (:func:`_line_residuals`) by more than ``OFF_GRID_MEDIANS``
    times the median distance of the frame's dots of their size (``area``, pixels; a small dot,
    foreshortened towards a silhouette, has a noisier centroid: up to twice the median distance
    of the others) and more than ``OFF_GRID_FLOOR_PX``: a centroid pulled off its place by an
    edge's fringe or a neighbour it merged with. Such a dot bends its neighbours' lines too, so
    the lines are fitted again without the dots found off them (a dot too few clean neighbours
    leave keeps its first distance), ``OFF_GRID_ROUNDS`` times at most."""
    ids = np.asarray(ids, np.int64)
    pos = np.asarray(pos, np.float64)

    def distance(lines: np.ndarray) -> np.ndarray:
        return np.fmax(_line_residuals(ids, pos, m, True, lines), _line_residuals(ids, pos, m, False, lines))

    first = distance(np.ones(len(ids), bool))
    fitted = np.isfinite(first)
    if fitted.sum() < OFF_GRID_CLASS_DOTS:
        return np.zeros(len(ids), bool)
    # the typical distance per size class (equal counts of the fitted dots)
    n_class = min(OFF_GRID_CLASSES, int(fitted.sum()) // OFF_GRID_CLASS_DOTS)
    edges = np.quantile(area[fitted], np.linspace(0, 1, n_class + 1)[1:-1])
    size_class = np.searchsorted(edges, area)
    overall = float(np.median(first[fitted]))
    typical = np.array([np.median(first[fitted & (size_class == k)]) if (size_class[fitted] == k).any()
                        else overall for k in range(n_class)])  # fmt: skip
    limit = np.maximum(OFF_GRID_MEDIANS * typical[size_class], OFF_GRID_FLOOR_PX)
    off = first > limit
    for _ in range(OFF_GRID_ROUNDS):
        if not off.any():
            break
        again = distance(~off)
        now = np.where(np.isfinite(again), again, first) > limit
        if (now == off).all():
            break
        off = now
    return off
