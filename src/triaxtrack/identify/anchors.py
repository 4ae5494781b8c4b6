"""The pedestal CTs that fix a membrane grid region's column and row offsets.

A pedestal CT pair (top CT C, bottom CT C + 16), or a single pedestal CT whose partner was not
decoded, is an anchor (:class:`_Anchor`). The pair's line gives the column of C's larger dots,
c = (C - 1) * 4 + 1 (corrected for the CTs' parallax, as they stand proud of the membrane); the
CTs, ``z_from_face`` above and below the membrane's end rows, give the row. The anchors' readings
of a region must agree (:func:`settle_offsets`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from triaxtrack.identify.grid import ellipse_radius
from triaxtrack.identify.state import IdentifyParams
from triaxtrack.kit_design import KitDesign


@dataclass(frozen=True)
class _Anchor:
    """A pedestal CT pair, or a single pedestal CT, that fixes the membrane columns under it."""

    C: int  # the pair's column number (the top CT's ID offset + 1): c = (C - 1) * 4 + 1
    top: tuple[np.ndarray, np.ndarray] | None  # (centre, ellipse map) of the top CT
    bottom: tuple[np.ndarray, np.ndarray] | None

    def first_ct(self) -> tuple[np.ndarray, np.ndarray]:
        """The (centre, ellipse map) of the top CT, or of the bottom one when it alone was decoded."""
        ct = self.top if self.top is not None else self.bottom
        if ct is None:
            raise ValueError(f"the pedestal anchor of column {self.C} has no decoded CT")
        return ct


def _pedestal_anchors(centres: dict, design: KitDesign) -> list[_Anchor]:
    """Pairs first (the paper's method), then single CTs whose partner was not decoded."""
    ped = {s.surface: s for s in design.pedestal_targets.stripes}
    top, bottom = ped["pedestal_top"], ped["pedestal_bottom"]
    anchors = []
    for k in range(top.count):
        a, b = centres.get(top.first_id + k), centres.get(bottom.first_id + k)
        if a is not None or b is not None:
            anchors.append(_Anchor(k + 1, a, b))
    return sorted(anchors, key=lambda x: x.top is None or x.bottom is None)


def _axis_down(anchors: list[_Anchor]) -> np.ndarray:
    """The image direction of -z along the specimen, from the decoded pedestal CTs."""
    tops = [a.top[0] for a in anchors if a.top is not None]
    bottoms = [a.bottom[0] for a in anchors if a.bottom is not None]
    if not tops or not bottoms:
        return np.array([0.0, 1.0])
    d = np.mean(bottoms, axis=0) - np.mean(tops, axis=0)
    return d / np.linalg.norm(d)


def _width_ratio(ellipse_map: np.ndarray, down: np.ndarray) -> float:
    """An ellipse's radius across ``down`` over its radius along it."""
    right = np.array([down[1], -down[0]])
    return float(
        ellipse_radius(ellipse_map[None], right[None])[0] / ellipse_radius(ellipse_map[None], down[None])[0]
    )


MIN_OVERRULING_PAIRS = 2  # pedestal CT pairs that agree on a region overrule single CTs
MAX_TAN_PHI = 3.0  # beyond about 72 degrees off a CT's normal, its parallax is not trusted
# the row pitch of a strained membrane changes along its height (bulging, end restraint: up to
# about 20 % between the end rows and the middle at 10 % axial strain), so a column's row read
# from a pedestal face with the pitch of its nearest dots is off by up to this share of the rows
# between them and the face: it is trusted only while that stays within the row tolerance (at
# 10 % strain, 25.6 rows read 4.4 rows off and gave 828 wrong IDs)
MAX_PITCH_CHANGE = 0.2
# a region's row pitch, in mm by the pedestal CT's scale, over the design's (specimen height over
# rows): a strained membrane's rows stay well within this (0.8-1.2 at 10 % axial strain); where
# the small dots are too small to resolve (720p, a 450 mm ring, focal 0.55 x width: 2.5 px dots)
# the larger dots alone form a grid four rows apart, which read 39 wrong IDs on one camera
ROW_PITCH_RANGE = (0.6, 1.6)


@dataclass(frozen=True)
class _MembraneView:
    """What the membrane labelling knows of the view: where the specimen's axis images, how
    round a pedestal CT seen head-on looks, and the design's parallax numbers."""

    axis_point: np.ndarray
    q_max: float  # largest (width across / height along the axis) of the pedestal CTs' centre dots
    proud_mm: float  # pedestal radius - membrane outer radius
    column_mm: float  # membrane column pitch on its outer surface

    @staticmethod
    def of(regions, anchors, axis, pos, design: KitDesign) -> _MembraneView:
        nodes = [k for g in regions for k in g.values()]
        q = [_width_ratio(e[1], axis) for a in anchors for e in (a.top, a.bottom) if e is not None]
        r_m = design.specimen.diameter / 2 + design.specimen.membrane_thickness
        return _MembraneView(
            axis_point=np.median(pos[nodes], axis=0) if nodes else np.zeros(2),
            q_max=max(q) if q else 1.0,
            proud_mm=design.pedestal.radius - r_m,
            column_mm=2 * np.pi * r_m / design.membrane.columns,
        )


def _grid_steps(grid: dict, pos: np.ndarray, nodes: list, di: int, dj: int) -> np.ndarray:
    """Image steps from the given nodes to their (di, dj) neighbours, where labelled."""
    return np.array(
        [pos[grid[(i + di, j + dj)]] - pos[grid[(i, j)]] for i, j in nodes if (i + di, j + dj) in grid]
    )


def _anchor_down(
    an: _Anchor, grid: dict, nodes: np.ndarray, xy: np.ndarray, pos: np.ndarray
) -> np.ndarray | None:
    """The unit image direction of -z at an anchor: along its CT pair, or for a single CT the
    median step to the next row among the region's 30 dots nearest it (``nodes`` (N, 2) grid
    indices (row, column) at ``xy`` (N, 2) undistorted pixels); None with fewer than 3 such steps."""
    ends = [e for e in (an.top, an.bottom) if e is not None]
    if len(ends) == 2:
        down = ends[1][0] - ends[0][0]  # bottom - top
        down /= np.linalg.norm(down)
        return down
    near = np.argsort(np.linalg.norm(xy - ends[0][0], axis=1))[:30]
    steps = _grid_steps(grid, pos, [tuple(nodes[k]) for k in near], 1, 0)
    if len(steps) < 3:
        return None
    down = np.median(steps, axis=0)
    down /= np.linalg.norm(down)
    return down


def _anchor_column(
    an: _Anchor,
    down: np.ndarray,
    grid: dict,
    nodes: np.ndarray,
    xy: np.ndarray,
    pos: np.ndarray,
    pj: int,
    step: int,
    ctx: _MembraneView,
) -> int | None:
    """The region's grid column (index j) under the anchor: of the columns of larger dots (phase
    ``pj``, every ``step``), the one whose dots nearest the CTs lie nearest the anchor's line along
    ``down``, after the CTs' parallax; None when the region has fewer than 3 column steps near
    the anchor, that column is more than 1.5 column pitches away (not in this region) or the
    next one is not at least twice as far (seen too obliquely to tell)."""
    ends = [e for e in (an.top, an.bottom) if e is not None]
    p0 = ends[0][0]
    right = np.array([down[1], -down[0]])
    near = np.argsort(np.linalg.norm(xy - p0, axis=1))[:30]
    gaps = _grid_steps(grid, pos, [tuple(nodes[k]) for k in near], 0, 1)
    if len(gaps) < 3:
        return None
    col_px = float(np.median(np.linalg.norm(gaps, axis=1)))
    # parallax: the CTs stand proud of the membrane by `proud` mm, so seen at an angle phi off
    # their normal the membrane column under them appears shifted towards the specimen's axis
    # by proud * sin(phi), i.e. (proud / column pitch) * tan(phi) columns
    cos_phi = np.mean([min(1.0, _width_ratio(e[1], down) / ctx.q_max) for e in ends])
    tan_phi = min(np.sqrt(max(1 - cos_phi**2, 0.0)) / max(cos_phi, 1e-3), MAX_TAN_PHI)
    side = np.sign((p0 - ctx.axis_point) @ right)
    expected = -side * col_px * ctx.proud_mm / ctx.column_mm * tan_phi
    perp = (xy - p0) @ right - expected
    dist_ends = np.min([np.linalg.norm(xy - e[0], axis=1) for e in ends], axis=0)
    cols = {}
    for j in np.unique(nodes[:, 1]):
        if (j - pj) % step:
            continue
        sel = np.nonzero(nodes[:, 1] == j)[0]
        if len(sel) < 2:
            continue
        use = sel[np.argsort(dist_ends[sel])[:3]]  # the column's dots nearest the CTs: no bulge
        cols[int(j)] = float(np.median(perp[use]))
    if not cols:
        return None
    ranked = sorted(cols, key=lambda j: abs(cols[j]))
    jc = ranked[0]
    if abs(cols[jc]) > 1.5 * col_px:
        return None  # the anchor's column is not in this region
    if len(ranked) > 1 and abs(cols[ranked[1]]) < 2 * abs(cols[jc]):
        return None  # seen too obliquely to tell its column
    return jc


def _anchor_row(
    an: _Anchor,
    down: np.ndarray,
    i_col: np.ndarray,
    xy_col: np.ndarray,
    pi: int,
    design: KitDesign,
    p: IdentifyParams,
) -> int | None:
    """The region's row offset from the anchor, read on one grid column (row indices ``i_col``,
    positions ``xy_col`` (N, 2) undistorted pixels) from each of its CTs: the membrane's end row
    lies half a row pitch from the pedestal face, which is ``z_from_face`` from the CT centres
    (rigid); the pitch is measured on the column itself, as the membrane may be strained
    unevenly. The offset is the one of the larger dots' row phase ``pi`` nearest the readings;
    None when no CT reads it or a reading is more than ``p.row_tolerance`` rows from it."""
    m = design.membrane
    rc = design.coded_target.centre_radius
    z_from_face = design.pedestal_targets.stripes[0].z_from_face
    step, first = m.large_step, m.large_first
    estimates = []
    for end, sign in ((an.top, 1.0), (an.bottom, -1.0)):
        if end is None:
            continue
        centre, mp = end
        mm_per_px = rc / ellipse_radius(mp[None], down[None])[0]
        d_mm = np.abs((xy_col - centre) @ down) * mm_per_px
        order = np.argsort(d_mm)[:4]
        di = np.abs(np.diff(i_col[order]))
        if len(order) < 3 or np.any(di != 1):
            continue  # the column's end rows are not all there
        pitch = float(np.median(np.abs(np.diff(d_mm[order]))))
        row_mm = design.specimen.height / m.rows
        if not ROW_PITCH_RANGE[0] <= pitch / row_mm <= ROW_PITCH_RANGE[1]:
            continue  # not the membrane's rows (a lattice of the larger dots alone, say)
        rows_from_face = (d_mm[order[0]] - z_from_face) / pitch
        if rows_from_face * MAX_PITCH_CHANGE > p.row_tolerance:
            continue  # the column's nearest dots are too far from the face to count rows
        r_first = 0.5 + rows_from_face if sign > 0 else m.rows + 0.5 - rows_from_face
        estimates.append(float(r_first - i_col[order[0]]))
    if not estimates:
        return None
    base = (first - pi) % step
    r_off = base + step * round((np.mean(estimates) - base) / step)
    if any(abs(e - r_off) > p.row_tolerance for e in estimates):
        return None
    return int(r_off)


def _anchor_offsets(
    an: _Anchor,
    grid: dict,
    nodes: np.ndarray,
    xy: np.ndarray,
    phase: tuple[int, int],
    pos: np.ndarray,
    design: KitDesign,
    p: IdentifyParams,
    ctx: _MembraneView,
) -> tuple[int, int] | None:
    """(column offset, row offset) of a grid region from one anchor; None when it cannot tell:
    the column of C's larger dots, c = (C - 1) * 4 + 1, is the region's column under the anchor
    (:func:`_anchor_column`), and the row comes from the CTs' distance to the end rows
    (:func:`_anchor_row`)."""
    m = design.membrane
    step, first = m.large_step, m.large_first
    pi, pj = phase
    down = _anchor_down(an, grid, nodes, xy, pos)
    if down is None:
        return None
    jc = _anchor_column(an, down, grid, nodes, xy, pos, pj, step, ctx)
    if jc is None:
        return None
    c_off = step * (an.C - 1) + first - jc
    sel = np.nonzero(nodes[:, 1] == jc)[0]
    r_off = _anchor_row(an, down, nodes[sel, 0], xy[sel], pi, design, p)
    if r_off is None:
        return None
    return c_off % m.columns, r_off


def _membrane_region_offsets(grid, phase, anchors, pos, design: KitDesign, p, ctx):
    """(column offset, row offset) of one grown grid region from the pedestal CTs, or the reason
    it cannot be fixed."""
    if len(grid) < p.min_region_dots:
        return "membrane region too small"
    if phase is None:
        return "larger membrane dots not distinguishable"
    nodes = np.array(list(grid.keys()))
    xy = pos[np.fromiter(grid.values(), int)]
    offsets: dict[tuple[int, int], list[_Anchor]] = {}
    for an in anchors:
        off = _anchor_offsets(an, grid, nodes, xy, phase, pos, design, p, ctx)
        if off is not None:
            offsets.setdefault(off, []).append(an)
    return settle_offsets(offsets)


def settle_offsets(offsets: dict[tuple[int, int], list[_Anchor]]) -> tuple[int, int] | str:
    """The one (column, row) offset of a membrane region that its pedestal CTs support
    (``offsets``: offset -> the anchors that read it), or the reason there is none.

    A CT whose partner was not decoded reads its column from one end only, and towards a
    silhouette it may read one large-dot column off: at least ``MIN_OVERRULING_PAIRS`` pairs that
    agree overrule such CTs. Anything else that disagrees leaves the region unlabelled.
    """
    if not offsets:
        return "no pedestal CT fixes this membrane region"
    if len(offsets) == 1:
        return next(iter(offsets))
    paired = {o: sum(a.top is not None and a.bottom is not None for a in ans) for o, ans in offsets.items()}
    backed = [o for o, n in paired.items() if n]
    if len(backed) == 1 and paired[backed[0]] >= MIN_OVERRULING_PAIRS:
        return backed[0]
    return "pedestal CTs disagree on this membrane region"
