"""A tracking window's white level and noise (:mod:`triaxtrack.window`), exactly from its
grey-level histograms: one pass copies the window out of the frame and counts its levels
(:func:`copy_window`), then the white level is the mean of the levels between the window's
``WHITE_BAND`` percentiles and the noise ``MAD_TO_SIGMA`` x the median deviation above it of the
annulus's levels over ``ABOVE_WHITE_SPREAD`` (:func:`levels`). Percentiles and the median are
numpy's (method 'linear'), found by scanning the 256 bins. Compiled with numba."""

from __future__ import annotations

import math

import numba
import numpy as np

from triaxtrack.window_lanes import copy_row, lanes_of
from triaxtrack.window_rows import MAX_COLUMNS

QUANTISATION_NOISE = 1 / np.sqrt(12)  # grey levels: the noise floor of an 8-bit frame
MAD_TO_SIGMA = 1.4826  # median absolute deviation to standard deviation (normal noise)
WHITE_BAND = (70.0, 90.0)  # the white level's percentiles (dots cover well under 30 % of a window)
# the annulus's spread above the white level over the pixel noise: 0.647 for the half of normal
# noise above its mean (the trimmed white level sits a little above the surface's mean, and the
# dots' fringes widen the spread: noise 4 reads 5.2 on blurred synthetic dots, an overestimate)
ABOVE_WHITE_SPREAD = 0.647
_U = np.uint64  # unsigned indices (numba then leaves out the wrap-around of negative ones)


@numba.njit(cache=True, inline="always")
def _count(hist: np.ndarray, v: int) -> int:
    """The window's pixels of level ``v`` (its four histograms: :func:`copy_window`)."""
    return hist[v] + hist[v + 256] + hist[v + 512] + hist[v + 768]


@numba.njit(cache=True, inline="always")
def _largest(hist: np.ndarray, k: int, top: int) -> tuple[int, int]:
    """The ``k``-th and ``k + 1``-th largest (from 0) grey levels of the annulus (its two
    histograms: :func:`copy_window`), none of them above ``top``."""
    seen, first = 0, -1
    for v in range(top, -1, -1):
        seen += hist[512 + v] + hist[768 + v]
        if first < 0 and seen > k:
            first = v
        if seen > k + 1:
            return first, v
    return max(first, 0), 0


@numba.njit(cache=True, inline="always")
def _lerp(a: float, b: float, gamma: float) -> float:
    """numpy.percentile's linear interpolation (the same rounding)."""
    return b - (b - a) * (1 - gamma) if gamma >= 0.5 else a + (b - a) * gamma


@numba.njit(cache=True, inline="always")
def _white_band(hist: np.ndarray, count: int, top: int) -> tuple[float, float]:
    """numpy.percentile's (method 'linear') ``WHITE_BAND`` percentiles of the ``count`` >= 2 levels
    of the window's histograms (:func:`copy_window`), in one scan down from ``top``, the brightest."""
    at_lo, at_hi = (count - 1) * (WHITE_BAND[0] / 100.0), (count - 1) * (WHITE_BAND[1] / 100.0)
    k_hi, k_lo = count - 2 - int(math.floor(at_hi)), count - 2 - int(math.floor(at_lo))  # from the top
    seen, v_hi, v_hi1, v_lo = 0, -1, -1, -1
    for v in range(top, -1, -1):
        seen += _count(hist, v)
        if v_hi < 0 and seen > k_hi:
            v_hi = v
        if v_hi1 < 0 and seen > k_hi + 1:
            v_hi1 = v
        if v_lo < 0 and seen > k_lo:
            v_lo = v
        if seen > k_lo + 1:  # the sorted levels' floor(at)-th is the (count - 1 - floor(at))-th from the top
            return (_lerp(v, v_lo, at_lo - math.floor(at_lo)),
                    _lerp(v_hi1, v_hi, at_hi - math.floor(at_hi)))  # fmt: skip
    return 0.0, 0.0


@numba.njit(cache=True, inline="always")
def _inner_columns(ring_r2: float, h: int, inner: np.ndarray) -> None:
    """``inner[d]`` for d = 0..h: the largest column offset c >= 0 with c^2 + d^2 <= ``ring_r2``
    (-1: none), from the centre row out (each row's is at most the one before)."""
    c = int(math.sqrt(ring_r2)) if ring_r2 >= 0 else -1
    while (c + 1) * (c + 1) <= ring_r2:
        c += 1
    for d in range(h + 1):
        while c >= 0 and c * c + d * d > ring_r2:
            c -= 1
        inner[d] = c


