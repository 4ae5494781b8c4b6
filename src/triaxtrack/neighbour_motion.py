"""Neighbour motion kernels for tracking (:mod:`triaxtrack.track`), compiled with numba: the
local affine flow of the neighbours' displacements, and the motion a frame shows unwrapped
across the grid of neighbours. Pixels in OpenCV's convention; a neighbour index equal to the
number of targets means none."""

from __future__ import annotations

import numba
import numpy as np

from triaxtrack.nearest import finite_rows, k_nearest

REFERENCE_NEIGHBOURS = 200  # reported targets whose displacement places a target taken on


@numba.njit(cache=True)
def affine_flow(
    ref_uv: np.ndarray, disp: np.ndarray, ok: np.ndarray, nb: np.ndarray, min_count: int
) -> tuple[np.ndarray, np.ndarray]:
    """Per target (N rows), the least-squares affine map ``d = a + B dx`` of its ``ok``
    neighbours' displacements ``d`` over their offsets ``dx`` at the reference frame (normal
    equations, 1e-6 added to the diagonal, solved by Gaussian elimination with partial pivoting);
    its constant term ``a`` is the prediction. Zero where not valid (too few neighbours, or no
    reference position)."""
    n = len(ref_uv)
    pred, valid = np.zeros((n, 2)), np.zeros(n, np.bool_)
    a, rhs = np.empty((3, 3)), np.empty((3, 2))
    for i in range(n):
        if not (np.isfinite(ref_uv[i, 0]) and np.isfinite(ref_uv[i, 1])):
            continue
        xx = xy = x = yy = y = used = xu = xv = yu = yv = u = v = 0.0  # sums of the normal equations
        for k in range(nb.shape[1]):
            j = nb[i, k]
            if j >= n or not ok[j]:
                continue
            dx, dy, du, dv = ref_uv[j, 0] - ref_uv[i, 0], ref_uv[j, 1] - ref_uv[i, 1], disp[j, 0], disp[j, 1]
            xx, xy, x, yy, y, used = xx + dx * dx, xy + dx * dy, x + dx, yy + dy * dy, y + dy, used + 1.0
            xu, xv, yu, yv, u, v = xu + dx * du, xv + dx * dv, yu + dy * du, yv + dy * dv, u + du, v + dv
        if used < min_count:
            continue
        a[0, 0], a[0, 1], a[0, 2], rhs[0, 0], rhs[0, 1] = xx + 1e-6, xy, x, xu, xv
        a[1, 0], a[1, 1], a[1, 2], rhs[1, 0], rhs[1, 1] = xy, yy + 1e-6, y, yu, yv
        a[2, 0], a[2, 1], a[2, 2], rhs[2, 0], rhs[2, 1] = x, y, used + 1e-6, u, v
        solve3(a, rhs)
        pred[i, 0], pred[i, 1], valid[i] = rhs[2, 0], rhs[2, 1], True
    return pred, valid


@numba.njit(cache=True)
def solve3(a: np.ndarray, rhs: np.ndarray) -> None:
    """Solve ``a x = rhs`` (3 x 3, two right-hand sides) in place (``x`` into ``rhs``; ``a``
    overwritten) by Gaussian elimination with partial pivoting, as LAPACK's gesv."""
    for c in range(3):
        p = c
        for r in range(c + 1, 3):
            if abs(a[r, c]) > abs(a[p, c]):
                p = r
        for k in range(3):
            a[c, k], a[p, k] = a[p, k], a[c, k]
        for k in range(2):
            rhs[c, k], rhs[p, k] = rhs[p, k], rhs[c, k]
        inv = 1.0 / a[c, c]
        for r in range(c + 1, 3):
            f = a[r, c] * inv
            for k in range(c, 3):
                a[r, k] -= f * a[c, k]
            for k in range(2):
                rhs[r, k] -= f * rhs[c, k]
    for r in range(2, -1, -1):
        for k in range(2):
            for q in range(r + 1, 3):
                rhs[r, k] -= a[r, q] * rhs[q, k]
            rhs[r, k] /= a[r, r]


