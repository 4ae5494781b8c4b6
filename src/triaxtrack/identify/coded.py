"""Coded targets (CTs) as identification sees them: their centres and centre-dot ellipse maps in
undistorted pixels, the blobs on their labels, the CT stripes of the design, the decoded CTs
whose place in the image agrees with their ID, and the image direction of +theta at a CT."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from triaxtrack.detect import ellipse_maps
from triaxtrack.identify.grid import undistorted_jacobians
from triaxtrack.identify.state import _Frame
from triaxtrack.kit_design import CodedTargetDesign, CtStripe, KitDesign, PedestalStripe


def _ct_maps(f: _Frame, cts: pd.DataFrame, undistort) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """CT id -> (undistorted centre, centre-dot ellipse map in undistorted pixels)."""
    if cts.empty:
        return {}
    rows = cts.blob.to_numpy()
    maps = ellipse_maps(f.blobs.loc[rows])
    jac = undistorted_jacobians(undistort, f.blobs.loc[rows, ["u_px", "v_px"]].to_numpy())
    maps_u = np.einsum("nij,njk->nik", jac, maps)
    return {int(t): (f.pos[b], m) for t, b, m in zip(cts.id, rows, maps_u, strict=True)}


def _inside_cts(f: _Frame, cts: pd.DataFrame, ct_design: CodedTargetDesign) -> np.ndarray:
    """Blobs that belong to a CT (its centre dot, code sectors, or anything on its label)."""
    inside = np.zeros(len(f.blobs), bool)
    if cts.empty:
        return inside
    extent = ct_design.label_radius / ct_design.centre_radius
    maps = ellipse_maps(f.blobs.loc[cts.blob.to_numpy()])
    uv = f.blobs[["u_px", "v_px"]].to_numpy()
    tree = cKDTree(uv)
    for (cu, cv), m in zip(cts[["u_px", "v_px"]].to_numpy(), maps, strict=True):
        near = tree.query_ball_point((cu, cv), extent * np.linalg.norm(m, 2))
        if near:
            local = np.linalg.solve(m, (uv[near] - (cu, cv)).T).T
            inside[np.asarray(near)[np.linalg.norm(local, axis=1) < extent]] = True
    return inside


def _ct_stripes(design: KitDesign) -> dict[int, tuple[str, int, int]]:
    """CT id -> (stripe name, first id, count) for every CT stripe of the design."""
    out = {}
    stripes: tuple[PedestalStripe | CtStripe, ...] = (
        *design.pedestal_targets.stripes,
        *design.cell_targets.ct_stripes,
    )
    for st in stripes:
        for i in range(st.count):
            out[st.first_id + i] = (st.name, st.first_id, st.count)
    return out


# CTs of one stripe are linked as one run when their IDs differ by at most this many steps
# (a CT between them hidden or not decoded) and their images are at most this many label radii
# apart per step: along a stripe the CTs are 2.3-2.4 label radii apart (pedestal: 15.7 mm, cell
# wall: 16.1 mm, label radius 6.8 mm), closer when foreshortened
RUN_MAX_STEPS = 3
RUN_RADII_PER_STEP = 3.0


def _plausible_cts(cts: pd.DataFrame, design: KitDesign) -> pd.DataFrame:
    """Drop CTs whose place in the image contradicts their ID (a misread, partly hidden target
    decodes to a valid but far-away code). Among a CT's two nearest decoded CTs there must be
    one of its own stripe whose ID is at most two steps away; and a stripe's CTs seen in one
    image form one run (:data:`RUN_MAX_STEPS`, :data:`RUN_RADII_PER_STEP`): CTs outside the
    stripe's largest run are dropped, all of them when two runs are equally large (on a 720p
    test two cell-wall CTs beside a stripe's end read as pedestal CTs 1 and 2, each other's
    support), unless those equal runs lie along one band in ID order with gaps that hold their
    missing CTs (:func:`_on_one_ring`: a band whose middle is cut off by the image border)."""
    if len(cts) < 3:
        return cts
    stripes = _ct_stripes(design)
    uv = cts[["u_px", "v_px"]].to_numpy()
    ids = cts.id.to_numpy()
    _, near = cKDTree(uv).query(uv, k=3)
    keep = np.zeros(len(cts), bool)
    for a in range(len(cts)):
        name, first, count = stripes[int(ids[a])]
        for b in near[a, 1:]:
            nb, _, _ = stripes[int(ids[b])]
            steps = (int(ids[b]) - int(ids[a])) % count
            if nb == name and min(steps, count - steps) <= 2:
                keep[a] = True
    keep &= _in_main_run(ids, uv, cts.extent_px.to_numpy(float), stripes)
    keep &= _on_stripe_arc(ids, uv, cts.extent_px.to_numpy(float), stripes, keep)
    return cts[keep].reset_index(drop=True)


# A stripe's CTs lie on the image of one horizontal circle: a smooth arc v(u). A CT farther than
# ARC_MAX_RADII label radii from the parabola through its stripe's other kept CTs (ARC_MIN_OTHERS
# or more) is a misread (at a 420 mm ring, a CT read as the top pedestal's 1 next to its 2..7
# sat 3 label radii above their arc, between the pedestal and the cell's top band)
ARC_MAX_RADII = 1.5
ARC_MIN_OTHERS = 4


def _on_stripe_arc(
    ids: np.ndarray, uv: np.ndarray, extent: np.ndarray, stripes: dict, keep: np.ndarray
) -> np.ndarray:
    """Which CTs lie on the arc of their stripe's other kept CTs (:data:`ARC_MAX_RADII`), the
    farthest off dropped first, one at a time (True where too few others to tell)."""
    names = np.array([stripes[int(t)][0] for t in ids])
    out = np.ones(len(ids), bool)
    for name in np.unique(names[keep]):
        while True:
            sel = np.nonzero(keep & out & (names == name))[0]
            if len(sel) <= ARC_MIN_OTHERS:
                break
            off = np.array([_arc_offset(uv[sel[sel != a]], uv[a]) / extent[a] for a in sel])
            worst = int(np.argmax(off))
            if off[worst] <= ARC_MAX_RADII:
                break
            out[sel[worst]] = False
    return out


def _arc_offset(uv: np.ndarray, at: np.ndarray) -> float:
    """Height (pixels) of ``at`` off the parabola v(u) through the points ``uv``."""
    u0, span = uv[:, 0].mean(), max(float(np.ptp(uv[:, 0])), 1.0)
    coef = np.polyfit((uv[:, 0] - u0) / span, uv[:, 1], 2)
    return float(abs(at[1] - np.polyval(coef, (at[0] - u0) / span)))


def _in_main_run(ids: np.ndarray, uv: np.ndarray, extent: np.ndarray, stripes: dict) -> np.ndarray:
    """Which CTs belong to the largest run of their stripe (see :func:`_plausible_cts`)."""
    from scipy.sparse.csgraph import connected_components

    names = np.array([stripes[int(t)][0] for t in ids])
    count = np.array([stripes[int(t)][2] for t in ids])
    steps = np.abs(ids[:, None] - ids[None, :]) % count[:, None]
    steps = np.minimum(steps, count[:, None] - steps)
    dist = np.linalg.norm(uv[:, None] - uv[None, :], axis=2)
    reach = RUN_RADII_PER_STEP * np.maximum(extent[:, None], extent[None, :]) * steps
    linked = (names[:, None] == names[None, :]) & (steps <= RUN_MAX_STEPS) & (dist <= reach)
    _, run = connected_components(linked, directed=False)
    size = np.bincount(run)[run]
    out = np.zeros(len(ids), bool)
    for name in np.unique(names):
        sel = np.nonzero(names == name)[0]
        largest = size[sel].max()
        runs = np.unique(run[sel][size[sel] == largest])
        tied = sel[np.isin(run[sel], runs)]
        if len(runs) == 1:
            out[sel] = run[sel] == runs[0]
        elif largest >= 2 and _on_one_ring(ids[tied], uv[tied], extent[tied], int(count[sel][0]), run[tied]):
            out[tied] = True  # equal runs along one band: its middle cut off or hidden
    return out


# Equally large runs of one stripe are taken as pieces of one band whose middle is cut off by the
# image border (or hidden) when they lie at one height, within this many label radii (a CT of
# another stripe is 15 mm, over two label radii, higher or lower), their IDs run one way across
# the image over less than half a turn, and the gaps between them hold their missing CTs: per ID
# step, RING_GAP_RANGE times the runs' own spacing (wider where the band faces the camera)
RING_MAX_HEIGHT_RADII = 1.5
RING_GAP_RANGE = (0.5, 3.0)


def _on_one_ring(ids: np.ndarray, uv: np.ndarray, extent: np.ndarray, count: int, run: np.ndarray) -> bool:
    """Do one stripe's equally large runs of CTs (``ids`` of a stripe of ``count``, image
    centres ``uv``, label radii ``extent``, pixels; ``run`` labels) lie along one band in ID
    order (:data:`RING_MAX_HEIGHT_RADII`, :data:`RING_GAP_RANGE`)?"""
    if np.ptp(uv[:, 1]) > RING_MAX_HEIGHT_RADII * float(np.median(extent)):
        return False
    order = np.argsort(uv[:, 0])
    steps = np.diff(ids[order]) % count  # cyclic steps from left to right
    steps = np.where((steps > count / 2).all(), count - steps, steps)  # IDs may run right to left
    if not (0 < steps).all() or steps.sum() >= count / 2:
        return False
    per_step = np.diff(uv[order, 0]) / steps
    inside = run[order][1:] == run[order][:-1]
    if not inside.any() or inside.all():
        return False
    spacing = float(np.median(per_step[inside]))
    lo, hi = RING_GAP_RANGE
    return bool(((per_step[~inside] >= lo * spacing) & (per_step[~inside] <= hi * spacing)).all())


def _theta_dir(ct_id: int, first: int, count: int, centres: dict) -> np.ndarray | None:
    """Image direction of +theta at a CT, from its decoded neighbours in the same stripe."""
    nxt = first + (ct_id - first + 1) % count
    prv = first + (ct_id - first - 1) % count
    if nxt in centres and prv in centres:
        d = centres[nxt][0] - centres[prv][0]
    elif nxt in centres:
        d = centres[nxt][0] - centres[ct_id][0]
    elif prv in centres:
        d = centres[ct_id][0] - centres[prv][0]
    else:
        return None
    return d / np.linalg.norm(d)
