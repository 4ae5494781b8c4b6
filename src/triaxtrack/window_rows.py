"""One target's blob in its window (:mod:`triaxtrack.window`) on masks packed one row a word
(bit j: column j), for windows of at most 63 columns: the same masks, re-centring and sums as the
byte masks of :mod:`triaxtrack.window` give. A row's disc is the word of its pixels' distance
tests, a 3x3 dilation is three ORs of shifted words, and a row's ink and distance tests are each
a few vector instructions on the whole row, the sums over the words' pixels vectors kept over
the rows (:mod:`triaxtrack.window_lanes`). The sums are of integers, the same in any order: the
same results. The planes of words are indexed in place, and viewed only where the window's rows
are summed (compiled, as :func:`triaxtrack.window._measure_one`, without reference counts). Also
the valley between touching targets (:func:`valley`), which both kernels share. Compiled with
numba."""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np
from numba.core import types
from numba.core.extending import intrinsic

from triaxtrack.window_lanes import at_most, column_squares, pos_sums, row_sums, within

MEAN_SHIFT_STEPS = 3  # re-centring steps of the disc; motion left after prediction is sub-pixel
INK_NOISE_K = 3.5  # ink: darker than the white level by at least this x the noise (one-sided
# Gaussian tail 2e-4: a stray ink pixel in one window in about twenty, and it must touch the blob)
GROW_PX = 1  # the centroid's weights: the blob grown by this (other ink excluded), as detection
VALLEY_STEP_PX = 0.25  # the line between two touching targets is sampled this often for its valley
MAX_COLUMNS = 63  # the widest window whose rows fit a word (and a bit to shift into)
# the words of a window (rows of a (planes, n + 2) int64 array; rows 0 and n + 1 empty): ink, ink
# beyond doubt, the disc, the target's cell, the blob, its growth by one pixel and by GROW_PX, the
# other ink's growth, scratch (the weighted pixels, at last), the weighted pixels of positive contrast
_INK, _SURE, _DISC, _CELL, _BLOB, _NEAR, _GROWN, _FRINGE, _SPARE, _POS = range(10)
PLANES = 10
_U = np.uint64  # unsigned indices: numba leaves out the wrap-around of negative indices
_ONE = np.int64(1)


@numba.njit(cache=True, inline="always")
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


def _ctpop() -> Any:
    """A compiled function of one int64 word: the number of bits set in it (LLVM's ctpop)."""

    def typer(typingctx: Any, w: Any) -> Any:
        if w != types.int64:
            return None

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            return builder.ctpop(args[0])

        return types.int64(types.int64), codegen

    return intrinsic(typer)


_popcount = _ctpop()  # the number of bits set in a word


@numba.njit(cache=True, inline="always")
def _dilate(words: np.ndarray, src: int, dst: int, n: int) -> None:
    """Rows 1 .. n of plane ``dst`` of ``words`` = the 3x3 dilation of plane ``src`` (within the
    window). (Planes are indexed in place: a view of one would count references.)"""
    full = (_ONE << np.int64(n)) - _ONE
    for i in range(1, n + 1):
        v = words[src, i - 1] | words[src, i] | words[src, i + 1]
        words[dst, i] = (v | (v << _ONE) | (v >> _ONE)) & full


@numba.njit(cache=True, inline="always")
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


@numba.njit(cache=True, inline="always")
def blob_moments(
    cnt: int, white: float, sv: int, sx: int, svx: int, sy: int, svy: int,
    npx: int, ax: int, ax2: int, ay: int, ay2: int,
) -> tuple[float, float, float, float, float, float, float]:  # fmt: skip
    """A blob's summed contrast ``s``, contrast-weighted centroid (``cu``, ``cv``; as
    :func:`shifted_centre`, 0 where ``s`` is not positive) and, over its ``npx`` pixels, the sums
    of their offsets from it and of their squares across and down (``du, du2, dv, dv2``: from the
    sums of x and x squared ``ax``, ``ax2`` and of y ``ay``, ``ay2``), from its integer sums."""
    s = cnt * white - sv
    safe = s if s > 0 else 1.0
    cu, cv = (white * sx - svx) / safe, (white * sy - svy) / safe
    du, du2 = ax - npx * cu, ax2 - 2 * cu * ax + npx * cu * cu
    dv, dv2 = ay - npx * cv, ay2 - 2 * cv * ay + npx * cv * cv
    return s, cu, cv, du, du2, dv, dv2


