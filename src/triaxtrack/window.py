"""Per-target window measurement for tracking (``triaxtrack.track``): the dark blob nearest a
predicted position, measured against the window's own white level and noise.

In a square window around each prediction (half-width the disc's radius rounded up, plus 2):

* the **white level** ``W`` is the mean of the window's pixels between its 70th and 90th
  percentiles (the surface around the dot: dots cover well under 30 % of a window), and the
  **noise** ``sigma`` 1.4826 x the median deviation above ``W`` of the annulus's pixels (those
  farther than the blob's disc plus one pixel from the window centre), held between the frame's
  noise (the median over its windows: a codec flattens some) and ``STRUCTURE_K`` times it (the
  dark beyond an edge fills others), at least the 8-bit quantisation noise;
* a pixel is **ink** when its contrast ``W - grey`` exceeds ``ink_fraction`` x ``W`` and
  ``INK_NOISE_K`` x ``sigma``: both scale with a uniform change of brightness, unlike a fixed
  number of grey levels;
* the blob is the ink at the mean-shifted centre grown through connected ink within its disc;
  its **centroid** is contrast-weighted over the blob grown by one pixel (other ink excluded);
  it is 'merged' where that growth meets ink beyond doubt outside the disc;
* **a dot larger than its disc**: a clean blob whose growth meets ink outside its disc is
  measured again in a disc ``TRUNCATED_GROW_PX`` wider (in its cell among the targets whose
  discs then overlap), and kept so where the whole blob lies in it, clear of other ink (in its
  own disc its ink beyond the disc counted as other ink, whose fringe was kept out of the
  weights: a centroid pulled towards the disc's centre);
* **touching targets**: a merged blob is measured again in its cell among the targets given
  whose discs overlap its own (up to ``TOUCH_MAX``): the side of the valley between it and each
  of them, the line across theirs through the lightest point between the two centres, where
  that point is lighter than the darkest on both sides by ``INK_NOISE_K`` x the noise (a saddle:
  two dots). The run-on and the weights count only in the cell, so two dots whose blurred images
  touch (compressed rows on soft footage) are each measured on their side, and a blob that runs
  on into ink that is no target's (an edge, a band), or with no valley, stays 'merged';
* its **normalised mass** ``m = sum(W - grey) / W`` over those pixels (in pixels: the area of an
  equally dark fully black dot) does not change when the whole window is brightened or dimmed;
  its standard uncertainty propagated from the pixel noise and the white level's is
  ``sigma_m^2 = n sigma^2 / W^2 + ((n - m) / W)^2 sigma_W^2`` (n pixels summed; ``sigma_W``
  the white level's uncertainty, ``sigma / sqrt(pixels averaged)``);
* the **centroid uncertainty** per axis, for ``c = sum(w x) / sum(w)`` with ``w = W - grey``:
  ``sigma_c^2 = (sigma^2 sum((x - c)^2) + sigma_W^2 (sum(x - c))^2) / (sum w)^2``, scaled by
  ``SIGMA_CALIBRATION`` (measured); ``sigma_px`` is the RMS of the two axes' (the standard
  uncertainty of either coordinate).

Pixels in OpenCV's convention (the centre of the top-left pixel is (0, 0)); grey levels of the
8-bit frame.

The measurement is a compiled kernel (numba; compiled once and cached on disk, so the first
call in a new environment takes some seconds): one pass over each window copies it out of the
frame and counts its levels in 256-bin histograms (the percentiles and the median are exact, as
numpy's: :mod:`triaxtrack.window_levels`); then per window, on byte masks padded by a pixel
all round (a 3x3 dilation is an OR of shifts) or on rows packed into words for the blob growing,
with the sums of integers where the weights are ``W - grey`` (``sum(w x) = W sum(x) -
sum(grey x)``).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba
import numpy as np
from numba.core.cpu import CPUTargetOptions

from triaxtrack.nearest import overlapping_discs
from triaxtrack.window_lanes import SLACK, prefetch
from triaxtrack.window_levels import QUANTISATION_NOISE, copy_window, levels
from triaxtrack.window_rows import (
    GROW_PX,
    INK_NOISE_K,
    MAX_COLUMNS,
    MEAN_SHIFT_STEPS,
    PLANES,
    blob_moments,
    measure_rows,
    shifted_centre,
    valley,
)

ANNULUS_GAP_PX = 1.0  # the annulus starts this far beyond the disc (the blob's blurred fringe)
# The centroid's uncertainty propagated from the pixel noise misses the noise of which pixels
# cross the ink threshold at a blurred edge: on blurred, noisy synthetic dots (5-8 px, blur 1 px,
# noise 4, read as 5.2; tests/test_track.py) the RMS of error / propagated sigma is 1.55, so the
# propagated sigma is scaled by that
SIGMA_CALIBRATION = 1.55
STRUCTURE_K = 3.0  # a window's spread above this x the frame's noise is structure, not noise
MIN_WHITE = 10.0  # grey levels: a window whose white is darker is under-exposed (a blank or
# black frame): its noise is clipped at black, so no dot can be told from it ('lost')


class WindowMeasure(NamedTuple):
    """Per target (N rows): what :func:`measure_windows` found; NaN/0 where ``reason`` != ''."""

    uv: np.ndarray  # (N, 2) contrast-weighted centroid, pixels
    area: np.ndarray  # (N,) the blob's ink area, pixels
    mass: np.ndarray  # (N,) normalised mass: summed contrast / white level, pixels
    sigma_mass: np.ndarray  # (N,) its standard uncertainty from the pixel noise, pixels
    sigma_px: np.ndarray  # (N,) standard uncertainty of each centroid coordinate, pixels
    white: np.ndarray  # (N,) the window's white level, grey levels
    noise: np.ndarray  # (N,) the window's pixel noise (standard deviation), grey levels
    code: np.ndarray  # (N,) int: the reason's index in REASON_CODES (0: '')
    divided: np.ndarray  # (N,) bool: measured in its cell, apart from a touching target

    @property
    def reason(self) -> np.ndarray:
        """(N,) object: '', 'edge', 'lost' or 'merged'."""
        return REASON_CODES[self.code]


REASON_CODES = np.array(["", "edge", "lost", "merged"], dtype=object)  # the kernel's reason codes
MERGED = list(REASON_CODES).index("merged")  # its code
# A blob that runs on beyond its disc is measured again in its cell among the targets whose
# discs overlap its own (at most this many, the nearest): touching dots are cut at their valley
TOUCH_MAX = 6
# A clean blob whose 1-pixel growth meets ink (not beyond doubt) outside its disc may go on beyond
# it (a soft dot larger than its disc: its thresholded area at identification undersizes it, and
# a dot's image grows as the specimen bulges towards a camera): it is measured again, from its
# centroid, in a disc this much wider (in its cell among the targets whose discs then overlap its
# own, as touching dots are), and kept so where its growth there meets no ink outside that disc
# (the whole dot); else it keeps its first measurement. A blob that runs on into ink beyond doubt
# stays 'merged' (it may be two dots, one of them not followed). (At 2 % strain, 1080p, a 6 px
# tall dot followed in a 2.7 px disc was read 1.1 px off, each frame's prediction lagging the
# last: a swap. Two steps took in a pedestal's face at 10 % strain, 720p, from a dot beside it:
# labels and tracks 1.1-1.9 px off.)
TRUNCATED_GROW_PX = 1.0  # once (the blur's reach: a blob larger still is no one dot)
_TRUNCATED = len(REASON_CODES)  # the kernel's code for such a blob (clean, measured as far as the disc)
_U = np.uint64  # unsigned indices: numba leaves out the wrap-around of negative indices, which
# would keep the loops from running on whole vectors
# The per-window loops are compiled without the runtime's reference counts (numba's option _nrt,
# not in its type stubs): they make no array, and every array they are given or view would
# otherwise be counted up and down, atomically, for every window (a tenth of the kernel's time).
# The option is numba's own, not a public one: a numba without it compiles them counted (the
# same results, slower) rather than failing at import
_UNCOUNTED: dict[str, Any] = {"cache": True, **({"_nrt": False} if hasattr(CPUTargetOptions, "_nrt") else {})}


@numba.njit(cache=True)
def _last_darker(white: float, level: float) -> int:
    """The largest grey level v (-1: none) with ``white - v > level``."""
    v = min(max(int(math.floor(white - level)), -1), 255)
    while v >= 0 and not white - v > level:
        v -= 1
    while v < 255 and white - (v + 1) > level:
        v += 1
    return v


@numba.njit(cache=True)
def _geometry(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An ``n`` x ``n`` window as a flat array padded by one pixel all round (row stride n + 2;
    pixel (i, j) at (i + 1) (n + 2) + j + 1), so that a 3x3 dilation is an OR of shifts: each
    entry's column and row offsets from the centre (float, far away in the padding; and int, 0
    there) and whether it is a pixel of the window."""
    stride, h = n + 2, n // 2
    xy = np.full((2, stride * stride), 1e9)
    off = np.zeros((2, stride * stride), np.int64)
    real = np.zeros(stride * stride, np.uint8)
    for i in range(n):
        for j in range(n):
            p = (i + 1) * stride + j + 1
            xy[0, p], xy[1, p], off[0, p], off[1, p], real[p] = j - h, i - h, j - h, i - h, 1
    return xy, off, real


