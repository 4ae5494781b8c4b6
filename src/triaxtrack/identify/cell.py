"""The cell wall's dots: annular and longitudinal stripes, and the bands that hide the membrane.

* **Cell annular stripes.** The larger dot under cell CT ``c`` has ID ``4 c - 243`` (Eq. 1). Its
  position is predicted from the CT by the designed offset (``dot_offset`` mm down the cell),
  through the CT's local affine map (from its centre dot's ellipse and the direction to its
  neighbouring CTs), then refined to the nearest detected dot. It must be larger than the dots
  beside it. The smaller dots between two larger dots are found by 1-D linear interpolation;
  beyond the last larger dot in view, the stripe is followed dot by dot (extrapolating from
  the last three).
* **Longitudinal stripes.** The uppermost and lowermost dots are predicted from the CTs directly
  above and below them (the CT and its Eq. 1 dot fix the local vertical in the image), and the
  dots between are followed and interpolated along the stripe.
* **Bands.** A longitudinal stripe's white band hides the membrane behind it
  (:func:`_hide_behind_band`); a stripe whose CT is not seen is found as a straight line of dots
  on a brighter surface (:func:`_on_another_surface`, :func:`_straight_chains`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from triaxtrack.identify.coded import _theta_dir
from triaxtrack.identify.grid import WHITE_TOLERANCE, _Pool, grow_chain, local_affine
from triaxtrack.identify.state import UNLABELLED, IdentifyParams, _assign, _Frame
from triaxtrack.kit import eq1_dot_id
from triaxtrack.kit_design import KitDesign


def _label_cell_stripes(f: _Frame, pool: _Pool, centres: dict, design: KitDesign, p: IdentifyParams) -> None:
    cell = design.cell_targets
    per, offset = cell.dots_per_ct, cell.dot_offset
    rc = design.coded_target.centre_radius
    r_out = design.cell.outer_radius
    ct_stripes = {s.name: s for s in cell.ct_stripes}
    area = f.blobs.area_px.to_numpy()
    for ds in cell.dot_stripes:
        cs = ct_stripes[ds.ct_stripe]
        n = ds.count
        spacing_mm = 2 * np.pi * r_out / n
        anchors, hints = {}, {}
        for c in range(cs.first_id, cs.first_id + cs.count):
            if c not in centres:
                continue
            d = _theta_dir(c, cs.first_id, cs.count, centres)
            if d is None:
                continue
            centre, m = centres[c]
            a = local_affine(m, d, rc)
            pred = centre + a @ np.array([0.0, -offset])
            step = a @ np.array([spacing_mm, 0.0])
            k = pool.unique_within(pred, p.anchor_gate * np.linalg.norm(step))
            if k < 0:
                continue
            # Eq. 1's dot is the larger one: larger than every other dot around it
            near = [j for j in pool.tree.query_ball_point(pool.pos[k], 1.3 * np.linalg.norm(step)) if j != k]
            if near and area[k] < p.large_area_ratio * area[near].max():
                continue
            i = per * (c - cs.first_id)
            anchors[i] = k
            hints[i] = step  # to i + 1, and (evenly spaced) into i from i - 1
            hints.setdefault((i - 1) % n, step)
            pool.free[k] = False
        labels = grow_chain(pool, anchors, n, cyclic=True, gate=p.gate, step_hint=hints)
        for i, k in labels.items():
            _assign(f, k, ds.first_id + i, ds.name, 1.0 if i in anchors else 0.9)


# The scale (pixels per mm down the cell) borrowed from a neighbouring CT, one or two places round
# the cell, is that of another distance from the camera. Near a silhouette it was 9 % off on the
# 4K nvr test (seed 4, cam08): over the 22 mm from the bottom CT's Eq. 1 dot to the stripe's end
# that is 0.6 of the stripe's spacing, and its end was anchored on the last-but-one dot (6 wrong
# IDs). A borrowed scale is trusted only where this error over the reach stays inside the gate.
NEIGHBOUR_SCALE_ERR = 0.1


def _label_longitudinal(f: _Frame, pool: _Pool, centres: dict, design: KitDesign, p: IdentifyParams) -> None:
    cell = design.cell_targets
    offset = cell.dot_offset
    zt, zb = cell.longitudinal_z_top, cell.longitudinal_z_bottom
    labelled = {int(t): k for k, t in enumerate(f.ids) if t != UNLABELLED}
    top, bottom = cell.ct_stripes[0], cell.ct_stripes[-1]
    for ls in cell.longitudinal_stripes:
        n = ls.count
        spacing_mm = cell.longitudinal_spacing(ls)
        anchors, hints = {}, {}
        ct_top = ls.ct
        ct_bottom = ct_top - top.first_id + bottom.first_id
        for ct_id, ct_z, index, z in (
            (ct_top, top.z, 0, zt),
            (ct_bottom, bottom.z, n - 1, zb),
        ):
            dot = labelled.get(eq1_dot_id(ct_id, design))
            if dot is None:
                continue
            if ct_id in centres:
                down = (f.pos[dot] - centres[ct_id][0]) / offset  # pixels per mm down the cell
            else:  # a CT seen too obliquely to decode: the direction down from its neighbour's
                down = _neighbour_down(f, ct_id, centres, labelled, design)
                # whose scale is another distance from the camera's: trusted over a short reach
                if down is None or NEIGHBOUR_SCALE_ERR * abs(ct_z - offset - z) > p.anchor_gate * spacing_mm:
                    continue
            pred = f.pos[dot] + down * (ct_z - offset - z)
            k = pool.unique_within(pred, p.anchor_gate * spacing_mm * np.linalg.norm(down))
            if k < 0:
                continue
            anchors[index] = k
            # the step from index to index + 1 (grow_chain's convention), so from the bottom
            # anchor it is the step into it: the walk goes up from there
            hints[index if index == 0 else index - 1] = down * spacing_mm
            pool.free[k] = False
        # a stripe walks on past one missing dot: at a 420 mm ring (720p, seen 53-62 degrees off
        # face on) one dot not detected left 55 of a stripe's 60 dots unlabelled on a camera
        labels = grow_chain(
            pool, anchors, n, cyclic=False, gate=p.gate, step_hint=hints, max_bracket=2, bridge=True
        )
        for i, k in labels.items():
            _assign(f, k, ls.first_id + i, ls.name, 1.0 if i in anchors else 0.9)


def _neighbour_down(
    f: _Frame, ct_id: int, centres: dict, labelled: dict, design: KitDesign
) -> np.ndarray | None:
    """Pixels per mm down the cell at CT ``ct_id`` (not decoded) from the nearest decoded CT of
    its stripe (one or two places along, the nearer first) whose Eq. 1 dot is labelled."""
    stripe = next(s for s in design.cell_targets.ct_stripes if 0 <= ct_id - s.first_id < s.count)
    for step in (1, -1, 2, -2):
        nb = stripe.first_id + (ct_id - stripe.first_id + step) % stripe.count
        dot = labelled.get(eq1_dot_id(nb, design))
        if nb in centres and dot is not None:
            return (f.pos[dot] - centres[nb][0]) / design.cell_targets.dot_offset
    return None


def _band_zone(f: _Frame, order: np.ndarray, pad: np.ndarray | float, design: KitDesign) -> np.ndarray:
    """Which blobs lie within half the white band's width, plus ``pad`` (per blob or one,
    pixels), of the line through a longitudinal stripe's dots ``order`` (blob indices, in
    order along it)."""
    line = f.pos[order]
    # pixels per mm across the band at each stripe dot: its minor axis (the band is
    # foreshortened across, towards a silhouette, never along)
    across = f.blobs.minor_px.to_numpy()[order] / design.cell_targets.longitudinal_dot_diameter
    half = design.cell_targets.longitudinal_band_width / 2
    return _near_polyline(f.pos, line, half * np.maximum(across[:-1], across[1:]), pad)


def _hide_behind_band(
    f: _Frame, pool: _Pool, order: np.ndarray, image: np.ndarray, pad: np.ndarray, design: KitDesign
) -> np.ndarray:
    """Take out of the pool (reason given) the free dots whose image reaches the white band of
    a longitudinal stripe whose dots, in order along it, are ``order`` (blob indices) or its
    blurred edge: within half the band's width of the line through them plus ``pad`` (per
    blob, pixels). Returns those whose image does not reach the band itself (plus ``image``
    per blob): beside it, not behind it."""
    hide = _band_zone(f, order, pad, design) & pool.free
    pool.free[hide] = False
    f.reason[hide] = BEHIND_BAND
    return hide & ~_band_zone(f, order, image, design)


BEHIND_BAND = "on a longitudinal stripe's band"  # the reason a dot is not labelled there


MIN_CHAIN_DOTS = 8  # a straight line of at least this many dots on another surface is a stripe
CHAIN_LINE_PX = 1.0  # ... within this of a straight line (undistorted pixels: a generatrix of the
# cell images straight)
CHAIN_PITCH_MIN = 0.9  # a stripe's gaps are at least this x its design spacing in membrane rows
CHAIN_PITCH_MAX = 1.5  # ... and at the median under this: most of a stripe's dots are consecutive
CHAIN_AXIS_DEG = 15.0  # a stripe runs along the specimen's axis (tilted cameras, distortion)
PITCH_NEIGHBOURS = 8  # a grid dot's row neighbour is among its 8 nearest
PITCH_AXIS_DEG = 30.0  # ... in the axis's direction within this (a nearer row neighbour comes first)


def _row_pitch_px(pos: np.ndarray, dots: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """(N,) for each of ``dots`` (indices into ``pos``, undistorted pixels): the distance to its
    nearest neighbour among its ``PITCH_NEIGHBOURS`` nearest in the direction of ``axis`` (within
    ``PITCH_AXIS_DEG``), NaN if none: the membrane's row pitch there."""
    from scipy.spatial import cKDTree

    p = pos[dots]
    dist, nb = cKDTree(p).query(p, k=min(len(dots), PITCH_NEIGHBOURS + 1))
    out = np.full(len(dots), np.nan)
    for j in range(1, dist.shape[1]):  # nearest first; column 0 is the dot itself
        along = np.abs((p[nb[:, j]] - p) @ axis) >= np.cos(np.deg2rad(PITCH_AXIS_DEG)) * dist[:, j]
        out = np.where(np.isnan(out) & along, dist[:, j], out)
    return out


