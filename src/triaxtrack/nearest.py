"""The nearest point within a reach, compiled with numba, for checks that ask only whether some
point lies within a threshold (tracking's ``ambiguous``, completion's separations): exact as
scipy's ``cKDTree.query`` is (the Euclidean distance ``sqrt(du**2 + dv**2)``, rounded as it
rounds it), but without building a tree for a handful of queries or for one frame (a tree over
1700 targets and its 1700 queries took 0.9 ms of a frame's 4.4 ms of tracking at 4K). Also the
discs that overlap a few given ones (:func:`overlapping_discs`: the window measurement's touching
targets). Pixels, or any units both arrays share."""

from __future__ import annotations

import math

import numba
import numpy as np
from scipy.spatial import cKDTree

CELL_SLACK = 1e-9  # relative widening of the cells searched: no point at the reach is missed by
# rounding in the cells' bounds (the distance test itself is exact)
BRUTE_FORCE_PAIRS = 250_000  # queries x points up to which overlapping_discs scans every point (compiled:
# 129 queries of 1800 points took 0.34 ms scanned, 0.42 ms with a tree; 300, 0.74 and 0.57 ms)
CELLS_PER_POINT = 16  # cells at most per point: cells of the reach where that allows, larger where
# the reach is small against the points' spread (a few points per cell in a dense grid of dots)


def finite_rows(a: np.ndarray) -> np.ndarray:
    """(n,) bool: the rows of ``a`` (n, 2) with both coordinates finite, as
    ``np.isfinite(a).all(axis=1)`` (a tenth of its time: a reduction along an axis of two is slow,
    20 us for 1700 rows)."""
    return np.isfinite(a[:, 0]) & np.isfinite(a[:, 1])