@numba.njit(cache=True, inline="always")
def _mean_shift(wins: np.ndarray, at: int, n: int, words: np.ndarray, white: float, cx: float, cy: float,
                core: float, squares: np.ndarray) -> tuple[float, float]:  # fmt: skip
    """The contrast-weighted centre of the ink (plane ``_INK`` of ``words``) within ``core``
    (squared distance) of (cx, cy), re-centred ``MEAN_SHIFT_STEPS`` times (window-relative; it
    stays put where there is none; a step that does not move it ends the re-centring). The
    pixels a step takes (in plane ``_SPARE``): a step that takes those of the step before has
    their sums, so their centre, and ends the re-centring without summing them again. Sums of
    integers (exact, in any order): sum(w x) = W sum(x) - sum(v x). ``squares``: scratch
    (:func:`~triaxtrack.window_lanes.column_squares`)."""
    h = n // 2
    if not (np.isfinite(cx) and np.isfinite(cy)):
        return cx, cy  # no pixel is taken: it stays put
    for step in range(MEAN_SHIFT_STEPS):
        same, lo, hi = step > 0, n + 1, 0
        column_squares(n, h, cx, squares)
        for i in range(1, n + 1):
            dy = (i - 1 - h) - cy
            t = words[_INK, i] & within(n, squares, dy * dy, core)
            same &= t == words[_SPARE, i]
            words[_SPARE, i] = t
            if t:
                lo, hi = min(lo, i), i
        if same:  # the pixels of the step before: its centre again
            break
        cnt, sj, sy, sv, svj, svy = pos_sums(wins, words[_SPARE], at, n, lo, hi)
        sx, svx = sj - h * cnt, svj - h * sv  # x = j - h
        ux, uy = shifted_centre(cnt, white, sv, sx, svx, sy, svy)
        if cnt == 0 or (ux == cx and uy == cy):
            break
        cx, cy = ux, uy
    return cx, cy


@numba.njit(cache=True, inline="always")
def _grow(words: np.ndarray, n: int) -> tuple[int, int]:
    """The blob (plane ``_BLOB``): the ink within sqrt(2) of the centre (``_SPARE``: the seeds)
    dilated (3x3) within the ink in the disc until nothing changes. Returns its first and last
    rows (of 1 .. n; none: n + 1, 0)."""
    cur, nxt, start, changed = _SPARE, _BLOB, True, True
    while changed or start:  # the seeds themselves need not be in the room
        changed = False
        for i in range(1, n + 1):
            v = words[cur, i - 1] | words[cur, i] | words[cur, i + 1]
            words[nxt, i] = (v | (v << _ONE) | (v >> _ONE)) & words[_INK, i] & words[_DISC, i]
            changed |= words[nxt, i] != words[cur, i]
        cur, nxt, start = nxt, cur, False
    first, last = n + 1, 0
    for i in range(1, n + 1):
        words[_BLOB, i] = words[cur, i]
        if words[cur, i]:
            first, last = min(first, i), i
    return first, last