@numba.njit(cache=True)
def _flat_rows(c: float, reach: float, stride: int) -> range:
    """The entries of a padded window (:func:`_geometry`) in the rows within ``reach`` of row
    offset ``c`` from the centre (and a row more either side)."""
    h, size = (stride - 2) // 2, stride * stride
    first = max(int(math.floor(c - reach)) + h, 0) * stride
    return range(_U(first), _U(min((int(math.ceil(c + reach)) + h + 3) * stride, size)))


# the masks of a window (rows of a (planes, entries) array; padded: :func:`_geometry`): ink,
# ink beyond doubt, the disc, where the blob may grow (ink in the disc), the seeds, the blob,
# its growth by one pixel and by GROW_PX (and a spare), the other ink and its 3x3 growth, the
# window's pixels, and the target's cell (its side of the valley to each touching target:
# :func:`_cell`; the whole window when none touches)
_INK, _SURE, _DISC, _ROOM, _SEED, _BLOB, _NEAR, _GROWN, _OTHER, _FRINGE, _REAL, _CELL = range(12)
_PLANES = 12


@numba.njit(cache=True)
def _mean_shift(wins: np.ndarray, at: int, m: np.ndarray, xy: np.ndarray, off: np.ndarray, white: float,
                cx: float, cy: float, core: float) -> tuple[float, float]:  # fmt: skip
    """The contrast-weighted centre of the ink (mask ``_INK``) within ``core`` (squared distance)
    of (cx, cy), re-centred ``MEAN_SHIFT_STEPS`` times (window-relative; it stays put where there
    is none; a step that does not move it ends the re-centring: the next ones would not either).
    The sums are of integers (exact): sum(w x) = W sum(x) - sum(v x)."""
    ink, stride = m[_INK], int(round(math.sqrt(xy.shape[1])))
    for _ in range(MEAN_SHIFT_STEPS):
        cnt = sv = sx = svx = sy = svy = 0
        for p in _flat_rows(cy, math.sqrt(core), stride):
            dx, dy = xy[0, p] - cx, xy[1, p] - cy
            take = np.int64(ink[p]) * np.int64(dx * dx + dy * dy <= core)
            v, x, y = np.int64(wins[at + _U(p)]), off[0, p], off[1, p]
            cnt, sv, sx, svx = cnt + take, sv + take * v, sx + take * x, svx + take * v * x
            sy, svy = sy + take * y, svy + take * v * y
        ux, uy = shifted_centre(cnt, white, sv, sx, svx, sy, svy)
        if cnt == 0 or (ux == cx and uy == cy):
            break
        cx, cy = ux, uy
    return cx, cy