@numba.njit(cache=True)
def median2(buf: np.ndarray, m: int) -> tuple[float, float]:
    """Per-axis median of the first ``m`` rows of ``buf`` (k, 2): the middle value of each sorted
    axis, or the mean of the two middle ones (NaN sorted last, as ``np.sort`` puts it), sorted
    in place (no copies: the unwrapping takes a few hundred medians of about ten a frame)."""
    for c in range(2):  # insertion sort of each column
        for i in range(1, m):
            x, j = buf[i, c], i
            while j > 0 and _after(buf[j - 1, c], x):
                buf[j, c] = buf[j - 1, c]
                j -= 1
            buf[j, c] = x
    h = m // 2
    if m % 2:
        return buf[h, 0], buf[h, 1]
    return 0.5 * (buf[h - 1, 0] + buf[h, 0]), 0.5 * (buf[h - 1, 1] + buf[h, 1])


@numba.njit(cache=True)
def _after(a: float, b: float) -> bool:
    """Whether ``a`` sorts after ``b`` (NaN after every number)."""
    return a > b or (np.isnan(a) and not np.isnan(b))


@numba.njit(cache=True)
def _known_median(
    i: int, motion: np.ndarray, known: np.ndarray, nb: np.ndarray, buf: np.ndarray
) -> tuple[int, float, float]:
    """(count, per-axis median) of the ``motion`` of target ``i``'s ``known`` neighbours
    (``buf`` (k, 2): scratch space); the median is NaN when there are none."""
    n, m = len(motion), 0
    for q in range(nb.shape[1]):
        j = nb[i, q]
        if j < n and known[j]:
            buf[m, 0], buf[m, 1] = motion[j, 0], motion[j, 1]
            m += 1
    if m == 0:
        return 0, np.nan, np.nan
    cu, cv = median2(buf, m)
    return m, cu, cv


@numba.njit(cache=True)
def unwrap_motion(
    miss: np.ndarray, found: np.ndarray, pos: np.ndarray, nb: np.ndarray, tol: np.ndarray, min_count: int
) -> tuple[np.ndarray, np.ndarray]:
    """Each target's motion ``(motion (n, 2), known (n,))`` from the ``found`` targets' ``miss``
    (n, 2: the blob found less the prediction, pixels) at their predicted positions ``pos``
    (n, 2), with neighbours ``nb`` (n, k indices; n: none) and tolerances ``tol`` (n,) pixels.

    A miss within its tolerance is the target's own motion (a seed). Round by round, a target
    with at least ``min_count`` known neighbours gets their per-axis median motion ``c``, and if
    it was found, the one of its miss and the miss less each neighbour's offset (the blob found
    may be that neighbour's dot, one offset over) nearest ``c`` where that is within its
    tolerance: the motion is unwrapped across the grid as phase is. Last, a motion spread to a
    target that is farther than its tolerance from its known neighbours' median is not
    ``known`` (a seed's, its own measurement, stands)."""
    n, k = nb.shape
    motion = np.zeros((n, 2))
    known = np.zeros(n, np.bool_)
    for i in range(n):  # the seeds: a miss within the gate is the target's own motion
        if found[i] and miss[i, 0] ** 2 + miss[i, 1] ** 2 <= tol[i] ** 2:
            motion[i, 0], motion[i, 1], known[i] = miss[i, 0], miss[i, 1], True  # not row views: slow
    seed = known.copy()
    buf = np.empty((k, 2))
    for _ in range(n):  # each round reaches the targets next to the known ones
        fresh = known.copy()
        for i in range(n):
            if known[i]:
                continue
            m, cu, cv = _known_median(i, motion, known, nb, buf)
            if m < min_count:
                continue
            motion[i, 0], motion[i, 1], fresh[i] = cu, cv, True
            if not found[i]:
                continue
            # the blob found is this dot, or a neighbour j one offset (pos_j - pos_i) over
            best = (miss[i, 0] - cu) ** 2 + (miss[i, 1] - cv) ** 2
            bu, bv = miss[i, 0], miss[i, 1]
            for q in range(k):
                j = nb[i, q]
                if j >= n:
                    continue
                au, av = miss[i, 0] - (pos[j, 0] - pos[i, 0]), miss[i, 1] - (pos[j, 1] - pos[i, 1])
                d = (au - cu) ** 2 + (av - cv) ** 2
                if d < best:
                    best, bu, bv = d, au, av
            if best <= tol[i] ** 2:
                motion[i, 0], motion[i, 1] = bu, bv
        if (fresh == known).all():
            break
        known = fresh
    agree = known.copy()  # each motion spread to must agree with its known neighbours' median
    for i in range(n):
        if not known[i] or seed[i]:
            continue
        m, cu, cv = _known_median(i, motion, known, nb, buf)
        if m >= min_count:
            agree[i] = (motion[i, 0] - cu) ** 2 + (motion[i, 1] - cv) ** 2 <= tol[i] ** 2
    return motion, agree