def _straight_chains(
    pos: np.ndarray, cand: np.ndarray, axis: np.ndarray, pitch: float, design: KitDesign
) -> list[np.ndarray]:
    """Longitudinal stripes among the blobs ``cand`` (indices; ``pos`` undistorted pixels): each
    a straight line of at least ``MIN_CHAIN_DOTS`` of them (RANSAC) along the specimen's axis
    (``axis``: its image direction, within ``CHAIN_AXIS_DEG``), its dots spaced as a stripe's
    are against the membrane's rows (``pitch``: the membrane's row pitch nearby, pixels; a stripe
    is spaced (z_top - z_bottom) / (count - 1), the rows height / rows: 3.15 against 2.37 mm)
    and most of them consecutive (the median gap under ``CHAIN_PITCH_MAX`` spacings: a membrane
    column's grazing dots, found every few rows at a silhouette, line up too), its blobs in
    order along it."""
    from skimage.measure import LineModelND, ransac

    left = np.asarray(cand, np.int64)
    out = []
    while len(left) >= MIN_CHAIN_DOTS:
        model, inl = ransac(pos[left], LineModelND, min_samples=2, residual_threshold=CHAIN_LINE_PX,
                            max_trials=200, rng=0)  # fmt: skip
        if model is None or inl is None or inl.sum() < MIN_CHAIN_DOTS:
            break
        members = left[inl]
        left = left[~inl]
        if abs(model.direction @ axis) < np.cos(np.deg2rad(CHAIN_AXIS_DEG)):
            continue  # a row of a ring's dots, not a stripe
        along = (pos[members] - model.origin) @ model.direction
        order = np.argsort(along)
        gap = np.median(np.diff(along[order])) / (_stripe_over_row_pitch(design) * pitch)
        if not CHAIN_PITCH_MIN <= gap < CHAIN_PITCH_MAX:
            continue  # a column of membrane dots (beside a bright edge, or every few rows), not a stripe
        out.append(members[order])
    return out