@numba.njit(cache=True)
def _dilate(src: np.ndarray, dst: np.ndarray, within: np.ndarray, stride: int, first: int, last: int) -> None:
    """Mask ``dst`` = the 3x3 dilation of mask ``src`` within the mask ``within`` (padded windows,
    :func:`_geometry`) on rows ``first..last`` (of 1 .. n; the padding rows: 0)."""
    s, one = _U(stride), _U(1)
    for q in range(max(_U(first) * s, s + one), min(_U(last + 1) * s, s * s - s - one)):
        dst[q] = (src[q - s - one] | src[q - s] | src[q - s + one] | src[q - one] | src[q] | src[q + one]
                  | src[q + s - one] | src[q + s] | src[q + s + one]) & within[q]  # fmt: skip
    for q in range(s + one):  # the first and last rows are padding
        dst[q] = dst[s * s - one - q] = 0


@numba.njit(cache=True)
def _grow(m: np.ndarray, stride: int) -> tuple[int, int]:
    """The blob (mask ``_BLOB``): the seeds dilated (3x3) within ``_ROOM`` until nothing changes
    (the ink connected to them). Returns the first and last rows that may hold it: all."""
    size, n = stride * stride, stride - 2
    _dilate(m[_SEED], m[_BLOB], m[_ROOM], stride, 1, n)  # the seeds themselves need not be in the room
    while True:
        _dilate(m[_BLOB], m[_SEED], m[_ROOM], stride, 1, n)
        same = True
        for p in range(size):  # (no temporary arrays: compiled without the runtime's reference counts)
            same &= m[_SEED, p] == m[_BLOB, p]
            m[_BLOB, p] = m[_SEED, p]
        if same:
            return 1, n


