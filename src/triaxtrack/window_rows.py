"""One target's blob in its window (:mod:`triaxtrack.window`) on masks packed one row a word
(bit j: column j), for windows of at most 63 columns: the same masks, re-centring and sums as the
byte masks of :mod:`triaxtrack.window` give. Each row's disc is a run of columns found from its
ends, a 3x3 dilation is three ORs of shifted words, and the loops over a row's pixels (the mean
shift's, the weighted sums) have no branches, so that they run on whole vectors. The sums are of
integers, the same in any order: the same results. Also the valley between touching targets
(:func:`valley`), which both kernels share. Compiled with numba."""

from __future__ import annotations

import math

import numba
import numpy as np

MEAN_SHIFT_STEPS = 3  # re-centring steps of the disc; motion left after prediction is sub-pixel
INK_NOISE_K = 3.5  # ink: darker than the white level by at least this x the noise (one-sided
# Gaussian tail 2e-4: a stray ink pixel in one window in about twenty, and it must touch the blob)
GROW_PX = 1  # the centroid's weights: the blob grown by this (other ink excluded), as detection
VALLEY_STEP_PX = 0.25  # the line between two touching targets is sampled this often for its valley
MAX_COLUMNS = 63  # the widest window whose rows fit a word (and a bit to shift into)
# the words of a window (rows of a (planes, n + 2) int64 array; rows 0 and n + 1 empty): ink, ink
# beyond doubt, the disc, the target's cell, the blob, its growth by one pixel and by GROW_PX, the
# other ink's growth, scratch
_INK, _SURE, _DISC, _CELL, _BLOB, _NEAR, _GROWN, _FRINGE, _SPARE = range(9)
PLANES = 9
_U = np.uint64  # unsigned indices: numba leaves out the wrap-around of negative indices
_ONE = np.int64(1)


@numba.njit(cache=True)
def grey_at(wins: np.ndarray, at: int, stride: int, x: float, y: float) -> float:
    """The grey level of a (padded) window at ``wins[at:]`` at (x, y) relative to its centre,
    interpolated bilinearly between its pixels; -1 outside them."""
    n = stride - 2
    h = n // 2
    fx, fy = x + h, y + h
    j, i = int(math.floor(fx)), int(math.floor(fy))
    if j < 0 or i < 0 or j + 1 > n - 1 or i + 1 > n - 1:
        return -1.0
    a, b = fx - j, fy - i
    q = at + _U((i + 1) * stride + j + 1)
    v00, v01 = float(wins[q]), float(wins[q + _U(1)])
    v10, v11 = float(wins[q + _U(stride)]), float(wins[q + _U(stride + 1)])
    return (1 - b) * ((1 - a) * v00 + a * v01) + b * ((1 - a) * v10 + a * v11)


@numba.njit(cache=True)
def valley(wins: np.ndarray, at: int, stride: int, cx: float, cy: float, nbk: np.ndarray, ox: float,
           oy: float, noise: float) -> tuple[bool, float, float, float, float]:  # fmt: skip
    """Whether the touching target ``nbk`` (centre, less (``ox``, ``oy``) the window's centre, and
    radius; NaN: none) is apart from the target at (cx, cy) (:func:`triaxtrack.window._cell`),
    the valley point (vx, vy) and the direction (dx, dy) between the centres: the target's side
    of it is where ``(x - vx) dx + (y - vy) dy > 0`` is false."""
    if not np.isfinite(nbk[2]):
        return False, 0.0, 0.0, 0.0, 0.0
    dx, dy = nbk[0] - ox - cx, nbk[1] - oy - cy
    length = math.sqrt(dx * dx + dy * dy)
    steps = int(length / VALLEY_STEP_PX)
    if steps < 2:
        return False, 0.0, 0.0, 0.0, 0.0
    top, at_top, dark_before, dark_after = -1.0, -1, 256.0, 256.0
    for s in range(steps + 1):
        v = grey_at(wins, at, stride, cx + dx * s / steps, cy + dy * s / steps)
        if v < 0:
            break
        if v > top:  # the lightest so far: what came before it is on this side
            if at_top >= 0:
                dark_before = min(dark_before, dark_after, top)
            top, at_top, dark_after = v, s, 256.0
        else:
            dark_after = min(dark_after, v)
    if at_top <= 0 or top - max(dark_before, dark_after) < INK_NOISE_K * noise:
        return False, 0.0, 0.0, 0.0, 0.0  # no valley (or nothing seen beyond it): no division
    return True, cx + dx * at_top / steps, cy + dy * at_top / steps, dx, dy


