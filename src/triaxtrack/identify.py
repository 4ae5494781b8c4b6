"""Identification: give every detected dot its design ID, or leave it unlabelled with a reason.

The paper's section 2.3, second half, against the kit design (``triaxtrack.kit``). All geometry
is done in undistorted pixels (ideal pinhole pixels of the calibrated camera matrix), where a
straight line in space stays straight.

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
* **Membrane.** From each pedestal CT pair (top CT C, bottom CT C + 16) a seed dot near the
  pair's line starts a 2-D walk of the grid: each next dot is predicted from its labelled grid
  neighbours (straight continuation and parallelograms) and accepted only when exactly one
  detected dot lies within the gate. The larger dots (every fourth row and column, Eqs. 2-3)
  give the grid's phase by their area; the pair's line gives the column of C's larger dots,
  c = (C - 1) * 4 + 1, and the pair's CTs, ``z_from_face`` above and below the membrane's end rows,
  give the row. ID = (r - 1) * 64 + c + 1000 (Eq. 4).

Every step accepts a dot only when it is the single candidate within its gate (a fraction of
the local dot spacing) and not claimed twice; the larger dots must be larger. A region, stripe
or grid that fails a check is left unlabelled (``reason``), never guessed.

Two membrane dots whose images merged into one blob (at high strain and low resolution) are
labelled once the grid around them is: between their labelled neighbours along a column or a
row, the blob is fitted with two Gaussians (:func:`~triaxtrack.detect.merged_pair_centroids`)
and each dot gets its own row at its fitted centre, with ``quality`` ``MERGED_QUALITY``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from triaxtrack.detect import ellipse_maps, gap_background_centroids, merged_pair_centroids
from triaxtrack.kit import eq1_dot_id

UNLABELLED = -1
NOT_REACHED = "not reached from any coded target"  # the reason of a dot nothing labelled
# a membrane dot beside a dark edge this much less round than its grid neighbours (seen at the
# same angle) has merged with the edge's fringe: on the demo one at 0.52 was 1.4 px off; 0.45 %
# of all labelled membrane dots on four tests fall below it, beside an edge or not
MERGED_ROUNDNESS_RATIO = 0.55
# an end-row membrane dot beside a pedestal's edge and a gap in its row this much larger than its
# grid neighbours has merged with the edge: of 869 on four tests, 99 % were under 1.33 and at
# most 0.39 px off; the largest (1.8) was 0.93 px off
MERGED_AREA_RATIO = 1.5
FAR_PX = 1e9
# a membrane dot whose image comes within this of a longitudinal band's (beyond its moment
# ellipse, where its blurred edge still darkens pixels) may be partly hidden: not labelled. At
# 0.5 px the dots kept beside a band were as accurate as the rest on four tests (membrane p99.9
# and maximum error unchanged); 1.0 px left 80-175 more a test unlabelled
BAND_BLUR_PX = 0.5
BLUR_REACH = 2.0  # a blurred edge darkens pixels this many lens-blur sigmas beyond it
GAP_ACROSS_PX = 1.0  # a re-centred dot's window reaches this far across beyond its moment ellipse
# two membrane dots merged in one blob (at 10 % strain, 720p) and fitted apart: on the one test
# of four with them, 228 dots were 0.11 px off at the median and 0.30 px at worst, so they are
# reported with a lower quality
MERGED_HEIGHT_RATIO = 2.0  # the two fitted Gaussians' heights agree within this factor
MERGED_FIT_RMS = 0.25  # residual RMS of the fit over the blob's largest contrast, at most
MERGED_QUALITY = 0.5


@dataclass(frozen=True)
class IdentifyParams:
    """Gates, as fractions of the local dot spacing, and the checks' limits."""

    gate: float = 0.3  # a predicted dot must be within this fraction of the local spacing
    anchor_gate: float = 0.35  # the Eq. 1 and stripe-end predictions (over 9-16 mm from a CT)
    large_area_ratio: float = 1.15  # a larger dot's area over its neighbours', at least
    phase_margin: float = 0.12  # log-area margin of the large-dot phase over the next best
    min_region_dots: int = 12  # a membrane grid region smaller than this is left unlabelled
    row_tolerance: float = 1.2  # |row estimated from a pedestal CT - row assigned|, rows
    # smaller or more oblique dots are detected but not labelled, where their centroid is not
    # accurate. A dot beside a dark edge (the dark beyond a band's or a label's edge, towards a
    # silhouette) takes in the edge's blurred fringe: oblique 6-7 px stripe dots at 720p were
    # 0.15-0.27 px off, so cell-wall dots there need a larger, rounder image; a longitudinal
    # stripe's dots re-centred against the background in its gaps (see identify) were 0.05-0.06 px
    # at the 95th percentile on four tests, and count as clear of the edge. Clear of an edge, dots
    # down to 4 px were within 0.1 px at the 95th percentile on four tests, membrane dots at
    # any roundness, cell-wall dots down to 0.3; but a cell-wall dot on the sliver of a ring's
    # label at the cell's silhouette (roundness 0.32-0.38, its edge not flagged) was 0.4-1.0 px
    # off, so those stop at 0.4
    min_cell_area_px: float = 8.0  # beside an edge
    min_cell_roundness: float = 0.5  # beside an edge
    min_clear_cell_area_px: float = 4.0
    min_clear_cell_roundness: float = 0.4
    # a longitudinal stripe's dot re-centred (see identify): down to 0.2, all were within 0.1 px
    min_recentred_roundness: float = 0.2
    min_membrane_area_px: float = 4.0
    min_membrane_roundness: float = 0.2


def undistorted_jacobians(undistort, uv: np.ndarray, h: float = 0.5) -> np.ndarray:
    """(N, 2, 2) d(undistorted)/d(distorted) at pixel positions, by central differences."""
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    cols = []
    for e in (np.array([h, 0.0]), np.array([0.0, h])):
        cols.append((undistort(uv + e) - undistort(uv - e)) / (2 * h))
    return np.stack(cols, axis=2)