@numba.njit(cache=True)
def _masks(wins: np.ndarray, at: int, xy: np.ndarray, sure_level: int, cx: float, cy: float, rad: float,
           m: np.ndarray) -> tuple[int, range]:  # fmt: skip
    """The masks (rows of ``m``) of one window from its ink (``_INK``): ink beyond doubt (levels
    <= ``sure_level``), the disc (``rad`` around (cx, cy)), the blob (the ink within sqrt(2) of
    the centre grown through connected (8-neighbour) ink within the disc), its growth by one pixel
    and by ``GROW_PX``, and the other ink's 3x3 growth (these three near the blob's rows only).
    Returns the mask that holds the blob grown by ``GROW_PX``, and the entries of the rows it
    can reach (and one more either side)."""
    size = xy.shape[1]
    stride = int(round(math.sqrt(size)))
    ink, sure, disc, room, seed = m[_INK], m[_SURE], m[_DISC], m[_ROOM], m[_SEED]
    r2 = rad * rad
    for p in range(size):
        sure[p] = wins[at + _U(p)] <= sure_level
        dx, dy = xy[0, p] - cx, xy[1, p] - cy
        d2 = dx * dx + dy * dy
        disc[p] = d2 <= r2
        room[p] = ink[p] & disc[p]
        seed[p] = ink[p] & (d2 <= 2.0)
    first, last = _grow(m, stride)
    blob, other = m[_BLOB], m[_OTHER]
    # each growth is right within GROW_PX + 1 rows of the blob's if worked out within 2 GROW_PX + 1
    lo, hi = max(first - 2 * GROW_PX - 1, 1), min(last + 2 * GROW_PX + 1, stride - 2)
    _dilate(blob, m[_NEAR], m[_REAL], stride, lo, hi)
    grown, spare = _NEAR, _GROWN
    for _ in range(GROW_PX - 1):
        _dilate(m[grown], m[spare], m[_REAL], stride, lo, hi)
        grown, spare = spare, grown
    for p in range(size):
        other[p] = ink[p] & ~blob[p]
    _dilate(other, m[_FRINGE], m[_REAL], stride, lo, hi)
    lo, hi = max(first - GROW_PX - 1, 1), min(last + GROW_PX + 1, stride - 2)
    return grown, range(_U(lo * stride), _U((hi + 1) * stride) if lo <= hi else _U(lo * stride))