@numba.njit(cache=True)
def _span(n: int, h: int, c: float, d2y: float, reach2: float) -> tuple[int, int]:
    """The columns j (0 .. n - 1) of a row with ``(j - h - c)^2 + d2y <= reach2`` (the same
    floating-point test as pixel by pixel: a run, as the left side grows away from ``c``), as
    (first, last); first > last: none."""
    if not d2y <= reach2:
        return 1, 0
    s = math.sqrt(reach2 - d2y)
    j0 = min(max(int(math.ceil(c + h - s)), 0), n - 1)
    j1 = min(max(int(math.floor(c + h + s)), 0), n - 1)
    while j0 > 0 and ((j0 - 1 - h) - c) * ((j0 - 1 - h) - c) + d2y <= reach2:
        j0 -= 1
    while j0 <= j1 and not ((j0 - h) - c) * ((j0 - h) - c) + d2y <= reach2:
        j0 += 1
    while j1 < n - 1 and ((j1 + 1 - h) - c) * ((j1 + 1 - h) - c) + d2y <= reach2:
        j1 += 1
    while j1 >= j0 and not ((j1 - h) - c) * ((j1 - h) - c) + d2y <= reach2:
        j1 -= 1
    return j0, j1


@numba.njit(cache=True)
def _bits(j0: int, j1: int) -> np.int64:
    """The word with bits j0 .. j1 set (none: 0)."""
    if j0 > j1:
        return np.int64(0)
    return ((_ONE << np.int64(j1 + 1)) - _ONE) ^ ((_ONE << np.int64(j0)) - _ONE)


@numba.njit(cache=True)
def _popcount(w: np.int64) -> int:
    """The number of bits set in ``w`` (>= 0)."""
    c = 0
    while w:
        w &= w - _ONE
        c += 1
    return c


@numba.njit(cache=True)
def _dilate(src: np.ndarray, dst: np.ndarray, n: int) -> None:
    """Rows 1 .. n of ``dst`` = the 3x3 dilation of the rows of ``src`` (within the window)."""
    full = (_ONE << np.int64(n)) - _ONE
    for i in range(1, n + 1):
        v = src[i - 1] | src[i] | src[i + 1]
        dst[i] = (v | (v << _ONE) | (v >> _ONE)) & full


@numba.njit(cache=True)
def shifted_centre(
    cnt: int, white: float, sv: int, sx: int, svx: int, sy: int, svy: int
) -> tuple[float, float]:
    """A mean shift's next centre from its integer sums over the ``cnt`` pixels taken (levels
    ``v``, offsets ``x``, ``y``): the contrast-weighted centre, sum(w x) / sum(w) with w = white
    - v, as sum(w x) = W sum(x) - sum(v x); NaN where no pixel was taken."""
    if cnt == 0:
        return np.nan, np.nan
    s = cnt * white - sv
    return (white * sx - svx) / s, (white * sy - svy) / s


@numba.njit(cache=True)
def _mean_shift(wins: np.ndarray, at: int, n: int, darkest: int, white: float, cx: float, cy: float,
                core: float) -> tuple[float, float]:  # fmt: skip
    """The contrast-weighted centre of the ink (levels <= ``darkest``) within ``core`` (squared
    distance) of (cx, cy),
    re-centred ``MEAN_SHIFT_STEPS`` times (window-relative; it stays put where there is none; a
    step that does not move it ends the re-centring). Sums of integers: sum(w x) = W sum(x) -
    sum(v x)."""
    h, stride = n // 2, n + 2
    for _ in range(MEAN_SHIFT_STEPS):
        cnt = sv = sx = svx = sy = svy = 0
        for i in range(n):
            dy = (i - h) - cy
            d2y = dy * dy
            if not d2y <= core:  # no pixel of the row is within it
                continue
            row, rc = at + _U((i + 1) * stride + 1), 0
            rv = rvx = rx = 0
            for j in range(n):  # the whole row, without branches (vectorised)
                v, dx = np.int64(wins[row + _U(j)]), (j - h) - cx
                take, x = np.int64(v <= darkest) & np.int64(dx * dx + d2y <= core), np.int64(j - h)
                rc, rv, rx, rvx = rc + take, rv + take * v, rx + take * x, rvx + take * v * x
            y = np.int64(i - h)
            cnt, sv, sx, svx, sy, svy = cnt + rc, sv + rv, sx + rx, svx + rvx, sy + rc * y, svy + rv * y
        ux, uy = shifted_centre(cnt, white, sv, sx, svx, sy, svy)
        if cnt == 0 or (ux == cx and uy == cy):
            break
        cx, cy = ux, uy
    return cx, cy


@numba.njit(cache=True)
def _grow(words: np.ndarray, n: int) -> tuple[int, int]:
    """The blob (``_BLOB``): the ink within sqrt(2) of the centre (``_SPARE``: the seeds) dilated
    (3x3) within the ink in the disc until nothing changes. Returns its first and last rows (of
    1 .. n; none: n + 1, 0)."""
    ink, disc, cur, nxt = words[_INK], words[_DISC], words[_SPARE], words[_BLOB]
    start, changed = True, True
    while changed or start:  # the seeds themselves need not be in the room
        changed = False
        for i in range(1, n + 1):
            v = cur[i - 1] | cur[i] | cur[i + 1]
            nxt[i] = (v | (v << _ONE) | (v >> _ONE)) & ink[i] & disc[i]
            changed |= nxt[i] != cur[i]
        cur, nxt, start = nxt, cur, False
    blob, first, last = words[_BLOB], n + 1, 0
    for i in range(1, n + 1):
        blob[i] = cur[i]
        if cur[i]:
            first, last = min(first, i), i
    return first, last


