"""The window rows' vector kernels (triaxtrack.window_lanes) against the same tests and sums a
pixel at a time: every bit and sum equal, on rows of 1 to 63 columns (16, 32 and 64 lanes)."""

from __future__ import annotations

import numpy as np
import pytest

from triaxtrack.window_lanes import SLACK, at_most, column_squares, copy_row, pos_sums, row_sums, within

WIDTHS = [1, 2, 11, 15, 16, 17, 21, 31, 32, 33, 47, 63]


def _word(bits: np.ndarray) -> int:
    return int(sum(1 << j for j in np.flatnonzero(bits)))


@pytest.mark.parametrize("n", WIDTHS)
def test_at_most_is_the_word_of_each_pixels_compare(n):
    rng = np.random.default_rng(n)
    wins = rng.integers(0, 256, 300 + SLACK, dtype=np.uint8)
    wins[:20] = [0, 255] * 10  # the extremes, in the first rows read
    for row in (0, 7, 300 - n):
        pixels = wins[row : row + n].astype(int)
        for level in (-300, -1, 0, 1, 100, 127, 128, 200, 254, 255, 256, 1000):
            assert at_most(wins, np.uint64(row), n, level) == _word(pixels <= level), (row, level)


@pytest.mark.parametrize("n", WIDTHS)
def test_within_is_the_word_of_each_pixels_distance_test(n):
    rng = np.random.default_rng(100 + n)
    h = n // 2
    squares = np.full(64, -1.0)
    centres = [0.0, 0.5, -0.5, 1e-17, 0.25 - 1e-16, np.nan, 3 * n, *rng.uniform(-h - 2, h + 2, 20)]
    for c in centres:
        column_squares(n, h, float(c), squares)
        for _ in range(30):
            dy, reach2 = rng.uniform(-h - 1, h + 1), rng.choice([2.0, rng.uniform(0, (h + 1) ** 2)])
            if rng.random() < 0.2:  # a reach on a pixel's squared distance exactly
                j = int(rng.integers(n))
                reach2 = ((j - h) - c) ** 2 + dy * dy
            # the kernels' test a pixel at a time (Python's floats are the same doubles)
            expect = [((j - h) - c) * ((j - h) - c) + dy * dy <= reach2 for j in range(n)]
            assert within(n, squares, dy * dy, float(reach2)) == _word(np.array(expect)), (c, dy, reach2)


@pytest.mark.parametrize("n", WIDTHS)
def test_row_sums_over_a_windows_rows_and_each_rows_words(n):
    rng = np.random.default_rng(200 + n)
    stride, h = n + 2, n // 2
    wins = rng.integers(0, 256, 3 + stride * stride + SLACK, dtype=np.uint8)
    wins[3 + stride : 3 + 3 * stride] = 255  # the largest sums
    w = np.zeros(n + 2, np.int64)
    pos = np.zeros(n + 2, np.int64)
    for lo, hi in ((1, n), (2, n - 1), (n, n), (3, 2)):
        for i in range(1, n + 1):
            take = [np.ones(n, bool), np.zeros(n, bool), rng.random(n) < 0.5][i % 3]
            w[i], pos[i] = _word(take), _word(take & (rng.random(n) < 0.7))
        expect_w, expect_p = np.zeros(5, np.int64), np.zeros(6, np.int64)
        for i in range(lo, hi + 1):
            y, v = i - 1 - h, wins[3 + i * stride + 1 :][:n].astype(np.int64)
            jw = [j for j in range(n) if w[i] >> j & 1]
            jp = [j for j in range(n) if pos[i] >> j & 1]
            expect_w += [len(jw), sum(jw), sum(j * j for j in jw), y * len(jw), y * y * len(jw)]
            vp = v[jp]
            expect_p += [
                len(jp),
                sum(jp),
                y * len(jp),
                vp.sum(),
                (vp * np.array(jp, np.int64)).sum(),
                y * vp.sum(),
            ]
        got = row_sums(wins, w, pos, np.uint64(3), n, lo, hi)
        assert got == (*expect_w, *expect_p), (lo, hi)
        assert pos_sums(wins, pos, np.uint64(3), n, lo, hi) == tuple(expect_p), (lo, hi)


@pytest.mark.parametrize("n", WIDTHS)
def test_copy_row_copies_a_frame_rows_pixels_and_finds_their_largest(n):
    rng = np.random.default_rng(300 + n)
    frame = rng.integers(0, 200, (9, 150), dtype=np.uint8)
    frame[4, 70] = 255  # beyond the row copied from column 71 on: never its largest
    frame[3, 60] = 254
    for y, x in ((0, 0), (3, 60), (4, 71), (8, 150 - 64)):
        wins = np.full(100 + SLACK, 7, np.uint8)
        top = copy_row(frame, y * frame.strides[0] + x, wins, np.uint64(30), n)
        assert top == frame[y, x : x + n].max(), (y, x)
        assert (wins[30 : 30 + n] == frame[y, x : x + n]).all() and (wins[:30] == 7).all()