def _stripe_over_row_pitch(design: KitDesign) -> float:
    """A longitudinal stripe's dot spacing over the membrane's row spacing (design, mm)."""
    cell, m, spec = design.cell_targets, design.membrane, design.specimen
    return cell.longitudinal_spacing(cell.longitudinal_stripes[0]) / (spec.height / m.rows)


def _near_polyline(
    points: np.ndarray, line: np.ndarray, radius: np.ndarray, pad: np.ndarray | float = 0.0
) -> np.ndarray:
    """Points within ``radius[k] + pad`` of segment k of a polyline (``pad``: per point or one)."""
    out = np.zeros(len(points), bool)
    for a, b, r in zip(line[:-1], line[1:], radius, strict=True):
        ab = b - a
        t = np.clip(((points - a) @ ab) / max(ab @ ab, 1e-12), 0, 1)
        out |= np.linalg.norm(points - (a + t[:, None] * ab), axis=1) < r + pad
    return out


SURFACE_NEIGHBOURS = 8  # free dots around a dot whose white level is the surface's


def _on_another_surface(pool: _Pool) -> np.ndarray:
    """Which free dots lie on a brighter surface, its white level more than ``WHITE_TOLERANCE``
    above the median of their ``SURFACE_NEIGHBOURS`` nearest free dots' (a stripe's white band
    in front of the grey membrane); the white level follows uneven light smoothly, a printed
    surface's edge does not. A darker one is not a band: the membrane's grazing columns at its
    silhouette, their white level taken in with the dark beyond, line up along the axis as a
    stripe's dots do (every 2-4 rows: a straight chain of 7-16 of them on most cameras of a
    300 mm ring), and a band laid along them hid the column and its neighbours."""
    free = np.nonzero(pool.free)[0]
    out = np.zeros(len(pool.free), bool)
    if len(free) <= SURFACE_NEIGHBOURS:
        return out
    tree = cKDTree(pool.pos[free])
    _, nb = tree.query(pool.pos[free], k=SURFACE_NEIGHBOURS + 1)
    white = pool.white[free]
    ratio = white / np.median(white[nb[:, 1:]], axis=1)
    out[free] = ratio - 1 > WHITE_TOLERANCE
    return out


def _over_chain_neighbours(ids: np.ndarray, values: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """Each labelled dot's value (a length, an area) over the median of its labelled neighbours
    along its stripe (IDs one less and one more in the same group); NaN where it has none."""
    df = pd.DataFrame({"id": np.asarray(ids, np.int64), "g": np.asarray(groups, object),
                       "v": np.asarray(values, np.float64)})  # fmt: skip
    own = df[df.id > 0].drop_duplicates(["g", "id"]).set_index(["g", "id"]).v
    nb = np.stack([own.reindex(pd.MultiIndex.from_arrays([df.g, df.id + d])).to_numpy() for d in (-1, 1)])
    n = np.isfinite(nb).sum(axis=0)
    mean = np.where(n > 0, np.nansum(nb, axis=0) / np.maximum(n, 1), np.nan)  # the median of two
    return np.where(df.id.to_numpy() > 0, df.v.to_numpy() / mean, np.nan)