def reference_places(
    ref_uv: np.ndarray, last_uv: np.ndarray, reported: np.ndarray, first_new: int, width_px: np.ndarray
) -> np.ndarray:
    """A copy of ``ref_uv`` (n, 2) with the reference places of the targets from ``first_new`` on
    (just taken on, seen at ``last_uv``) moved back by the displacement since the reference frame
    that the ``reported`` targets before them show there: a least-squares quadratic map of their
    displacements over their places now, weighted by a Gaussian of each new target's
    ``width_px`` (m,) around it (:func:`weighted_quadratic`; its ``REFERENCE_NEIGHBOURS`` nearest).

    The weighting makes the places a smooth field: targets taken on together inside a patch that
    was hidden (a few spacings from the nearest reported ones) get consistent places, so their
    own affine motion, which the tracker's flow check compares each of them with from the next
    frame, does not read their differences as drift. Placed by the median displacement of a few
    nearest, a dot was off their motion by its gradient over that reach (58 of 69 dots of a
    hidden patch dropped as drifting the frame after, on a test at 1 % strain); placed by their
    affine motion, by its curvature (a patch of 223 dots 3-9 spacings across: 0.3 px median,
    1.8 px worst, against 0.07 and 0.46 px with the quadratic map)."""
    ref = np.array(ref_uv, dtype=np.float64, copy=True)
    pool = np.nonzero(np.asarray(reported[:first_new], bool) & finite_rows(ref[:first_new]))[0]
    new = np.arange(first_new, len(ref))
    if len(pool) < 6 or not len(new):  # a quadratic needs six
        return ref
    at = np.asarray(last_uv, np.float64)
    k = min(REFERENCE_NEIGHBOURS, len(pool))
    dist, j = k_nearest(at[pool], at[new], k)
    width = np.asarray(width_px, np.float64)
    disp = weighted_quadratic(at[pool], at[pool] - ref[pool], at[new], j, dist, width)
    ref[new] = at[new] - disp
    return ref


@numba.njit(cache=True)
def weighted_quadratic(
    at: np.ndarray, value: np.ndarray, query: np.ndarray, nb: np.ndarray, dist: np.ndarray, width: np.ndarray
) -> np.ndarray:
    """Per query point (m, 2), the constant term of the least-squares quadratic map of ``value``
    (p, 2) over the places ``at`` (p, 2) of its neighbours ``nb`` (m, k; at distances ``dist``,
    nearest first), each weighted by ``exp(-(d^2 - d_0^2) / (2 width^2))`` (relative to the
    nearest: no underflow far from every point); offsets in units of ``width``, and a ridge of
    1e-6 of the total weight on the five non-constant terms (finite where the neighbours lie on
    a line)."""
    m = len(query)
    out = np.zeros((m, 2))
    basis = np.empty(6)
    for i in range(m):
        a, rhs = np.zeros((6, 6)), np.zeros((6, 2))
        for q in range(nb.shape[1]):
            w = np.exp(-(dist[i, q] ** 2 - dist[i, 0] ** 2) / (2.0 * width[i] ** 2))
            j = nb[i, q]
            x, y = (at[j, 0] - query[i, 0]) / width[i], (at[j, 1] - query[i, 1]) / width[i]
            basis[0], basis[1], basis[2], basis[3], basis[4], basis[5] = 1.0, x, y, x * x, x * y, y * y
            for r in range(6):
                for c in range(6):
                    a[r, c] += w * basis[r] * basis[c]
                rhs[r, 0] += w * basis[r] * value[j, 0]
                rhs[r, 1] += w * basis[r] * value[j, 1]
        for r in range(1, 6):
            a[r, r] += 1e-6 * a[0, 0]
        sol = np.linalg.solve(a, rhs)
        out[i, 0], out[i, 1] = sol[0, 0], sol[0, 1]
    return out