@numba.njit(cache=True)
def _blob_sums(wins: np.ndarray, at: int, off: np.ndarray, m: np.ndarray, grown: int, entries: range,
               white: float) -> tuple:  # fmt: skip
    """From the masks of :func:`_masks` (the blob grown by ``GROW_PX`` in mask ``grown``, within
    ``entries``): whether the blob's 1-pixel growth meets ink beyond doubt outside the disc in the
    target's cell (it runs on: merged), and ink there (it may go on beyond the disc), its pixel
    count, and over the weighted pixels (the grown blob in the target's cell, less the other
    ink's fringe): the summed contrast ``w = W - v`` (0 where v >= W), the contrast-weighted
    centroid (window-relative), the pixel count and the sums of the pixels' offsets from the
    centroid and of their squares per axis."""
    near, sure, disc, blob, fringe, cell = m[_NEAR], m[_SURE], m[_DISC], m[_BLOB], m[_FRINGE], m[_CELL]
    weighted = m[grown]
    ink, runs, trunc = m[_INK], 0, 0
    area = cnt = sv = sx = svx = sy = svy = npx = ax = ax2 = ay = ay2 = 0
    below = int(math.ceil(white)) - 1  # the levels with a positive contrast
    for p in entries:
        runs |= near[p] & sure[p] & ~disc[p] & cell[p]
        trunc |= near[p] & ink[p] & ~disc[p] & cell[p]
        area += blob[p]
        use = np.int64(weighted[p] & ~fringe[p] & cell[p] & 1)
        v = np.int64(wins[at + _U(p)])
        pos, x, y = use * np.int64(v <= below), off[0, p], off[1, p]
        npx, ax, ax2, ay, ay2 = npx + use, ax + use * x, ax2 + use * x * x, ay + use * y, ay2 + use * y * y
        cnt, sv, sx, svx = cnt + pos, sv + pos * v, sx + pos * x, svx + pos * v * x
        sy, svy = sy + pos * y, svy + pos * v * y
    s, cu, cv, du, du2, dv, dv2 = blob_moments(cnt, white, sv, sx, svx, sy, svy, npx, ax, ax2, ay, ay2)
    return runs != 0, trunc != 0, area, s, cu, cv, npx, du, du2, dv, dv2


@numba.njit(cache=True)
def _cell(m: np.ndarray, wins: np.ndarray, at: int, xy: np.ndarray, cx: float, cy: float, nb: np.ndarray,
          ox: float, oy: float, noise: float) -> None:  # fmt: skip
    """Mask ``_CELL``: the window's entries on the target's side of the valley between it (at
    (cx, cy)) and each touching target in ``nb`` ((k, 3): centre, less (``ox``, ``oy``) the
    window's centre, and radius; NaN rows: none). The valley is the lightest point of the line
    between the two centres, sampled every ``VALLEY_STEP_PX``; it divides them (the line through
    it across theirs) where it is lighter by ``INK_NOISE_K`` x ``noise`` than the darkest point
    on either side of it, so two dots apart (a saddle between them), not one dot, an edge or a
    neighbour predicted onto this dot's own ink."""
    size = xy.shape[1]
    stride = int(round(math.sqrt(size)))
    cell = m[_CELL]
    cell[:size] = 1
    for k in range(nb.shape[0]):
        divides, vx, vy, dx, dy = valley(wins, at, stride, cx, cy, nb[k], ox, oy, noise)
        if divides:
            for p in range(size):
                if (xy[0, p] - vx) * dx + (xy[1, p] - vy) * dy > 0:
                    cell[p] = 0