def ellipse_radius(maps: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Radius of each ellipse (maps: unit circle -> ellipse) along unit directions ``dirs``."""
    inv = np.linalg.inv(maps)
    return 1.0 / np.linalg.norm(np.einsum("nij,nj->ni", inv, dirs), axis=1)


def local_affine(map_u: np.ndarray, theta_dir: np.ndarray, radius_mm: float) -> np.ndarray:
    """(2, 2) map from design millimetres (theta-arc to the right, z up, seen from outside) to
    undistorted pixel offsets, at a CT whose centre dot (radius ``radius_mm``) images as the
    ellipse ``map_u`` and whose +theta direction in the image is ``theta_dir``.

    Seen from outside, (theta, z) -> (u, v) reverses orientation (z up, v down), so the map is
    ``map_u / r . Rot(a) . diag(1, -1)`` with ``a`` such that +theta points along ``theta_dir``.
    """
    x = np.linalg.solve(map_u, theta_dir)
    a = np.arctan2(x[1], x[0])
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    return map_u / radius_mm @ rot @ np.diag([1.0, -1.0])


class _Pool:
    """The free candidate dots, with a KD-tree for gated nearest-point search."""

    def __init__(self, pos: np.ndarray, free: np.ndarray, blobs: pd.DataFrame):
        self.pos = pos
        self.free = free.copy()
        self.area = blobs.area_px.to_numpy()
        self.white = blobs.background.to_numpy()
        self.roundness = blobs.roundness.to_numpy()
        self.tree = cKDTree(pos)

    def unique_within(self, pred: np.ndarray, radius: float) -> int:
        """Index of the single free dot within ``radius`` of ``pred``; -1 if none or several.

        Taken dots count as candidates too (a prediction that lands on a labelled dot is
        ambiguous, not a licence to take the next nearest).
        """
        if not np.all(np.isfinite(pred)) or radius <= 0:
            return -1
        hits = self.tree.query_ball_point(pred, radius)
        if len(hits) != 1 or not self.free[hits[0]]:
            return -1
        return int(hits[0])


def grow_chain(
    pool: _Pool,
    labels: dict[int, int],
    n: int,
    cyclic: bool,
    gate: float,
    step_hint: dict[int, np.ndarray] | None = None,
    max_bracket: int = 4,
) -> dict[int, int]:
    """Extend a 1-D stripe labelling (index -> dot) by interpolation and stepwise extrapolation.

    A missing dot stops the walk (the next prediction falls between dots, outside the gate), so a
    gap is never skipped and the IDs beyond it cannot shift. ``step_hint[i]``: the image step from
    index i to i + 1, used when i has no labelled neighbour to extrapolate from.
    """
    labels = dict(labels)
    hint = step_hint or {}
    pos = pool.pos

    def key(i):
        return i % n if cyclic else i

    def has(i):
        return (cyclic or 0 <= i < n) and key(i) in labels

    def p(i):
        return pos[labels[key(i)]]

    while True:
        proposals: dict[int, int] = {}
        for i in range(n):
            if i in labels:
                continue
            pred = spacing = None
            lo = next((j for j in range(i - 1, i - max_bracket, -1) if has(j)), None)
            hi = next((k for k in range(i + 1, i + max_bracket) if has(k)), None)
            if lo is not None and hi is not None:
                f = (i - lo) / (hi - lo)
                pred = p(lo) + f * (p(hi) - p(lo))
                spacing = np.linalg.norm(p(hi) - p(lo)) / (hi - lo)
            else:
                for s in (1, -1):
                    a = i - s
                    if not has(a):
                        continue
                    if has(a - s):
                        d = p(a) - p(a - s)
                        if has(a - 2 * s):
                            pred = p(a) + d + (d - (p(a - s) - p(a - 2 * s)))
                        else:
                            pred = p(a) + d
                        spacing = np.linalg.norm(d)
                    elif (s == 1 and key(a) in hint) or (s == -1 and key(i) in hint):
                        d = hint[key(a)] if s == 1 else -hint[key(i)]
                        pred, spacing = p(a) + d, np.linalg.norm(d)
                    if pred is not None:
                        break
            if pred is None:
                continue
            j = pool.unique_within(pred, gate * spacing)
            if j >= 0:
                if j in proposals.values():  # two indices want one dot: neither gets it
                    proposals = {k: v for k, v in proposals.items() if v != j}
                    continue
                proposals[i] = j
        if not proposals:
            return labels
        for i, j in proposals.items():
            labels[i] = j
            pool.free[j] = False


NEIGHBOURS = ((1, 0), (-1, 0), (0, 1), (0, -1))
MIN_SUPPORT = 3  # labelled nodes among the 8 around a node before it is predicted
AREA_RANGE = (0.45, 1.85)  # a grid dot's area over its labelled neighbours' median
WHITE_TOLERANCE = 0.08  # a grid dot's local white level may differ this much from its neighbours'


def grow_grid(pool: _Pool, seed: dict[tuple[int, int], int], gate: float) -> dict[tuple[int, int], int]:
    """Extend a 2-D grid labelling ((row, col) -> dot) from its labelled neighbours.

    A node is predicted by every straight continuation (two labelled nodes in a line) and every
    parallelogram (three labelled corners); the predictions must agree within the gate, and
    exactly one free dot may lie within ``gate`` times the local spacing of their median (the
    spacing along the lines and, where measured, across them). A node needs ``MIN_SUPPORT``
    labelled nodes among its eight neighbours, or one fewer when one of them continues a straight
    line and the other, beside it, gives the spacing across that line: that carries a strip a few
    columns wide past a dot missing from its edge column (towards a silhouette, beyond a band).
    """
    labels = dict(seed)
    pos = pool.pos
    frontier = {(i + di, j + dj) for (i, j) in labels for di, dj in NEIGHBOURS} - set(labels)
    while frontier:
        proposals: dict[tuple[int, int], int] = {}
        claimed: dict[int, tuple[int, int]] = {}
        for i, j in frontier:
            support = sum((i + di, j + dj) in labels for di in (-1, 0, 1) for dj in (-1, 0, 1))
            if support < MIN_SUPPORT - 1:
                continue  # never grow a spur: a node needs two labelled neighbours at least
            preds, steps = [], []
            across = False  # a straight continuation whose spacing across was measured
            for di, dj in NEIGHBOURS:
                a, b = (i + di, j + dj), (i + 2 * di, j + 2 * dj)
                if a in labels:
                    if b in labels:
                        d = pos[labels[a]] - pos[labels[b]]
                        preds.append(pos[labels[a]] + d)
                        steps.append(np.linalg.norm(d))
                        for e in ((a[0] + dj, a[1] + di), (a[0] - dj, a[1] - di)):
                            if e in labels:  # the spacing across the line, which bounds the gate
                                across = True
                                steps.append(np.linalg.norm(pos[labels[e]] - pos[labels[a]]))
                    c = (i - di, j - dj)
                    if c in labels and di >= 0 and dj >= 0:
                        preds.append(0.5 * (pos[labels[a]] + pos[labels[c]]))
                        steps.append(0.5 * np.linalg.norm(pos[labels[a]] - pos[labels[c]]))
            for di in (1, -1):
                for dj in (1, -1):
                    a, b, c = (i + di, j), (i, j + dj), (i + di, j + dj)
                    if a in labels and b in labels and c in labels:
                        preds.append(pos[labels[a]] + pos[labels[b]] - pos[labels[c]])
                        steps.append(
                            min(
                                np.linalg.norm(pos[labels[a]] - pos[labels[c]]),
                                np.linalg.norm(pos[labels[b]] - pos[labels[c]]),
                            )
                        )
            if not preds or (support < MIN_SUPPORT and not across):
                continue
            preds = np.asarray(preds)
            pred = np.median(preds, axis=0)
            radius = gate * min(steps)
            if np.max(np.linalg.norm(preds - pred, axis=1)) > radius:
                continue
            k = pool.unique_within(pred, radius)
            if k < 0:
                continue
            nb = [labels[(i + di, j + dj)] for di, dj in NEIGHBOURS if (i + di, j + dj) in labels]
            if not AREA_RANGE[0] <= pool.area[k] / np.median(pool.area[nb]) <= AREA_RANGE[1]:
                continue  # not a dot of this grid (a fragment of an edge, a merged pair, ...)
            if abs(pool.white[k] / np.median(pool.white[nb]) - 1) > WHITE_TOLERANCE:
                continue  # printed on another surface (a longitudinal band in front, ...)
            if k in claimed:
                proposals.pop(claimed[k], None)
                continue
            claimed[k] = (i, j)
            proposals[(i, j)] = k
        if not proposals:
            break
        for node, k in proposals.items():
            labels[node] = k
            pool.free[k] = False
        # a node becomes predictable when a node up to two steps away is labelled
        frontier = {
            (i + di, j + dj) for (i, j) in proposals for di in range(-2, 3) for dj in range(-2, 3)
        } - set(labels)
    return labels


LABEL_COLUMNS = [
    "id", "kind", "group", "u_px", "v_px", "u_undist_px", "v_undist_px", "area_px", "roundness",
    "quality", "reason",
]  # fmt: skip


@dataclass
class _Frame:
    """Working state of one frame's identification."""

    blobs: pd.DataFrame
    pos: np.ndarray  # undistorted centroids of all blobs
    ids: np.ndarray  # per blob, UNLABELLED until labelled
    group: np.ndarray  # per blob, stripe or region name
    quality: np.ndarray
    reason: np.ndarray


def _ct_maps(f: _Frame, cts: pd.DataFrame, undistort) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """CT id -> (undistorted centre, centre-dot ellipse map in undistorted pixels)."""
    if cts.empty:
        return {}
    rows = cts.blob.to_numpy()
    maps = ellipse_maps(f.blobs.loc[rows])
    jac = undistorted_jacobians(undistort, f.blobs.loc[rows, ["u_px", "v_px"]].to_numpy())
    maps_u = np.einsum("nij,njk->nik", jac, maps)
    return {int(t): (f.pos[b], m) for t, b, m in zip(cts.id, rows, maps_u, strict=True)}


def _inside_cts(f: _Frame, cts: pd.DataFrame, ct_design: dict) -> np.ndarray:
    """Blobs that belong to a CT (its centre dot, code sectors, or anything on its label)."""
    inside = np.zeros(len(f.blobs), bool)
    if cts.empty:
        return inside
    extent = ct_design.get("label_radius", ct_design["ring_outer_radius"] + 1.2) / ct_design["centre_radius"]
    maps = ellipse_maps(f.blobs.loc[cts.blob.to_numpy()])
    uv = f.blobs[["u_px", "v_px"]].to_numpy()
    tree = cKDTree(uv)
    for (cu, cv), m in zip(cts[["u_px", "v_px"]].to_numpy(), maps, strict=True):
        near = tree.query_ball_point((cu, cv), extent * np.linalg.norm(m, 2))
        if near:
            local = np.linalg.solve(m, (uv[near] - (cu, cv)).T).T
            inside[np.asarray(near)[np.linalg.norm(local, axis=1) < extent]] = True
    return inside


def _ct_stripes(design: dict) -> dict[int, tuple[str, int, int]]:
    """CT id -> (stripe name, first id, count) for every CT stripe of the design."""
    out = {}
    stripes = design["pedestal_targets"]["stripes"] + design["cell_targets"]["ct_stripes"]
    for st in stripes:
        for i in range(st["count"]):
            out[st["first_id"] + i] = (st["name"], st["first_id"], st["count"])
    return out


def _plausible_cts(cts: pd.DataFrame, design: dict) -> pd.DataFrame:
    """Drop CTs whose place in the image contradicts their ID: among a CT's two nearest decoded
    CTs there must be one of its own stripe whose ID is at most two steps away (a misread
    partly hidden target decodes to a valid but far-away code)."""
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
    return cts[keep].reset_index(drop=True)


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


def _assign(f: _Frame, blob: int, tid: int, group: str, quality: float) -> None:
    f.ids[blob] = tid
    f.group[blob] = group
    f.quality[blob] = quality
    f.reason[blob] = ""


def _label_cell_stripes(f: _Frame, pool: _Pool, centres: dict, design: dict, p: IdentifyParams) -> None:
    cell = design["cell_targets"]
    per, offset = cell["dots_per_ct"], cell["dot_offset"]
    rc = design["coded_target"]["centre_radius"]
    r_out = design["cell"]["outer_radius"]
    ct_stripes = {s["name"]: s for s in cell["ct_stripes"]}
    area = f.blobs.area_px.to_numpy()
    for ds in cell["dot_stripes"]:
        cs = ct_stripes[ds["ct_stripe"]]
        n = ds["count"]
        spacing_mm = 2 * np.pi * r_out / n
        anchors, hints = {}, {}
        for c in range(cs["first_id"], cs["first_id"] + cs["count"]):
            if c not in centres:
                continue
            d = _theta_dir(c, cs["first_id"], cs["count"], centres)
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
            i = per * (c - cs["first_id"])
            anchors[i] = k
            hints[i] = step  # to i + 1, and (evenly spaced) into i from i - 1
            hints.setdefault((i - 1) % n, step)
            pool.free[k] = False
        labels = grow_chain(pool, anchors, n, cyclic=True, gate=p.gate, step_hint=hints)
        for i, k in labels.items():
            _assign(f, k, ds["first_id"] + i, ds["name"], 1.0 if i in anchors else 0.9)


def _label_longitudinal(f: _Frame, pool: _Pool, centres: dict, design: dict, p: IdentifyParams) -> None:
    cell = design["cell_targets"]
    offset = cell["dot_offset"]
    zt, zb = cell["longitudinal_z_top"], cell["longitudinal_z_bottom"]
    labelled = {int(t): k for k, t in enumerate(f.ids) if t != UNLABELLED}
    top, bottom = cell["ct_stripes"][0], cell["ct_stripes"][-1]
    for ls in cell["longitudinal_stripes"]:
        n = ls["count"]
        spacing_mm = (zt - zb) / (n - 1)
        anchors, hints = {}, {}
        ct_top = ls["ct"]
        ct_bottom = ct_top - top["first_id"] + bottom["first_id"]
        for ct_id, ct_z, index, z in (
            (ct_top, top["z"], 0, zt),
            (ct_bottom, bottom["z"], n - 1, zb),
        ):
            dot = labelled.get(eq1_dot_id(ct_id, design))
            if dot is None:
                continue
            if ct_id in centres:
                down = (f.pos[dot] - centres[ct_id][0]) / offset  # pixels per mm down the cell
            else:  # a CT seen too obliquely to decode: the direction down from its neighbour's
                down = _neighbour_down(f, ct_id, centres, labelled, design)
                if down is None:
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
        labels = grow_chain(pool, anchors, n, cyclic=False, gate=p.gate, step_hint=hints, max_bracket=2)
        for i, k in labels.items():
            _assign(f, k, ls["first_id"] + i, ls["name"], 1.0 if i in anchors else 0.9)


def _neighbour_down(f: _Frame, ct_id: int, centres: dict, labelled: dict, design: dict) -> np.ndarray | None:
    """Pixels per mm down the cell at CT ``ct_id`` (not decoded) from the nearest decoded CT of
    its stripe (one or two places along, the nearer first) whose Eq. 1 dot is labelled."""
    stripe = next(s for s in design["cell_targets"]["ct_stripes"] if 0 <= ct_id - s["first_id"] < s["count"])
    for step in (1, -1, 2, -2):
        nb = stripe["first_id"] + (ct_id - stripe["first_id"] + step) % stripe["count"]
        dot = labelled.get(eq1_dot_id(nb, design))
        if nb in centres and dot is not None:
            return (f.pos[dot] - centres[nb][0]) / design["cell_targets"]["dot_offset"]
    return None


def _hide_behind_band(f: _Frame, pool: _Pool, order: np.ndarray, pad: np.ndarray, design: dict) -> None:
    """Take out of the pool (reason given) the free dots whose image reaches the white band of
    a longitudinal stripe whose dots, in order along it, are ``order`` (blob indices): within
    half the band's width of the line through them plus ``pad`` (per blob, pixels)."""
    line = f.pos[order]
    # pixels per mm across the band at each stripe dot: its minor axis (the band is
    # foreshortened across, towards a silhouette, never along)
    across = f.blobs.minor_px.to_numpy()[order] / design["cell_targets"]["longitudinal_dot_diameter"]
    half = design["cell_targets"]["longitudinal_band_width"] / 2
    radius = half * np.maximum(across[:-1], across[1:])
    hide = _near_polyline(f.pos, line, radius, pad) & pool.free
    pool.free[hide] = False
    f.reason[hide] = "on a longitudinal stripe's band"


MIN_CHAIN_DOTS = 8  # a straight line of at least this many dots on another surface is a stripe
CHAIN_LINE_PX = 1.0  # ... within this of a straight line (undistorted pixels: a generatrix of the
# cell images straight)
CHAIN_AXIS_DEG = 15.0  # a stripe runs along the specimen's axis (tilted cameras, distortion)


def _straight_chains(pos: np.ndarray, cand: np.ndarray, axis: np.ndarray) -> list[np.ndarray]:
    """Longitudinal stripes among the blobs ``cand`` (indices; ``pos`` undistorted pixels): each
    a straight line of at least ``MIN_CHAIN_DOTS`` of them (RANSAC) along the specimen's axis
    (``axis``: its image direction, within ``CHAIN_AXIS_DEG``), its blobs in order along it."""
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
        out.append(members[np.argsort(along)])
    return out


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


def _seed_grid(
    pool: _Pool, start: int, down: np.ndarray, gate: float, narrow: bool = False
) -> dict[tuple[int, int], int] | None:
    """A 3 x 3 grid seed around a dot (or, ``narrow``, 3 x 2 to its right): its neighbours
    below and in +theta fix the two grid steps, and every node of the block must be the single
    dot within the gate of its prediction."""
    right = np.array([down[1], -down[0]])  # seen from outside, +theta is `down` turned this way
    d, idx = pool.tree.query(pool.pos[start], k=9)
    steps = []
    for axis in (down, right):
        best = None
        for dist, j in zip(d[1:], idx[1:], strict=True):
            if not np.isfinite(dist) or j >= len(pool.pos) or not pool.free[j]:
                continue
            if (pool.pos[j] - pool.pos[start]) @ axis > dist * np.cos(np.radians(25)):
                best = j
                break
        if best is None:
            return None
        steps.append(pool.pos[best] - pool.pos[start])
    radius = gate * min(np.linalg.norm(steps[0]), np.linalg.norm(steps[1]))
    node = {
        (i, j): pool.unique_within(pool.pos[start] + i * steps[0] + j * steps[1], radius)
        for i in (-1, 0, 1)
        for j in (-1, 0, 1)
    }
    # the 3 x 3 block, or (``narrow``) where the column on the start's left is missing (a strip
    # two columns wide, beyond a band and towards a silhouette) the 3 x 2 block on its right: every
    # free dot is tried as a start, so a strip's left column is among them
    for cols in ((-1, 0, 1), (0, 1)) if narrow else ((-1, 0, 1),):
        seed = {(i, j): node[(i, j)] for i in (-1, 0, 1) for j in cols}
        if min(seed.values()) >= 0:
            return seed
    return None


def _grid_phase(grid: dict, area: np.ndarray, p: IdentifyParams) -> tuple[int, int] | None:
    """(row, col) residues mod 4 of the larger dots, from each dot's area over its neighbours'."""
    la = {node: np.log(area[k]) for node, k in grid.items()}
    sums = np.zeros((4, 4))
    counts = np.zeros((4, 4))
    for (i, j), v in la.items():
        # only opposite neighbours in pairs: the dots' size changes across the image (towards a
        # silhouette, along the axis) and a pair's mean cancels that change to first order
        nb = [
            0.5 * (la[(i - di, j - dj)] + la[(i + di, j + dj)])
            for di, dj in ((1, 0), (0, 1))
            if (i - di, j - dj) in la and (i + di, j + dj) in la
        ]
        if nb:
            sums[i % 4, j % 4] += v - np.mean(nb)
            counts[i % 4, j % 4] += 1
    mean = np.where(counts > 0, sums / np.maximum(counts, 1), -np.inf)
    order = np.argsort(mean.ravel())[::-1]
    best, second = mean.ravel()[order[0]], mean.ravel()[order[1]]
    if counts.ravel()[order[0]] < 3 or best - second < p.phase_margin:
        return None
    return int(order[0] // 4), int(order[0] % 4)


@dataclass(frozen=True)
class _Anchor:
    """A pedestal CT pair, or a single pedestal CT, that fixes the membrane columns under it."""

    C: int  # the pair's column number (the top CT's ID offset + 1): c = (C - 1) * 4 + 1
    top: tuple[np.ndarray, np.ndarray] | None  # (centre, ellipse map) of the top CT
    bottom: tuple[np.ndarray, np.ndarray] | None


def _pedestal_anchors(centres: dict, design: dict) -> list[_Anchor]:
    """Pairs first (the paper's method), then single CTs whose partner was not decoded."""
    ped = {s["surface"]: s for s in design["pedestal_targets"]["stripes"]}
    top, bottom = ped["pedestal_top"], ped["pedestal_bottom"]
    anchors = []
    for k in range(top["count"]):
        a, b = centres.get(top["first_id"] + k), centres.get(bottom["first_id"] + k)
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


@dataclass(frozen=True)
class _MembraneView:
    """What the membrane labelling knows of the view: where the specimen's axis images, how
    round a pedestal CT seen head-on looks, and the design's parallax numbers."""

    axis_point: np.ndarray
    q_max: float  # largest (width across / height along the axis) of the pedestal CTs' centre dots
    proud_mm: float  # pedestal radius - membrane outer radius
    column_mm: float  # membrane column pitch on its outer surface

    @staticmethod
    def of(regions, anchors, axis, pos, design) -> _MembraneView:
        nodes = [k for g in regions for k in g.values()]
        q = [_width_ratio(e[1], axis) for a in anchors for e in (a.top, a.bottom) if e is not None]
        r_m = design["specimen"]["diameter"] / 2 + design["specimen"]["membrane_thickness"]
        return _MembraneView(
            axis_point=np.median(pos[nodes], axis=0) if nodes else np.zeros(2),
            q_max=max(q) if q else 1.0,
            proud_mm=design["pedestal"]["radius"] - r_m,
            column_mm=2 * np.pi * r_m / design["membrane"]["columns"],
        )


def _grow_region(pool: _Pool, start: int, down: np.ndarray, gate: float, narrow: bool = False) -> list[dict]:
    """The grid region grown from a free dot (taking its dots from the pool), or none."""
    if not pool.free[start]:
        return []
    seed = _seed_grid(pool, start, down, gate, narrow)
    if seed is None:
        return []
    pool.free[list(seed.values())] = False
    return [grow_grid(pool, seed, gate)]


def _label_membrane(f: _Frame, pool: _Pool, centres: dict, design: dict, p: IdentifyParams) -> None:
    rc = design["coded_target"]["centre_radius"]
    anchors = _pedestal_anchors(centres, design)
    axis = _axis_down(anchors)
    area = f.blobs.area_px.to_numpy()
    regions = []
    z_from_face = design["pedestal_targets"]["stripes"][0]["z_from_face"]
    for an in anchors:
        if an.top is not None and an.bottom is not None:
            down = an.bottom[0] - an.top[0]
            down /= np.linalg.norm(down)
            start_at = 0.5 * (an.top[0] + an.bottom[0])
        else:
            centre, mp = an.top or an.bottom
            sign = 1.0 if an.top is not None else -1.0
            down = axis
            # a point on the membrane a quarter of its height from the CT's pedestal face
            depth_mm = design["specimen"]["height"] / 4 + z_from_face
            start_at = centre + sign * down * depth_mm * ellipse_radius(mp[None], down[None])[0] / rc
        _, start = pool.tree.query(start_at)
        regions += _grow_region(pool, int(start), down, p.gate)
    # then the dots no pedestal CT led to (beyond a longitudinal stripe's band): their regions
    # are fixed across the band below. Strips two columns wide are seeded last, from what the
    # wider regions left
    tops = [a.top[0] @ axis for a in anchors if a.top is not None]
    bottoms = [a.bottom[0] @ axis for a in anchors if a.bottom is not None]
    if tops and bottoms:
        s = f.pos @ axis
        for narrow in (False, True):
            for k in np.nonzero(pool.free & (s > np.mean(tops)) & (s < np.mean(bottoms)))[0]:
                regions += _grow_region(pool, int(k), axis, p.gate, narrow)
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
        ids = _grid_ids(grid, *fixed[ri], design["membrane"])
        for node, k in grid.items():
            if node in ids:
                _assign(f, k, ids[node], name, 0.9)
            else:
                f.reason[k] = "beyond the membrane's rows"


def _bridge(grid, phase, other, other_off, pos, axis, design) -> tuple[int, int] | None:
    """(column offset, row offset) of ``grid`` from a fixed neighbouring region ``other``.

    Rows are matched along the specimen's axis between the two regions' facing columns; the
    number of columns hidden between them is estimated from the gap and the columns' spacing,
    and must be the one value within 1.5 columns of that estimate that puts this region's
    larger dots on the design's larger columns and rows.
    """
    m = design["membrane"]
    step, first = m["large_step"], m["large_first"]
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
    ja = min(a_col) if side > 0 else max(a_col)
    jb = max(b_col) if side > 0 else min(b_col)
    ja2, jb2 = ja + int(side), jb - int(side)  # one column further in, to measure the spacing
    if ja2 not in a_col or jb2 not in b_col:
        return None
    # each row's facing dot and its slope there (from the next column in), extrapolated to the
    # middle of the gap from both sides: a row images as an arc, and extrapolating its tangent
    # by the same distance from either side cancels the arc's curvature
    mid = 0.5 * (a_col[ja] + b_col[jb])
    ends_a = _row_ends(grid, pos, ja, ja2, axis, right, mid)
    ends_b = _row_ends(other, pos, jb, jb2, axis, right, mid)
    if len(ends_a) < 5 or len(ends_b) < 5:
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
    if len(shifts) < 5:
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
        n for n in range(1, int(n_est) + 3)
        if abs(n - n_est) < 1.5 and (pj + c_b + side * n - ja - first) % step == 0
    ]  # fmt: skip
    if len(fits) != 1:
        return None
    c_off = int((c_b + side * fits[0] - ja) % m["columns"])
    return c_off, r_off


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


def _grid_ids(grid: dict, c_off: int, r_off: int, m: dict) -> dict:
    """Node -> membrane ID (Eq. 4) for a region with known offsets; nodes beyond the rows left out."""
    out = {}
    for i, j in grid:
        r, c = i + r_off, (j + c_off - 1) % m["columns"] + 1
        if 1 <= r <= m["rows"]:  # beyond: not a membrane dot (a pedestal edge fragment, ...)
            out[(i, j)] = (r - 1) * m["columns"] + c + m["first_id"] - 1
    return out


def _grid_steps(grid: dict, pos: np.ndarray, nodes: list, di: int, dj: int) -> np.ndarray:
    """Image steps from the given nodes to their (di, dj) neighbours, where labelled."""
    return np.array(
        [pos[grid[(i + di, j + dj)]] - pos[grid[(i, j)]] for i, j in nodes if (i + di, j + dj) in grid]
    )


def _anchor_offsets(an: _Anchor, grid, nodes, xy, phase, pos, design, p, ctx) -> tuple[int, int] | None:
    """(column offset, row offset) of a grid region from one anchor; None when it cannot tell."""
    m = design["membrane"]
    rc = design["coded_target"]["centre_radius"]
    z_from_face = design["pedestal_targets"]["stripes"][0]["z_from_face"]
    step, first = m["large_step"], m["large_first"]
    pi, pj = phase
    ends = [e for e in (an.top, an.bottom) if e is not None]
    p0 = ends[0][0]
    if len(ends) == 2:
        down = an.bottom[0] - an.top[0]
        down /= np.linalg.norm(down)
    else:
        near = np.argsort(np.linalg.norm(xy - p0, axis=1))[:30]
        steps = _grid_steps(grid, pos, [tuple(nodes[k]) for k in near], 1, 0)
        if len(steps) < 3:
            return None
        down = np.median(steps, axis=0)
        down /= np.linalg.norm(down)
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
    sel = np.nonzero(nodes[:, 1] == jc)[0]
    if abs(cols[jc]) > 1.5 * col_px:
        return None  # the anchor's column is not in this region
    if len(ranked) > 1 and abs(cols[ranked[1]]) < 2 * abs(cols[jc]):
        return None  # seen too obliquely to tell its column
    c_off = step * (an.C - 1) + first - jc
    # rows: the membrane's end row lies half a row pitch from the pedestal face, which is
    # z_from_face from the CT centres (rigid); the pitch is measured on the column itself, as
    # the membrane may be strained unevenly
    estimates = []
    i_col = nodes[sel, 0]
    for end, sign in ((an.top, 1.0), (an.bottom, -1.0)):
        if end is None:
            continue
        centre, mp = end
        mm_per_px = rc / ellipse_radius(mp[None], down[None])[0]
        d_mm = np.abs((xy[sel] - centre) @ down) * mm_per_px
        order = np.argsort(d_mm)[:4]
        di = np.abs(np.diff(i_col[order]))
        if len(order) < 3 or np.any(di != 1):
            continue  # the column's end rows are not all there
        pitch = float(np.median(np.abs(np.diff(d_mm[order]))))
        rows_from_face = (d_mm[order[0]] - z_from_face) / pitch
        r_first = 0.5 + rows_from_face if sign > 0 else m["rows"] + 0.5 - rows_from_face
        estimates.append(float(r_first - i_col[order[0]]))
    if not estimates:
        return None
    base = (first - pi) % step
    r_off = base + step * round((np.mean(estimates) - base) / step)
    if any(abs(e - r_off) > p.row_tolerance for e in estimates):
        return None
    return c_off % m["columns"], int(r_off)


def _membrane_region_offsets(grid, phase, anchors, pos, design, p, ctx):
    """(column offset, row offset) of one grown grid region from the pedestal CTs, or the reason
    it cannot be fixed."""
    if len(grid) < p.min_region_dots:
        return "membrane region too small"
    if phase is None:
        return "larger membrane dots not distinguishable"
    nodes = np.array(list(grid.keys()))
    xy = pos[np.fromiter(grid.values(), int)]
    offsets = {}
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


def identify(
    blobs: pd.DataFrame,
    cts: pd.DataFrame,
    design: dict,
    undistort,
    dots: np.ndarray,
    params: IdentifyParams | None = None,
    gray: np.ndarray | None = None,
    detect_params=None,
) -> pd.DataFrame:
    """Label one frame's detections (see the module docstring).

    ``blobs``/``cts``: from :func:`triaxtrack.detect.detect_blobs` and
    :func:`~triaxtrack.detect.decode_coded_targets`; ``dots``: the blobs that pass the dot
    criteria (:func:`~triaxtrack.detect.dot_mask`); ``undistort``: (N, 2) distorted pixels ->
    undistorted pixels; ``gray``: the frame, if given, re-centres the longitudinal stripes' dots
    beside a dark edge (:func:`~triaxtrack.detect.gap_background_centroids`) and fits membrane
    dots merged in pairs apart (:func:`_split_merged_pairs`, with ``detect_params``' ink rule).
    Returns one row per CT and per dot (columns ``LABEL_COLUMNS``), ``id`` -1 with a ``reason``
    where the dot could not be labelled beyond doubt; a merged pair's two dots have a row each.
    """
    p = params or IdentifyParams()
    blur_px = float(blobs.blur.iloc[0]) if "blur" in blobs and len(blobs) else 0.0
    uv = blobs[["u_px", "v_px"]].to_numpy(np.float64, copy=True)
    pos = undistort(uv) if len(uv) else uv.copy()
    invertible = np.isfinite(pos).all(axis=1)
    pos = np.where(invertible[:, None], pos, FAR_PX)  # beyond the lens model: never a candidate
    n = len(blobs)
    f = _Frame(
        blobs=blobs,
        pos=pos,
        ids=np.full(n, UNLABELLED, np.int64),
        group=np.full(n, "", object),
        quality=np.zeros(n),
        reason=np.full(n, NOT_REACHED, object),
    )
    in_ct = _inside_cts(f, cts, design["coded_target"])
    cts = _plausible_cts(cts, design)
    candidates = np.asarray(dots, bool) & ~in_ct & invertible
    centres = _ct_maps(f, cts, undistort)
    pool = _Pool(pos, candidates, blobs)
    _label_cell_stripes(f, pool, centres, design, p)
    _label_longitudinal(f, pool, centres, design, p)
    # the white band of a longitudinal stripe hides the membrane behind it: a dot whose image
    # reaches the band's (half its major axis and BAND_BLUR_PX from it) is partly hidden and its
    # centroid is biased, so drop what remains there
    long_names = {s["name"] for s in design["cell_targets"]["longitudinal_stripes"]}
    # the band's blurred edge reaches two lens-blur sigmas beyond its printed edge
    pad = blobs.major_px.to_numpy() / 2 + max(BAND_BLUR_PX, BLUR_REACH * blur_px)
    for sel in (np.nonzero(f.group == nm)[0] for nm in long_names):
        if len(sel) >= 2:
            _hide_behind_band(f, pool, sel[np.argsort(f.ids[sel])], pad, design)
    # a stripe whose coded target is out of the picture is a straight line of free dots on a
    # white band in front of the membrane: never membrane dots, and its band hides the membrane
    axis = _axis_down(_pedestal_anchors(centres, design))
    for order in _straight_chains(pos, np.nonzero(_on_another_surface(pool))[0], axis):
        pool.free[order] = False
        f.reason[order] = "on a longitudinal stripe not identified (its coded target not seen)"
        _hide_behind_band(f, pool, order, pad, design)
    _label_membrane(f, pool, centres, design, p)
    # a dot too small or seen too obliquely for its place (see IdentifyParams: cell-wall dots
    # beside a dark edge need more) has no accurate centroid: not reported; nor has the last dot
    # of a membrane row beside a dark edge (a silhouette, a pedestal edge), whose blob takes in
    # the edge's fringe (up to 1.4 px off on the demo), while the end rows along the pedestal
    # faces keep theirs, also beside a gap where one of their dots was lost to the pedestal's
    # edge (on four tests 0.17 px at the 95th percentile; the one bad dot, 0.93 px off, had
    # taken in the edge: 1.8 times its neighbours' area)
    m = design["membrane"]
    membrane = _is_membrane(f.ids, m)
    edge = blobs.beside_edge.to_numpy(bool, copy=True)
    recentred = np.zeros(n, bool)
    if gray is not None:
        # a longitudinal stripe seen edge-on lies along the dark beyond its band: its dots'
        # centroids, re-measured against the gaps' background, are as good as those clear of it
        k, new = _recentred_beside_edge(f, uv, edge, gray, long_names)
        new_pos = undistort(new) if len(k) else new
        ok = np.isfinite(new_pos).all(axis=1)
        k, new, new_pos = k[ok], new[ok], new_pos[ok]
        uv[k], pos[k], edge[k], recentred[k] = new, new_pos, False, True
    cell_area = np.where(edge, p.min_cell_area_px, p.min_clear_cell_area_px)
    cell_round = np.where(edge, p.min_cell_roundness, p.min_clear_cell_roundness)
    cell_round = np.where(recentred, p.min_recentred_roundness, cell_round)
    row_end, row_gap = _membrane_row_ends(f.ids, m)
    for bad, why in (
        (blobs.area_px.to_numpy() < np.where(membrane, p.min_membrane_area_px, cell_area),
         "too small for an accurate centroid"),
        (blobs.roundness.to_numpy() < np.where(membrane, p.min_membrane_roundness, cell_round),
         "seen too obliquely for an accurate centroid"),
        (row_end & ~row_gap & edge,
         "last of its membrane row, beside a dark edge"),
        (row_gap & edge & (_over_neighbours(f.ids, blobs.area_px.to_numpy(), m) > MERGED_AREA_RATIO),
         "larger than its neighbours beside a dark edge and a gap in its row (merged with the edge)"),
        ((_over_neighbours(f.ids, blobs.roundness.to_numpy(), m) < MERGED_ROUNDNESS_RATIO) & edge,
         "less round than its neighbours, beside a dark edge (merged with the edge's fringe)"),
    ):  # fmt: skip
        bad &= f.ids != UNLABELLED
        f.ids[bad] = UNLABELLED
        f.reason[bad] = why
    split = pd.DataFrame(columns=LABEL_COLUMNS)
    if gray is not None:
        # a blob nothing labelled or turned down (not by a band, a filter), clear of a dark edge
        free = ~in_ct & invertible & ~edge & (f.reason == NOT_REACHED)
        split = _split_merged_pairs(f, uv, gray, free, m, p, detect_params)
        und = undistort(split[["u_px", "v_px"]].to_numpy(np.float64)) if len(split) else np.zeros((0, 2))
        split = split.assign(u_undist_px=und[:, 0], v_undist_px=und[:, 1])
        split = split[np.isfinite(und).all(axis=1)]
    ct_rows = pd.DataFrame({
        "id": cts.id.to_numpy(np.int64), "kind": "coded", "group": "coded",
        "u_px": cts.u_px.to_numpy(), "v_px": cts.v_px.to_numpy(),
        "u_undist_px": pos[cts.blob.to_numpy(), 0] if len(cts) else [],
        "v_undist_px": pos[cts.blob.to_numpy(), 1] if len(cts) else [],
        "area_px": blobs.area_px.to_numpy()[cts.blob.to_numpy()] if len(cts) else [],
        "roundness": blobs.roundness.to_numpy()[cts.blob.to_numpy()] if len(cts) else [],
        "quality": cts.confidence.to_numpy(), "reason": "",
    })  # fmt: skip
    sel = np.nonzero(candidates)[0]
    dot_rows = pd.DataFrame({
        "id": f.ids[sel], "kind": "dot", "group": f.group[sel],
        "u_px": uv[sel, 0], "v_px": uv[sel, 1], "u_undist_px": pos[sel, 0], "v_undist_px": pos[sel, 1],
        "area_px": blobs.area_px.to_numpy()[sel], "roundness": blobs.roundness.to_numpy()[sel],
        "quality": f.quality[sel], "reason": f.reason[sel],
    })  # fmt: skip
    parts = [ct_rows, dot_rows] + ([split[LABEL_COLUMNS].astype(dot_rows.dtypes)] if len(split) else [])
    return pd.concat(parts, ignore_index=True)[LABEL_COLUMNS]


def _recentred_beside_edge(
    f: _Frame, uv: np.ndarray, edge: np.ndarray, gray: np.ndarray, stripes: set[str]
) -> tuple[np.ndarray, np.ndarray]:
    """(blob indices, their new distorted centroids) of the labelled dots of ``stripes`` beside a
    dark edge whose two neighbours along the stripe are labelled, re-centred by
    :func:`~triaxtrack.detect.gap_background_centroids`; where that fails, left out."""
    on = np.isin(f.group, list(stripes))
    blob_of = {(f.group[k], int(f.ids[k])): k for k in np.nonzero(on)[0]}
    sel, prev, nxt = [], [], []
    for k in np.nonzero(on & edge)[0]:
        a, b = (blob_of.get((f.group[k], int(f.ids[k]) + s)) for s in (-1, 1))
        if a is not None and b is not None:
            sel.append(k)
            prev.append(a)
            nxt.append(b)
    sel = np.asarray(sel, int)
    if not len(sel):
        return sel, np.zeros((0, 2))
    minor = f.blobs.minor_px.to_numpy()[sel]
    new = gap_background_centroids(gray, uv[sel], uv[prev], uv[nxt], 0.5 * minor + GAP_ACROSS_PX)
    ok = np.isfinite(new).all(axis=1)
    return sel[ok], new[ok]


def _split_merged_pairs(
    f: _Frame, uv: np.ndarray, gray: np.ndarray, free: np.ndarray, m: dict, p: IdentifyParams, detect_params
) -> pd.DataFrame:
    """Label rows (``LABEL_COLUMNS``) of membrane dots merged in pairs, each pair fitted apart
    by :func:`~triaxtrack.detect.merged_pair_centroids`.

    Two neighbouring unlabelled grid nodes A, B between labelled dots U, D (U, A, B, D along a
    column or a row) whose images merged (a blob at the midpoint of U and D, ``free``: nothing
    labelled it or turned it down, and larger than U and D) are expected at the thirds of U-D.
    They are labelled when both fitted centres lie within the gate of the thirds, their heights
    agree within a factor of ``MERGED_HEIGHT_RATIO`` and the fit leaves under
    ``MERGED_FIT_RMS`` of the blob's contrast.
    ``uv``: the blobs' (distorted) centroids. The merged blob itself stays unlabelled, with a reason.
    """
    member = np.nonzero(_is_membrane(f.ids, m))[0]
    labelled = f.ids[member]
    blob_of = pd.Series(member, index=labelled)
    blob_of = blob_of[~blob_of.index.duplicated()]
    tree = cKDTree(uv)
    area = f.blobs.area_px.to_numpy()
    white = f.blobs.background.to_numpy()
    quads = []
    for dr, dc in ((1, 0), (0, 1)):
        a, b, d = (_grid_neighbour(labelled, m, j * dr, j * dc) for j in (1, 2, 3))
        ok = (a > 0) & (b > 0) & ~np.isin(a, labelled) & ~np.isin(b, labelled) & np.isin(d, labelled)
        quads += zip(member[ok], a[ok], b[ok], blob_of.reindex(d[ok]).to_numpy(), strict=True)
    rows, taken, split = [], set(), set()
    for ku, a, b, kd in sorted(quads, key=lambda q: (f.ids[q[0]], q[2] - q[1])):
        step = (uv[kd] - uv[ku]) / 3
        gate = p.gate * np.linalg.norm(step)
        dist, k = tree.query(uv[ku] + 1.5 * step)
        if {a, b} & taken or k in split or dist > gate or not free[k] or area[k] <= max(area[ku], area[kd]):
            continue
        expected = np.array([uv[ku] + step, uv[ku] + 2 * step])
        centres, (ha, hb, rms, roundness) = merged_pair_centroids(
            gray, *expected, white[k], uv[[ku, kd]], detect_params
        )
        if not (
            np.isfinite(centres).all()
            and (np.linalg.norm(centres - expected, axis=1) <= gate).all()
            and 0 < min(ha, hb)
            and max(ha, hb) <= MERGED_HEIGHT_RATIO * min(ha, hb)
            and rms <= MERGED_FIT_RMS
        ):
            continue
        taken |= {int(a), int(b)}
        split.add(k)
        f.reason[k] = f"two dots merged, fitted apart as {a} and {b}"
        for tid, c in zip((a, b), centres, strict=True):
            rows.append({"id": int(tid), "kind": "dot", "group": f.group[ku], "u_px": c[0], "v_px": c[1],
                         "area_px": area[k] / 2, "roundness": roundness, "quality": MERGED_QUALITY,
                         "reason": ""})  # fmt: skip
    return pd.DataFrame(rows, columns=[c for c in LABEL_COLUMNS if "undist" not in c])


SURFACE_NEIGHBOURS = 8  # free dots around a dot whose white level is the surface's


def _on_another_surface(pool: _Pool) -> np.ndarray:
    """Which free dots lie on a surface whose white level differs by more than
    ``WHITE_TOLERANCE`` from the median of their ``SURFACE_NEIGHBOURS`` nearest free dots' (a
    stripe's white band in front of the grey membrane, a strap across it); the white level
    follows uneven light smoothly, a printed surface's edge does not."""
    free = np.nonzero(pool.free)[0]
    out = np.zeros(len(pool.free), bool)
    if len(free) <= SURFACE_NEIGHBOURS:
        return out
    tree = cKDTree(pool.pos[free])
    _, nb = tree.query(pool.pos[free], k=SURFACE_NEIGHBOURS + 1)
    white = pool.white[free]
    ratio = white / np.median(white[nb[:, 1:]], axis=1)
    out[free] = np.abs(ratio - 1) > WHITE_TOLERANCE
    return out


def _is_membrane(ids: np.ndarray, m: dict) -> np.ndarray:
    """Which of ``ids`` are membrane dot IDs (Eq. 4) of the design's membrane ``m``."""
    k = np.asarray(ids, np.int64) - m["first_id"]
    return (k >= 0) & (k < m["rows"] * m["columns"])


def _grid_neighbour(ids: np.ndarray, m: dict, dr: int, dc: int) -> np.ndarray:
    """The membrane ID ``dr`` rows and ``dc`` columns (around the specimen) from each of ``ids``
    (membrane IDs); 0 beyond the end rows."""
    k = np.asarray(ids, np.int64) - m["first_id"]
    row, col = k // m["columns"] + dr, (k % m["columns"] + dc) % m["columns"]
    return np.where((row >= 0) & (row < m["rows"]), row * m["columns"] + col + m["first_id"], 0)


def _over_neighbours(ids: np.ndarray, values: np.ndarray, m: dict) -> np.ndarray:
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


def _membrane_row_ends(ids: np.ndarray, m: dict) -> tuple[np.ndarray, np.ndarray]:
    """Which of ``ids`` are membrane dots whose row neighbour on either side (column c - 1 or
    c + 1, around the specimen) is not among ``ids``, and which of those are in an end row
    (along a pedestal) with every missing neighbour's own neighbour towards the middle rows
    among ``ids``: a gap in the row where a dot was lost, not the row's end at a silhouette."""
    ids = np.asarray(ids, np.int64)
    member = _is_membrane(ids, m)
    labelled = ids[member]
    row = (ids - m["first_id"]) // m["columns"]
    inward = np.where(row == 0, 1, -1)
    end_row = member & ((row == 0) | (row == m["rows"] - 1))
    ends = np.zeros(len(ids), bool)
    gap = end_row.copy()
    for s in (-1, 1):
        missing = member & ~np.isin(_grid_neighbour(ids, m, 0, s), labelled)
        ends |= missing
        beyond = np.where(inward > 0, _grid_neighbour(ids, m, 1, s), _grid_neighbour(ids, m, -1, s))
        gap &= ~missing | np.isin(beyond, labelled)
    return ends, ends & gap


def undistorted_pixels(camera) -> callable:
    """(N, 2) distorted pixels -> undistorted pixels of ``camera`` (NaN where not invertible)."""
    from functools import partial

    from triaxtrack.optics import pixels_to_undistorted

    return partial(pixels_to_undistorted, camera)


def label_frame(gray: np.ndarray, camera, design: dict, codes: dict[int, int], detect_params=None,
                identify_params: IdentifyParams | None = None) -> pd.DataFrame:  # fmt: skip
    """Detect and identify every target in one grey frame of a calibrated ``camera``
    (:class:`triaxtrack.optics.Camera`, intrinsics used). Columns ``LABEL_COLUMNS``."""
    from triaxtrack.detect import decode_coded_targets, detect_blobs, dot_mask

    blobs = detect_blobs(gray, detect_params)
    cts = decode_coded_targets(gray, blobs, codes, design["coded_target"], detect_params)
    return identify(blobs, cts, design, undistorted_pixels(camera), dot_mask(blobs, detect_params),
                    identify_params, gray=gray, detect_params=detect_params)  # fmt: skip


def draw_labels(gray: np.ndarray, labels: pd.DataFrame, scale: int = 2) -> np.ndarray:
    """A BGR picture of the frame with every labelled target's ID, for a person to check.

    Green: CTs (ID printed); cyan: cell dots; yellow: membrane dots (ID printed on the larger
    ones and every tenth); red crosses: detections left unlabelled.
    """
    import cv2

    img = cv2.cvtColor(np.asarray(gray, np.uint8), cv2.COLOR_GRAY2BGR)
    img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_LINEAR)
    font = cv2.FONT_HERSHEY_SIMPLEX
    for r in labels.itertuples(index=False):
        c = (int(round((r.u_px + 0.5) * scale - 0.5)), int(round((r.v_px + 0.5) * scale - 0.5)))
        if r.id == UNLABELLED:
            cv2.drawMarker(img, c, (0, 0, 255), cv2.MARKER_TILTED_CROSS, 3 * scale, 1)
            continue
        if r.kind == "coded":
            colour, text = (0, 220, 0), str(r.id)
        elif str(r.group).startswith("membrane"):
            colour, text = (0, 220, 220), str(r.id) if r.id % 10 == 0 else ""
        else:
            colour, text = (220, 220, 0), str(r.id) if r.id % 4 == 1 else ""
        cv2.circle(img, c, 2 * scale, colour, 1, cv2.LINE_AA)
        if text:
            cv2.putText(
                img, text, (c[0] + 3 * scale, c[1] - 2 * scale), font, 0.3 * scale, colour, 1, cv2.LINE_AA
            )
    return img


def label_chunk_start(
    video_path, fmap: pd.DataFrame, camera, design: dict, codes: dict[int, int], start: int, stop: int
) -> tuple[int | None, np.ndarray | None, pd.DataFrame]:
    """Label the first frame of the chunk ``[start, stop)`` that the camera recorded.

    Returns ``(frame, image, labels)``; ``frame`` is None (and ``labels`` empty) when the camera
    recorded none of the chunk's frames. ``labels`` carries ``camera`` and ``frame`` columns.
    """
    from triaxtrack.frames import iter_test_frames

    for k, image in iter_test_frames(video_path, fmap, start, stop):
        if image is not None:
            labels = label_frame(image, camera, design, codes)
            return k, image, labels.assign(camera=camera.name, frame=k)
    return None, None, pd.DataFrame(columns=["camera", "frame", *LABEL_COLUMNS])