@numba.njit(cache=True, inline="always")
def measure_rows(wins: np.ndarray, at: int, n: int, darkest: int, sure_level: int, cx: float, cy: float,
                 rad: float, core: float, white: float, noise: float, nb: np.ndarray, ox: float, oy: float,
                 words: np.ndarray, squares: np.ndarray) -> tuple:  # fmt: skip
    """One target's blob in its ``n`` x ``n`` (padded) window at ``wins[at:]`` (n <= ``MAX_COLUMNS``)
    from the prediction (cx, cy) relative to its centre (``ox``, ``oy``), as
    :func:`triaxtrack.window._measure_one` finds it (ink: levels <= ``darkest``, beyond doubt <=
    ``sure_level``; the disc ``rad``, the mean shift's ``core``; ``words``: scratch, (``PLANES``,
    >= n + 2) int64, and ``squares``, float64 (64); ``wins`` readable ``SLACK`` bytes past its
    rows: :mod:`triaxtrack.window_lanes`):
    ``(runs on, ink outside the disc, area, summed contrast, centroid u, v,
    weighted pixels, sum(x - u), sum((x - u)^2), sum(y - v), sum((y - v)^2))`` (window-relative)."""
    h, stride = n // 2, n + 2
    for p in range(PLANES):  # the padding rows (rows 1 .. n are all written before they are read)
        words[p, 0] = words[p, n + 1] = 0
    full = (_ONE << np.int64(n)) - _ONE
    for i in range(1, n + 1):
        row = at + _U(i * stride + 1)
        words[_INK, i], words[_SURE, i] = at_most(wins, row, n, darkest), at_most(wins, row, n, sure_level)
        words[_CELL, i] = full
    for k in range(nb.shape[0]):  # the target's side of the valley to each touching target
        divides, vx, vy, dx, dy = valley(wins, at, stride, cx, cy, nb[k], ox, oy, noise)
        if divides:
            for i in range(n):
                y = (i - h) - vy
                for j in range(n):
                    if ((j - h) - vx) * dx + y * dy > 0:
                        words[_CELL, i + 1] &= ~(_ONE << np.int64(j))
    cx, cy = _mean_shift(wins, at, n, words, white, cx, cy, core, squares)
    r2 = rad * rad
    column_squares(n, h, cx, squares)
    for i in range(1, n + 1):  # the disc, and the seeds: the ink within sqrt(2) of the centre
        dy = (i - 1 - h) - cy
        words[_DISC, i] = within(n, squares, dy * dy, r2)
        words[_SPARE, i] = words[_INK, i] & within(n, squares, dy * dy, 2.0)
    first, last = _grow(words, n)
    _dilate(words, _BLOB, _NEAR, n)
    for i in range(n + 2):
        words[_GROWN, i] = words[_NEAR, i]
    for _ in range(GROW_PX - 1):
        for i in range(n + 2):
            words[_SPARE, i] = words[_GROWN, i]
        _dilate(words, _SPARE, _GROWN, n)
    for i in range(1, n + 1):
        words[_SPARE, i] = words[_INK, i] & ~words[_BLOB, i]
    _dilate(words, _SPARE, _FRINGE, n)
    runs = trunc = np.int64(0)
    area = 0
    below = int(math.ceil(white)) - 1  # the levels with a positive contrast
    lo, hi = max(first - GROW_PX - 1, 1), min(last + GROW_PX + 1, n)
    for i in range(lo, hi + 1):
        out = words[_NEAR, i] & ~words[_DISC, i] & words[_CELL, i]
        runs |= out & words[_SURE, i]
        trunc |= out & words[_INK, i]
        area += _popcount(words[_BLOB, i])
        w = words[_GROWN, i] & ~words[_FRINGE, i] & words[_CELL, i]  # the weighted pixels,
        words[_SPARE, i] = w  # and those with a positive contrast (their levels summed)
        words[_POS, i] = w & at_most(wins, at + _U(i * stride + 1), n, below) if w else w
    npx, sj, sj2, ay, ay2, cnt, pj, sy, sv, svj, svy = row_sums(
        wins, words[_SPARE], words[_POS], at, n, lo, hi
    )
    ax, ax2 = sj - h * npx, sj2 - 2 * h * sj + h * h * npx  # x = j - h
    sx, svx = pj - h * cnt, svj - h * sv
    s, cu, cv, du, du2, dv, dv2 = blob_moments(cnt, white, sv, sx, svx, sy, svy, npx, ax, ax2, ay, ay2)
    return runs != 0, trunc != 0, area, s, cu, cv, npx, du, du2, dv, dv2