@numba.njit(**_UNCOUNTED)
def _measure_one(wins: np.ndarray, at: int, xy: np.ndarray, off: np.ndarray, cx: float, cy: float, rad: float,
                 white: float, noise: float, s_white: float, ink_fraction: float, disc_margin: float,
                 m: np.ndarray, rows: np.ndarray, squares: np.ndarray, nball: np.ndarray, t: int, ox: float,
                 oy: float) -> tuple:  # fmt: skip
    """One target's blob in its (padded) window at ``wins[at:]`` from the prediction (cx, cy)
    relative to the window centre (``ox``, ``oy``; module docstring), weighted and run on in its
    cell among its touching targets ``nball[t]`` (:func:`_cell`; none: the whole window):
    ``(centroid u, v relative to the window centre, area, mass, sigma_mass, sigma_px, reason
    code)``. A window of at most ``MAX_COLUMNS`` columns is measured on its rows packed into
    words (:func:`triaxtrack.window_rows.measure_rows`, scratch ``rows`` and ``squares``), a wider
    one on the byte masks ``m`` (the same results)."""
    nb = nball[t]
    level = max(INK_NOISE_K * noise, ink_fraction * white)
    darkest, sure = _last_darker(white, level), _last_darker(white, level + INK_NOISE_K * noise)
    n, core = int(round(math.sqrt(xy.shape[1]))) - 2, (rad - disc_margin) ** 2
    if n <= MAX_COLUMNS:
        runs_on, trunc, area, s, cu, cv, npx, du, du2, dv, dv2 = measure_rows(
            wins, at, n, darkest, sure, cx, cy, rad, core, white, noise, nb, ox, oy, rows, squares
        )
    else:
        ink = m[_INK]
        _cell(m, wins, at, xy, cx, cy, nb, ox, oy, noise)
        for p in range(xy.shape[1]):
            ink[p] = wins[at + _U(p)] <= darkest
        cx, cy = _mean_shift(wins, at, m, xy, off, white, cx, cy, core)
        grown, entries = _masks(wins, at, xy, sure, cx, cy, rad, m)
        runs_on, trunc, area, s, cu, cv, npx, du, du2, dv, dv2 = _blob_sums(
            wins, at, off, m, grown, entries, white
        )
    safe = s if s > 0 else 1.0
    var_u = (noise**2 * du2 + s_white**2 * du**2) / safe**2
    var_v = (noise**2 * dv2 + s_white**2 * dv**2) / safe**2
    wl = max(white, MIN_WHITE)
    m_norm = s / wl
    var_m = npx * noise**2 / wl**2 + ((npx - m_norm) / wl) ** 2 * s_white**2
    area = area if white >= MIN_WHITE else 0
    code = 2 if area == 0 else (3 if runs_on else (_TRUNCATED if trunc else 0))
    return cu, cv, area, m_norm, math.sqrt(var_m), SIGMA_CALIBRATION * math.sqrt((var_u + var_v) / 2), code


