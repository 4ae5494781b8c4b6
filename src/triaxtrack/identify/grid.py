"""Chain and grid growing over the pool of free candidate dots, and the local geometry they use.

Every step accepts a dot only when it is the single candidate within its gate (a fraction of
the local dot spacing) and not claimed twice (:class:`_Pool`). A 1-D stripe grows by
interpolation and stepwise extrapolation (:func:`grow_chain`), a 2-D grid from a 3 x 3 seed by
straight continuations and parallelograms (:func:`grow_grid`). All geometry is in undistorted
pixels; a CT's local affine map (design millimetres to pixels) comes from its centre dot's
ellipse (:func:`local_affine`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree


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
    bridge: bool = False,
) -> dict[int, int]:
    """Extend a 1-D stripe labelling (index -> dot) by interpolation and stepwise extrapolation.

    A missing dot stops the walk (the next prediction falls between dots, outside the gate), so
    the IDs beyond it cannot shift. With ``bridge``, when the walk has stopped, a walk's end
    goes on past one missing dot where nothing at all lies within the gate of that dot's
    prediction and exactly one free dot within the gate of the next one's (two steps on: a dot
    one step off is a whole spacing away), and on from there with the step across the gap.
    ``step_hint[i]``: the image step from index i to i + 1, used when i has no labelled
    neighbour to extrapolate from.
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
            pred: np.ndarray | None = None
            spacing = 0.0  # the dot spacing there, pixels (set with pred)
            lo = next((j for j in range(i - 1, i - max_bracket, -1) if has(j)), None)
            hi = next((k for k in range(i + 1, i + max_bracket) if has(k)), None)
            if lo is not None and hi is not None:
                f = (i - lo) / (hi - lo)
                pred = p(lo) + f * (p(hi) - p(lo))
                spacing = float(np.linalg.norm(p(hi) - p(lo))) / (hi - lo)
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
                        spacing = float(np.linalg.norm(d))
                    elif bridge and has(a - 2 * s):  # on from a bridged gap
                        d = 0.5 * (p(a) - p(a - 2 * s))
                        pred, spacing = p(a) + d, float(np.linalg.norm(d))
                    elif (s == 1 and key(a) in hint) or (s == -1 and key(i) in hint):
                        d = hint[key(a)] if s == 1 else -hint[key(i)]
                        pred, spacing = p(a) + d, float(np.linalg.norm(d))
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
        if not proposals and bridge:
            proposals = _bridged(pool, labels, n, cyclic, gate)
        if not proposals:
            return labels
        for i, j in proposals.items():
            labels[i] = j
            pool.free[j] = False


def _bridged(pool: _Pool, labels: dict[int, int], n: int, cyclic: bool, gate: float) -> dict[int, int]:
    """:func:`grow_chain`'s bridges: index -> dot for each walk's end (the index behind it
    labelled) whose next dot is missing, nothing at all within the gate of its prediction (straight
    on at the last step), and the dot after it alone within the gate of its own; an index or a
    dot two ends want goes to neither."""
    found: list[tuple[int, int]] = []
    for e in labels:
        for s in (1, -1):
            idx = [e - s, e + s, e + 2 * s]
            if not cyclic and not all(0 <= i < n for i in idx):
                continue
            back, gap, far = (i % n if cyclic else i for i in idx)
            if back not in labels or gap in labels or far in labels:
                continue
            d = pool.pos[labels[e]] - pool.pos[labels[back]]
            radius = gate * float(np.linalg.norm(d))
            if radius <= 0 or pool.tree.query_ball_point(pool.pos[labels[e]] + d, radius):
                continue  # a dot there, free or taken: not a gap
            j = pool.unique_within(pool.pos[labels[e]] + 2 * d, radius)
            if j >= 0:
                found.append((far, j))
    indices, dots = [i for i, _ in found], [j for _, j in found]
    return {i: j for i, j in found if indices.count(i) == 1 and dots.count(j) == 1}