@numba.njit(cache=True)
def measure_rows(wins: np.ndarray, at: int, n: int, darkest: int, sure_level: int, cx: float, cy: float,
                 rad: float, core: float, white: float, noise: float, nb: np.ndarray, ox: float, oy: float,
                 words: np.ndarray) -> tuple:  # fmt: skip
    """One target's blob in its ``n`` x ``n`` (padded) window at ``wins[at:]`` (n <= ``MAX_COLUMNS``)
    from the prediction (cx, cy) relative to its centre (``ox``, ``oy``), as
    :func:`triaxtrack.window._measure_one` finds it (ink: levels <= ``darkest``, beyond doubt <=
    ``sure_level``; the disc ``rad``, the mean shift's ``core``; ``words``: scratch, (``PLANES``,
    >= n + 2) int64): ``(runs on, ink outside the disc, area, summed contrast, centroid u, v,
    weighted pixels, sum(x - u), sum((x - u)^2), sum(y - v), sum((y - v)^2))`` (window-relative)."""
    h, stride = n // 2, n + 2
    words[:, : n + 2] = 0
    ink, sure, disc, cell = words[_INK], words[_SURE], words[_DISC], words[_CELL]
    full = (_ONE << np.int64(n)) - _ONE
    for i in range(1, n + 1):
        row, a, b = at + _U(i * stride + 1), np.int64(0), np.int64(0)
        for j in range(n):
            v = wins[row + _U(j)]
            a |= np.int64(v <= darkest) << np.int64(j)
            b |= np.int64(v <= sure_level) << np.int64(j)
        ink[i], sure[i], cell[i] = a, b, full
    for k in range(nb.shape[0]):  # the target's side of the valley to each touching target
        divides, vx, vy, dx, dy = valley(wins, at, stride, cx, cy, nb[k], ox, oy, noise)
        if divides:
            for i in range(n):
                y = (i - h) - vy
                for j in range(n):
                    if ((j - h) - vx) * dx + y * dy > 0:
                        cell[i + 1] &= ~(_ONE << np.int64(j))
    cx, cy = _mean_shift(wins, at, n, darkest, white, cx, cy, core)
    seed, r2 = words[_SPARE], rad * rad
    for i in range(n):
        dy = (i - h) - cy
        j0, j1 = _span(n, h, cx, dy * dy, r2)
        disc[i + 1] = _bits(j0, j1)
        j0, j1 = _span(n, h, cx, dy * dy, 2.0)
        seed[i + 1] = ink[i + 1] & _bits(j0, j1)
    first, last = _grow(words, n)
    blob, near, grown = words[_BLOB], words[_NEAR], words[_GROWN]
    fringe, spare = words[_FRINGE], words[_SPARE]
    _dilate(blob, near, n)
    grown[: n + 2] = near[: n + 2]
    for _ in range(GROW_PX - 1):
        spare[: n + 2] = grown[: n + 2]
        _dilate(spare, grown, n)
    for i in range(1, n + 1):
        spare[i] = ink[i] & ~blob[i]
    _dilate(spare, fringe, n)
    runs = trunc = np.int64(0)
    area = cnt = sv = sx = svx = sy = svy = npx = ax = ax2 = ay = ay2 = 0
    below = int(math.ceil(white)) - 1  # the levels with a positive contrast
    for i in range(max(first - GROW_PX - 1, 1), min(last + GROW_PX + 1, n) + 1):
        out = near[i] & ~disc[i] & cell[i]
        runs |= out & sure[i]
        trunc |= out & ink[i]
        area += _popcount(blob[i])
        w = grown[i] & ~fringe[i] & cell[i]
        row, y = at + _U(i * stride + 1), np.int64(i - 1 - h)
        rn = rx = rx2 = rc = rv = rpx = rvx = 0
        for j in range(n if w else 0):  # the whole row, without branches (vectorised)
            v, x, use = np.int64(wins[row + _U(j)]), np.int64(j - h), (w >> np.int64(j)) & _ONE
            pos = use * np.int64(v <= below)
            rn, rx, rx2 = rn + use, rx + use * x, rx2 + use * x * x
            rc, rv, rpx, rvx = rc + pos, rv + pos * v, rpx + pos * x, rvx + pos * v * x
        npx, ax, ax2, ay, ay2 = npx + rn, ax + rx, ax2 + rx2, ay + rn * y, ay2 + rn * y * y
        cnt, sv, sx, svx, sy, svy = cnt + rc, sv + rv, sx + rpx, svx + rvx, sy + rc * y, svy + rv * y
    s = cnt * white - sv
    safe = s if s > 0 else 1.0
    cu, cv = (white * sx - svx) / safe, (white * sy - svy) / safe
    # offsets from the centroid: sum(x - c) and sum((x - c)^2) from sums of x and x^2
    du, du2 = ax - npx * cu, ax2 - 2 * cu * ax + npx * cu * cu
    dv, dv2 = ay - npx * cv, ay2 - 2 * cv * ay + npx * cv * cv
    return runs != 0, trunc != 0, area, s, cu, cv, npx, du, du2, dv, dv2