@numba.njit(cache=True)
def _windows(shape: tuple, uv: np.ndarray, rad: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each target's window: half-width (the disc's radius rounded up, plus 2) and centre pixel
    (the prediction rounded), and the reason code: 0 (to measure), 1 'edge' (the window leaves
    the image; or a radius no window holds), 2 'lost' (no prediction or radius)."""
    n = len(uv)
    half, centre, code = np.zeros(n, np.int64), np.zeros((n, 2), np.int64), np.zeros(n, np.int64)
    for t in range(n):
        if not (np.isfinite(uv[t, 0]) and np.isfinite(uv[t, 1]) and np.isfinite(rad[t]) and rad[t] >= 0):
            code[t] = 2
            continue
        if max(abs(uv[t, 0]), abs(uv[t, 1]), rad[t]) >= 2.0**40:  # beyond any image
            code[t] = 1
            continue
        half[t] = int(math.ceil(rad[t])) + 2
        x, y = int(np.rint(uv[t, 0])), int(np.rint(uv[t, 1]))
        centre[t, 0], centre[t, 1] = x, y
        if min(x, y) - half[t] < 0 or x + half[t] >= shape[1] or y + half[t] >= shape[0]:
            code[t] = 1
    return half, centre, code


@numba.njit(**_UNCOUNTED)
def _copy_windows(g: np.ndarray, sel: np.ndarray, centre: np.ndarray, half: np.ndarray, sizes: np.ndarray,
                  start: np.ndarray, rad: np.ndarray, hist: np.ndarray, wins: np.ndarray, inner: np.ndarray,
                  white: np.ndarray, noise: np.ndarray, s_white: np.ndarray) -> None:  # fmt: skip
    """Each window ``sel[k]`` copied into ``wins`` from ``start[k]`` and its levels (white, noise
    and the white level's uncertainty) measured (compiled without the runtime's reference counts:
    no array is made or kept, and none is counted again for every window)."""
    for k in range(len(sel)):
        if k + 1 < len(sel):  # the next window's rows fetched while this one is counted (a 4K frame
            u = sel[k + 1]  # is larger than the caches, and its windows are not in memory order)
            ny, nx = centre[u, 1] - half[u], centre[u, 0] - half[u]
            for i in range(sizes[k + 1]):
                prefetch(g, (ny + i) * g.strides[0] + nx)
                prefetch(g, (ny + i) * g.strides[0] + nx + sizes[k + 1] - 1)
        t = sel[k]
        y0, x0, ring_r2 = centre[t, 1] - half[t], centre[t, 0] - half[t], (rad[t] + ANNULUS_GAP_PX) ** 2
        top = copy_window(g, y0, x0, sizes[k], ring_r2, hist, wins, _U(start[k]), inner)
        white[t], noise[t], s_white[t] = levels(hist, sizes[k], top)


@numba.njit(cache=True)
def _measure_all(g: np.ndarray, uv: np.ndarray, rad: np.ndarray, ink_fraction: float, disc_margin: float,
                 nb: np.ndarray, frame_noise: float) -> tuple:  # fmt: skip
    """:func:`measure_windows` (the reasons as codes: :data:`REASON_CODES`): the windows' levels
    first (the frame's noise is their median, unless ``frame_noise`` > 0 gives it), then the
    blobs, each in its cell among its touching targets ``nb`` ((N, k, 3): centre, radius; NaN
    rows: none; k may be 0). Also returns the frame's noise."""
    n = len(uv)
    half, centre, code = _windows(g.shape, uv, rad)
    sel = np.nonzero(code == 0)[0]
    m = len(sel)
    sizes = 2 * half[sel] + 1
    start = np.zeros(m + 1, np.int64)
    start[1:] = np.cumsum((sizes + 2) ** 2)
    # each window's pixels, copied once (the frame is large); a row is read as whole vector lanes
    wins = np.empty(start[-1] + SLACK, np.uint8)
    hist = np.empty(1024, np.int32)
    inner = np.empty(half.max() + 1 if n else 1, np.int64)
    white, noise, s_white = np.full(n, np.nan), np.full(n, np.nan), np.zeros(n)
    _copy_windows(g, sel, centre, half, sizes, start, rad, hist, wins, inner, white, noise, s_white)
    out = np.full((n, 2), np.nan), np.zeros(n), np.zeros(n), np.zeros(n), np.full(n, np.nan)
    if m == 0:
        return out + (white, noise, code, frame_noise)
    uv_out, area, mass, smass, spx = out
    if not frame_noise > 0:
        frame_noise = max(np.median(noise[sel]), QUANTISATION_NOISE)
    # the codec flattens some windows' white (their spread reads below the noise) and the dark
    # beyond an edge fills others' (far above it): each is held to the frame's noise
    noise[sel] = np.minimum(np.maximum(noise[sel], frame_noise), STRUCTURE_K * frame_noise)
    masks = np.zeros((_PLANES, (sizes.max() + 2) ** 2), np.uint8)
    words = np.zeros((PLANES, sizes.max() + 2), np.int64)
    squares = np.empty(64)
    xy, off, real = _geometry(0)
    for k in np.argsort(sizes):  # by size: one geometry for each
        t = sel[k]
        if xy.shape[1] != (sizes[k] + 2) ** 2:
            xy, off, real = _geometry(sizes[k])
            masks[_REAL, : len(real)] = real
        cx, cy = uv[t, 0] - centre[t, 0], uv[t, 1] - centre[t, 1]  # the prediction, window-relative
        cu, cv, area[t], mass[t], smass[t], sigma, code[t] = _measure_one(
            wins, _U(start[k]), xy, off, cx, cy, rad[t], white[t], noise[t], s_white[t], ink_fraction,
            disc_margin, masks, words, squares, nb, t, float(centre[t, 0]), float(centre[t, 1]))  # fmt: skip
        if code[t] == 0 or code[t] == _TRUNCATED:
            uv_out[t, 0], uv_out[t, 1], spx[t] = cu + centre[t, 0], cv + centre[t, 1], sigma
    return uv_out, area, mass, smass, spx, white, noise, code, frame_noise


def disc_radius(area_px: np.ndarray, roundness: np.ndarray, disc_margin_px: float) -> np.ndarray:
    """The disc that holds a blob of a thresholded ``area_px`` and ``roundness`` (minor over major
    axis): its semi-major axis ``sqrt(area / (pi roundness))`` (area at least 1 px, roundness
    held to 0.2-1) plus ``disc_margin_px``, pixels."""
    area = np.maximum(np.asarray(area_px, np.float64), 1.0)
    roundness = np.clip(np.asarray(roundness, np.float64), 0.2, 1.0)
    return np.sqrt(area / (np.pi * roundness)) + disc_margin_px


def measure_windows(
    gray: np.ndarray, uv_px: np.ndarray, radius_px: np.ndarray, ink_fraction: float, disc_margin_px: float
) -> WindowMeasure:
    """The dark blobs nearest (N, 2) predicted pixel positions (NaN rows: 'lost') in an 8-bit
    (H, W) frame.

    ``radius_px`` (N,): the disc that holds a blob (its semi-major axis plus ``disc_margin_px``).
    See the module docstring for the rule; ``reason`` is 'edge' where the window leaves the image,
    'lost' where there is no ink at the centre, 'merged' where the blob runs on beyond its disc
    (``code``: its index in :data:`REASON_CODES`, as the tracker keeps it).
    """
    g = np.asarray(gray).view()
    if g.dtype != np.uint8 or g.ndim != 2:
        raise TypeError(f"measure_windows: an 8-bit (H, W) frame expected, got {g.dtype} {g.shape}")
    g.flags.writeable = False  # as decoded frames are: one compiled kernel for both
    uv = np.ascontiguousarray(uv_px, np.float64).reshape(-1, 2)
    rad = np.ascontiguousarray(radius_px, np.float64).reshape(-1)
    ink_fraction, disc_margin_px = float(ink_fraction), float(disc_margin_px)
    none = np.empty((len(uv), 0, 3))  # no touching targets
    meas, frame_noise = _measure(g, uv, rad, ink_fraction, disc_margin_px, none, 0.0, False)
    grow = np.nonzero(meas.code == _TRUNCATED)[0]
    if len(grow):  # a dot larger than its disc: measured in a wider one, in its cell
        wider = rad.copy()
        wider[grow] += TRUNCATED_GROW_PX
        nb = overlapping_discs(uv, wider, grow, TOUCH_MAX)
        wide, _ = _measure(
            g, meas.uv[grow], wider[grow], ink_fraction, disc_margin_px, nb, frame_noise, False
        )
        meas = _taken(meas, grow, wide._replace(divided=np.isfinite(nb[:, :, 2]).any(axis=1)), wide.code == 0)
    meas = meas._replace(code=np.where(meas.code == _TRUNCATED, 0, meas.code))
    merged = np.nonzero(meas.code == MERGED)[0]
    if len(merged) == 0:
        return meas
    nb = overlapping_discs(uv, rad, merged, TOUCH_MAX)
    touching = np.isfinite(nb[:, :, 2]).any(axis=1)
    again, nb = merged[touching], nb[touching]
    if len(again) == 0:
        return meas
    cut, _ = _measure(g, uv[again], rad[again], ink_fraction, disc_margin_px, nb, frame_noise, True)
    cut = cut._replace(code=np.where(cut.code == _TRUNCATED, 0, cut.code))  # (in its cell: no wider disc)
    return _taken(meas, again, cut, cut.code == 0)


def _measure(
    g: np.ndarray, uv: np.ndarray, rad: np.ndarray, ink_fraction: float, disc_margin_px: float,
    nb: np.ndarray, frame_noise: float, divided: bool,
) -> tuple[WindowMeasure, float]:  # fmt: skip
    """:func:`_measure_all` as a :class:`WindowMeasure` (``divided`` for every row), and the
    frame's noise."""
    res = _measure_all(g, uv, rad, ink_fraction, disc_margin_px, nb, frame_noise)
    uv_out, area, mass, smass, spx, white, noise, code, frame_noise = res
    return WindowMeasure(
        uv_out, area, mass, smass, spx, white, noise, code, np.full(len(uv), divided)
    ), float(frame_noise)


def _taken(meas: WindowMeasure, rows: np.ndarray, again: WindowMeasure, take: np.ndarray) -> WindowMeasure:
    """``meas`` with the rows ``rows[take]`` from ``again`` (measured at ``rows``)."""
    return WindowMeasure(*(_put(a, rows[take], b[take]) for a, b in zip(meas, again, strict=True)))


def _put(a: np.ndarray, rows: np.ndarray, values: np.ndarray) -> np.ndarray:
    """A copy of ``a`` with ``values`` in ``rows``."""
    out = a.copy()
    out[rows] = values
    return out