NEIGHBOURS = ((1, 0), (-1, 0), (0, 1), (0, -1))
MIN_SUPPORT = 3  # labelled nodes among the 8 around a node before it is predicted
AREA_RANGE = (0.45, 1.85)  # a grid dot's area over its labelled neighbours' median
# ... up to AREA_RANGE[1] x the design's larger over smaller dots' area (``size_ratio``) for a dot
# inside the grid, with a dot beyond it on every side: a larger dot. On soft footage the blur
# shrinks the smaller dots' thresholded area the more: at 720p (nvr, blur 1 px) the larger
# membrane dots' area over their neighbours' was 1.71-1.75 at the median and 2.1-2.4 at the 99th
# percentile (design 1.56), and AREA_RANGE alone stopped the grid's growth at every larger dot of
# a strip three columns wide beyond a band (a 420 mm ring's camera left 6 of the 15 columns it saw
# within 60 degrees of face on unlabelled). At the grid's edge such a blob is a dot that took in
# an edge's fringe (an end row's larger dot merged with the pedestal face: 1.1 px off)
WHITE_TOLERANCE = 0.08  # a grid dot's local white level may differ this much from its neighbours'


def grow_grid(
    pool: _Pool, seed: dict[tuple[int, int], int], gate: float, size_ratio: float = 1.0
) -> dict[tuple[int, int], int]:
    """Extend a 2-D grid labelling ((row, col) -> dot) from its labelled neighbours.

    A node is predicted by every straight continuation (two labelled nodes in a line) and every
    parallelogram (three labelled corners); the predictions must agree within the gate, and
    exactly one free dot may lie within ``gate`` times the local spacing of their median (the
    spacing along the lines and, where measured, across them). A node needs ``MIN_SUPPORT``
    labelled nodes among its eight neighbours, or one fewer when one of them continues a straight
    line and the other, beside it, gives the spacing across that line: that carries a strip a few
    columns wide past a dot missing from its edge column (towards a silhouette, beyond a band).
    A dot's area over its labelled neighbours' median must be within ``AREA_RANGE``, or up to
    ``size_ratio`` (the design's larger over its smaller dots' area) times its upper end for a
    dot inside the grid (:func:`_inside`).
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
            preds: list[np.ndarray] = []
            steps: list[np.floating] = []
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
            candidates = np.asarray(preds)
            pred = np.median(candidates, axis=0)
            radius = gate * min(steps)
            if np.max(np.linalg.norm(candidates - pred, axis=1)) > radius:
                continue
            k = pool.unique_within(pred, radius)
            if k < 0:
                continue
            nb = [labels[(i + di, j + dj)] for di, dj in NEIGHBOURS if (i + di, j + dj) in labels]
            ratio = pool.area[k] / np.median(pool.area[nb])
            larger = AREA_RANGE[1] < ratio <= AREA_RANGE[1] * size_ratio
            same = AREA_RANGE[0] <= ratio <= AREA_RANGE[1]
            if not (same or (larger and _inside(pool, labels, (i, j), k, gate))):
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


def _inside(pool: _Pool, labels: dict, node: tuple[int, int], k: int, gate: float) -> bool:
    """Whether dot ``k`` at grid ``node`` has a dot beyond it on every side along its row and
    column: a labelled node, or a detected dot (free or not) within ``gate`` of the step from the
    labelled node opposite, mirrored."""
    i, j = node
    for di, dj in NEIGHBOURS:
        if (i + di, j + dj) in labels:
            continue
        back = labels.get((i - di, j - dj))
        if back is None:
            return False
        step = pool.pos[k] - pool.pos[back]
        if not pool.tree.query_ball_point(pool.pos[k] + step, gate * float(np.linalg.norm(step))):
            return False
    return True


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


def _grow_region(
    pool: _Pool, start: int, down: np.ndarray, gate: float, size_ratio: float, narrow: bool = False
) -> list[dict]:
    """The grid region grown from a free dot (taking its dots from the pool), or none
    (``size_ratio``: :func:`grow_grid`'s)."""
    if not pool.free[start]:
        return []
    seed = _seed_grid(pool, start, down, gate, narrow)
    if seed is None:
        return []
    pool.free[list(seed.values())] = False
    return [grow_grid(pool, seed, gate, size_ratio)]