def nearest_within(
    points: np.ndarray, queries: np.ndarray, reach: np.ndarray | float, *, exclude_self: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Per query (q, 2), the distance to the nearest of the finite ``points`` (p, 2) and its
    index, where that distance is at most ``reach`` (q,) or a scalar (inclusive; infinite:
    anywhere); else ``(inf, -1)`` (also for a NaN query or reach). With ``exclude_self`` the
    queries are the points themselves and query i does not find point i (a duplicate of it at
    distance 0 is found). Any comparison of the distance with a threshold at most the reach
    (``d < t``, ``d <= t``, ``d > t``, ``d >= t``) comes out as with the exact nearest distance:
    beyond the reach ``inf`` compares as a farther distance does. Ties (equal distances) go to
    either point."""
    pts = np.ascontiguousarray(points, np.float64).reshape(-1, 2)
    qry = np.ascontiguousarray(queries, np.float64).reshape(-1, 2)
    lim = np.ascontiguousarray(np.broadcast_to(np.asarray(reach, np.float64), (len(qry),)))
    if exclude_self and len(pts) != len(qry):
        raise ValueError(f"nearest_within: exclude_self needs the points as the queries, "
                         f"got {len(pts)} points and {len(qry)} queries")  # fmt: skip
    return _nearest_within(pts, qry, lim, exclude_self)


def crowded(points: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """(p,) bool: the points (p, 2) with another closer than their ``reach`` (p,), and the nearest
    other of each of them (two targets converged on one blob: both)."""
    d, nearest = nearest_within(points, points, reach, exclude_self=True)
    close = d < reach
    out = close.copy()
    out[nearest[close]] = True
    return out


@numba.njit(cache=True)
def _nearest_within(
    pts: np.ndarray, qry: np.ndarray, lim: np.ndarray, exclude_self: bool
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nearest_within`: the points binned in square cells of the median reach (larger
    where that would make more than about ``CELLS_PER_POINT`` cells a point), each query scanning
    the cells within its reach (a strip of one coordinate would hold whole rows or columns of a
    grid of dots)."""
    q = len(qry)
    dist, index = np.full(q, np.inf), np.full(q, -1, np.int64)
    keep = np.nonzero(np.isfinite(pts[:, 0]) & np.isfinite(pts[:, 1]))[0]
    n = len(keep)
    if n == 0:
        return dist, index
    u0, v0 = pts[keep, 0].min(), pts[keep, 1].min()
    wu, wv = max(pts[keep, 0].max() - u0, 1.0), max(pts[keep, 1].max() - v0, 1.0)
    fin = lim[np.isfinite(lim) & (lim > 0)]
    cells = CELLS_PER_POINT * n  # at most about 3 x this many cells, however the points spread
    h = max(np.median(fin) if len(fin) else 0.0, math.sqrt(wu * wv / cells), max(wu, wv) / cells)
    nx, ny = int(wu / h) + 1, int(wv / h) + 1
    cell = np.empty(n, np.int64)
    start = np.zeros(nx * ny + 1, np.int64)
    for t in range(n):
        cx = min(int((pts[keep[t], 0] - u0) / h), nx - 1)
        cy = min(int((pts[keep[t], 1] - v0) / h), ny - 1)
        cell[t] = cy * nx + cx
        start[cell[t] + 1] += 1
    start = np.cumsum(start)
    order, fill = np.empty(n, np.int64), start[:-1].copy()
    for t in range(n):
        order[fill[cell[t]]] = keep[t]
        fill[cell[t]] += 1
    for i in range(q):
        qu, qv, r = qry[i, 0], qry[i, 1], lim[i]
        if not (np.isfinite(qu) and np.isfinite(qv)) or math.isnan(r) or r < 0:
            continue
        pad = r + CELL_SLACK * (r + abs(qu) + abs(qv) + 1.0)
        fx0, fx1 = (qu - pad - u0) / h, (qu + pad - u0) / h
        fy0, fy1 = (qv - pad - v0) / h, (qv + pad - v0) / h
        if fx1 < 0 or fy1 < 0 or fx0 >= nx or fy0 >= ny:
            continue
        x0, x1 = int(max(fx0, 0.0)), int(min(fx1, nx - 1.0))
        y0, y1 = int(max(fy0, 0.0)), int(min(fy1, ny - 1.0))
        best, at = np.inf, -1
        for y in range(y0, y1 + 1):
            for c in range(y * nx + x0, y * nx + x1 + 1):
                for t in range(start[c], start[c + 1]):
                    j = order[t]
                    if exclude_self and j == i:
                        continue
                    du, dv = pts[j, 0] - qu, pts[j, 1] - qv
                    d = math.sqrt(du * du + dv * dv)
                    if d <= r and d < best:
                        best, at = d, j
        dist[i], index[i] = best, at
    return dist, index


def overlapping_discs(uv: np.ndarray, rad: np.ndarray, which: np.ndarray, most: int) -> np.ndarray:
    """(len(which), most, 3): for each of the discs ``which`` (indices), the centres and radii of
    those of the ``most`` other discs with the nearest centres that overlap it, nearest first
    (centres ``uv`` (N, 2), radii ``rad`` (N,); NaN ones are none); NaN rows where fewer do."""
    out = np.full((len(which), most, 3), np.nan)
    live = np.nonzero(finite_rows(uv) & np.isfinite(rad))[0]
    if len(live) < 2:
        return out
    k = min(most + 1, len(live))
    if len(which) * len(live) <= BRUTE_FORCE_PAIRS:  # a few queries: no tree over every point
        d, j = _k_nearest(np.ascontiguousarray(uv, np.float64), live, np.asarray(which, np.int64), k)
    else:
        d, j = cKDTree(uv[live]).query(uv[which], k=k)
    d, j = d.reshape(len(which), k), live[np.minimum(j, len(live) - 1)].reshape(len(which), k)
    uv, rad = np.ascontiguousarray(uv, np.float64), np.ascontiguousarray(rad, np.float64)
    _touching(uv, rad, np.asarray(which, np.int64), np.ascontiguousarray(d), np.ascontiguousarray(j), out)
    return out


@numba.njit(cache=True)
def _touching(uv: np.ndarray, rad: np.ndarray, which: np.ndarray, d: np.ndarray, j: np.ndarray,
              out: np.ndarray) -> None:  # fmt: skip
    """Into ``out`` ((m, most, 3), NaN): for each disc ``which[q]``, the centres and radii of the
    discs ``j[q]`` (nearest first, at distances ``d[q]``) that overlap it, in that order, at most
    ``most``."""
    for q in range(len(which)):
        w, c = which[q], 0
        for s in range(j.shape[1]):
            if c == out.shape[1]:
                break
            t = j[q, s]
            if d[q, s] < rad[w] + rad[t] and t != w and d[q, s] > 0:
                out[q, c, 0], out[q, c, 1], out[q, c, 2] = uv[t, 0], uv[t, 1], rad[t]
                c += 1


@numba.njit(cache=True)
def _k_nearest(uv: np.ndarray, live: np.ndarray, which: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(m, k) distances and positions in ``live`` of the ``k`` points of ``live`` nearest each of
    the points ``which`` (k <= len(live)), nearest first, by scanning them all (a few queries)."""
    m = len(which)
    d2, j = np.full((m, k), np.inf), np.zeros((m, k), np.int64)
    for q in range(m):
        u, v = uv[which[q], 0], uv[which[q], 1]
        for i in range(len(live)):
            du, dv = u - uv[live[i], 0], v - uv[live[i], 1]
            e = du * du + dv * dv
            if e < d2[q, k - 1]:  # insert, keeping the k nearest in order
                s = k - 1
                while s > 0 and d2[q, s - 1] > e:
                    d2[q, s], j[q, s] = d2[q, s - 1], j[q, s - 1]
                    s -= 1
                d2[q, s], j[q, s] = e, i
    return np.sqrt(d2), j


def k_nearest(points: np.ndarray, queries: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(q, k) distances and indices of the ``k`` points (p, 2) nearest each query (q, 2), nearest
    first: ``cKDTree(points).query(queries, k=k)`` (1 <= k <= p), the same numbers. Found in a
    compiled grid of cells (the tree's 1600 queries of 13 neighbours took 1.6 ms, a chunk's
    set-up); where two of a query's k + 1 nearest are equally far (their order is the tree's own)
    or a coordinate is not finite, by the tree."""
    pts = np.ascontiguousarray(points, np.float64).reshape(-1, 2)
    qry = np.ascontiguousarray(queries, np.float64).reshape(-1, 2)
    if not 1 <= k <= len(pts):
        raise ValueError(f"k_nearest: k = {k} of {len(pts)} points")
    if np.isfinite(pts).all() and np.isfinite(qry).all():
        d2, j, tied = _grid_k_nearest(pts, qry, k)
        if not tied:
            return np.sqrt(d2), j
    d, j = cKDTree(pts).query(qry, k=k)
    return np.asarray(d).reshape(len(qry), k), np.asarray(j).reshape(len(qry), k)


@numba.njit(cache=True)
def _grid_k_nearest(pts: np.ndarray, qry: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, bool]:
    """:func:`k_nearest`'s squared distances (as the tree sums them: du * du + dv * dv) and
    indices, the points binned in square cells of about two points each, each query scanning
    rings of cells around its own until its k + 1 nearest (k where there are no more) are nearer
    than any point beyond; and whether two of those k + 1 were equally far for some query."""
    n, q = len(pts), len(qry)
    m = min(k + 1, n)  # k + 1: a tie at the k-th is seen
    u0, v0 = pts[:, 0].min(), pts[:, 1].min()
    wu, wv = max(pts[:, 0].max() - u0, 1.0), max(pts[:, 1].max() - v0, 1.0)
    h = max(math.sqrt(2.0 * wu * wv / n), max(wu, wv) / (4.0 * n))
    nx, ny = int(wu / h) + 1, int(wv / h) + 1
    cell = np.empty(n, np.int64)
    start = np.zeros(nx * ny + 1, np.int64)
    for t in range(n):
        cell[t] = min(int((pts[t, 1] - v0) / h), ny - 1) * nx + min(int((pts[t, 0] - u0) / h), nx - 1)
        start[cell[t] + 1] += 1
    start = np.cumsum(start)
    order, fill = np.empty(n, np.int64), start[:-1].copy()
    for t in range(n):
        order[fill[cell[t]]] = t
        fill[cell[t]] += 1
    d2, idx = np.empty((q, k)), np.empty((q, k), np.int64)
    best, at = np.empty(m), np.empty(m, np.int64)
    tied = False
    for i in range(q):
        qu, qv = qry[i, 0], qry[i, 1]
        cx = min(max(int(math.floor((qu - u0) / h)), 0), nx - 1)
        cy = min(max(int(math.floor((qv - v0) / h)), 0), ny - 1)
        got = 0
        r = 0
        while True:
            for y in range(cy - r, cy + r + 1):
                if y < 0 or y >= ny:
                    continue
                step = 1 if y == cy - r or y == cy + r else 2 * r  # the ring's cells only
                for x in range(cx - r, cx + r + 1, max(step, 1)):
                    if x < 0 or x >= nx:
                        continue
                    c = y * nx + x
                    for s in range(start[c], start[c + 1]):
                        t = order[s]
                        du, dv = qu - pts[t, 0], qv - pts[t, 1]
                        e = du * du + dv * dv
                        if got == m and e >= best[m - 1]:
                            continue
                        p = got if got < m else m - 1  # insert, keeping the m nearest in order
                        while p > 0 and best[p - 1] > e:
                            best[p], at[p] = best[p - 1], at[p - 1]
                            p -= 1
                        best[p], at[p] = e, t
                        got = min(got + 1, m)
            if cx - r <= 0 and cy - r <= 0 and cx + r >= nx - 1 and cy + r >= ny - 1:
                break  # every cell scanned
            if got == m:  # every point beyond the rings scanned is farther than reach (a side at
                # the grid's edge has none beyond it)
                reach = np.inf
                if cx - r > 0:
                    reach = min(reach, qu - (u0 + (cx - r) * h))
                if cx + r < nx - 1:
                    reach = min(reach, u0 + (cx + r + 1) * h - qu)
                if cy - r > 0:
                    reach = min(reach, qv - (v0 + (cy - r) * h))
                if cy + r < ny - 1:
                    reach = min(reach, v0 + (cy + r + 1) * h - qv)
                reach -= 1e-9 * (abs(qu) + abs(qv) + h * (r + 1) + 1.0)
                if reach > 0 and best[m - 1] < reach * reach:
                    break
            r += 1
        for s in range(1, m):
            if best[s] == best[s - 1]:
                tied = True
        d2[i], idx[i] = best[:k], at[:k]
    return d2, idx, tied