@numba.njit(cache=True, inline="always")
def copy_window(
    g: np.ndarray, y0: int, x0: int, n: int, ring_r2: float, hist: np.ndarray, wins: np.ndarray, at: int,
    inner: np.ndarray,
) -> int:  # fmt: skip
    """Copy the ``n`` x ``n`` window at (``x0``, ``y0``) of the frame ``g`` into ``wins`` from
    ``at`` (padded: :func:`_geometry`; the padding 255 where the window is wider than
    ``MAX_COLUMNS``, measured on byte masks: a packed row's words hold no padding, and its rows
    are copied as whole vectors, bytes past them overwritten by the next) and count its levels in
    ``hist`` (1024): the pixels within ``ring_r2`` (squared distance from the centre) and those of
    the annulus beyond it, each in two histograms interleaved by column (a run of one level does
    not wait on itself); ``inner``: scratch for :func:`_inner_columns`. Returns the window's
    brightest level: the scans of :func:`levels` start there, not at 255 (the surface of a test
    is some way below it, and the bins above are empty)."""
    for v in range(1024):
        hist[v] = 0
    h, stride = n // 2, _U(n + 2)
    _inner_columns(ring_r2, h, inner)
    packed = n <= MAX_COLUMNS
    if not packed:
        for q in range(stride * stride):
            wins[at + q] = 255
    # a row as one vector where its lanes can be read: within the frame's data (rows in order)
    s0, lanes = g.strides[0], lanes_of(n)
    vectors = packed and g.strides[1] == 1 and s0 > 0
    end = (g.shape[0] - 1) * s0 + g.shape[1]  # one past the frame's last byte
    top = 0
    for i in range(n):
        y, row = y0 + i, at + _U(i + 1) * stride + _U(1)
        if vectors and y * s0 + x0 + lanes <= end:
            top = max(top, copy_row(g, y * s0 + x0, wins, row, n))
        else:
            for j in range(_U(n)):
                v = g[_U(y), _U(x0) + j]
                wins[row + j] = v
                top = max(top, v)
        c = inner[abs(i - h)]  # the annulus: the columns farther than this from the centre's
        left, right = (h - c, h + c + 1) if c >= 0 else (n, n)
        # (counted from the frame: a byte of the copy just stored as part of a vector would wait)
        yy, xx = _U(y), _U(x0)
        for j in range(_U(left)):
            hist[_U(512) + ((j & _U(1)) << _U(8)) + _U(g[yy, xx + j])] += 1
        for j in range(_U(left), _U(right)):
            hist[((j & _U(1)) << _U(8)) + _U(g[yy, xx + j])] += 1
        for j in range(_U(right), _U(n)):
            hist[_U(512) + ((j & _U(1)) << _U(8)) + _U(g[yy, xx + j])] += 1
    return int(top)


@numba.njit(cache=True, inline="always")
def levels(hist: np.ndarray, n: int, top: int) -> tuple[float, float, float]:
    """The white level, noise (before it is held to the frame's) and the white level's
    uncertainty (module docstring) of an ``n`` x ``n`` window from its histograms (:func:`copy_window`),
    ``top`` its brightest level: exact percentiles and median."""
    lo, hi = _white_band(hist, n * n, top)
    total = band = 0
    for v in range(int(math.ceil(lo)), int(math.floor(hi)) + 1):
        total += v * _count(hist, v)
        band += _count(hist, v)
    white = total / max(band, 1)
    cnt = 0  # the annulus's levels >= white, and the median of (level - white) over them
    for v in range(int(math.ceil(white)), top + 1):
        cnt += hist[512 + v] + hist[768 + v]
    noise = 0.0
    if cnt > 0:
        hi_v, lo_v = _largest(hist, cnt - 1 - cnt // 2, top)  # sorted: (cnt - 1) // 2-th, next
        lo_v = lo_v if cnt % 2 == 0 else hi_v
        noise = MAD_TO_SIGMA * (((lo_v - white) + (hi_v - white)) / 2) / ABOVE_WHITE_SPREAD
    noise = max(noise, QUANTISATION_NOISE)
    return white, noise, noise / math.sqrt(max(band, 3))
