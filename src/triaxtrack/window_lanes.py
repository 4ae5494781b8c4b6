"""A window row's pixels as one vector, for the packed rows of :mod:`triaxtrack.window_rows`:
LLVM's vector instructions through numba intrinsics, on rows of at most 63 columns held in 16,
32 or 64 lanes (the fewest that hold the row; a pixel loop over a row of ~20 columns runs mostly
in its scalar remainder, and a compare's result is then one bit a lane in a word at once):

* :func:`at_most`: the word of a row's pixels at most a grey level (the bytes compared at once);
* :func:`within`: the word of a row's pixels within a reach of a centre, from the squared
  column offsets of the centre (:func:`column_squares`, once per centre) plus the row's;
* :func:`row_sums` (and :func:`pos_sums`): over the rows of a window and the pixels of each
  row's words, the sums of 1, j, j^2, the row's y and y^2, the levels ``v``, ``v j`` and ``v y``,
  kept in the lanes over the rows and summed across them once (a row's sum across its lanes is a
  chain of shuffles: one per row was most of a blob's sums);
* :func:`copy_row`: a frame row's pixels copied into a window as one vector, and their largest
  (:mod:`triaxtrack.window_levels`), and :data:`prefetch`: a hint to fetch a frame's cache line
  (the next window's rows, while this one is counted: the frame is larger than the caches)

(``j``: the column, 0 at the row's first pixel; bit j of a word is column j). The sums are of
integers and the distance test the same floating-point operations as a pixel at a time (the
square, then the row's added, then the compare), so the results are the same bits.

A row is read as whole lanes from its first pixel: the window array must hold ``SLACK`` bytes
after the last window's last row; the lanes past the row are masked off (or out of the word).
Compiled with numba.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from llvmlite import ir  # type: ignore[import-untyped]  # (numba's code generator, installed with it)
from numba.core import cgutils, types
from numba.core.extending import intrinsic

SLACK = 64  # bytes readable after any row's start beyond the window array's own rows
_I32 = ir.IntType(32)


def _lanes(builder: Any, lanes: int) -> tuple:
    """Helpers for the codegen of one intrinsic on ``lanes`` lanes: the i32 vector type, a
    word's low bits as a lane mask, a vector's lanes summed (int64), a constant i32 vector, and
    a value in every lane of a vector type."""
    vi32 = ir.VectorType(_I32, lanes)

    def mask(word: Any) -> Any:
        bits = word if lanes == 64 else builder.trunc(word, ir.IntType(lanes))
        return builder.bitcast(bits, ir.VectorType(ir.IntType(1), lanes))

    def total(vec: Any) -> Any:
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(_I32, [vi32]), f"llvm.vector.reduce.add.v{lanes}i32"
        )
        return builder.sext(builder.call(fn, [vec]), ir.IntType(64))

    def const(values: Any) -> Any:
        return ir.Constant(vi32, [ir.Constant(_I32, int(x)) for x in values])

    def splat(value: Any, vty: Any) -> Any:
        one = builder.insert_element(ir.Constant(vty, None), value, ir.Constant(_I32, 0))
        return builder.shuffle_vector(
            one, ir.Constant(vty, None), ir.Constant(ir.VectorType(_I32, lanes), None)
        )

    return vi32, mask, total, const, splat


def _word(builder: Any, bits: Any, lanes: int) -> Any:
    """A vector of ``lanes`` booleans as an int64 word (lane j: bit j)."""
    word = builder.bitcast(bits, ir.IntType(lanes))
    return word if lanes == 64 else builder.zext(word, ir.IntType(64))


def _row(context: Any, builder: Any, ary_type: Any, ary: Any, at: Any, lanes: int) -> Any:
    """The ``lanes`` bytes of a uint8 array from index ``at``, as a vector."""
    data = context.make_array(ary_type)(context, builder, ary).data
    vty = ir.VectorType(ir.IntType(8), lanes)
    return builder.load(builder.bitcast(builder.gep(data, [at]), vty.as_pointer()), align=1)


def _bytes_ok(wins: Any, at: Any) -> bool:
    """Whether the types are a contiguous 1-d uint8 array and an integer index."""
    return (
        isinstance(wins, types.Array)
        and wins.dtype == types.uint8
        and wins.ndim == 1
        and wins.layout == "C"
        and at in types.integer_domain
    )


def _at_most(lanes: int) -> Any:
    """An intrinsic ``(wins, at, level)``: the word of lanes j with ``wins[at + j] <= level``
    (level 0..254: the byte's compare, unsigned)."""

    def typer(typingctx: Any, wins: Any, at: Any, level: Any) -> Any:
        if not (_bytes_ok(wins, at) and level == types.int64):
            return None

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            _, _, _, _, splat = _lanes(builder, lanes)
            row = _row(context, builder, sig.args[0], args[0], args[1], lanes)
            level = splat(builder.trunc(args[2], ir.IntType(8)), row.type)
            return _word(builder, builder.icmp_unsigned("<=", row, level), lanes)

        return types.int64(wins, at, level), codegen

    return intrinsic(typer)


def _within(lanes: int) -> Any:
    """An intrinsic ``(squares, d2y, reach2)``: the word of lanes j with ``squares[j] + d2y <=
    reach2`` (float64; false where NaN, as Python's ``<=``)."""

    def typer(typingctx: Any, squares: Any, d2y: Any, reach2: Any) -> Any:
        if not (isinstance(squares, types.Array) and squares.dtype == types.float64 and squares.ndim == 1
                and squares.layout == "C" and d2y == types.float64 and reach2 == types.float64):  # fmt: skip
            return None

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            _, _, _, _, splat = _lanes(builder, lanes)
            data = context.make_array(sig.args[0])(context, builder, args[0]).data
            vty = ir.VectorType(ir.DoubleType(), lanes)
            sq = builder.load(builder.bitcast(data, vty.as_pointer()), align=8)
            dist = builder.fadd(sq, splat(args[1], vty))
            return _word(builder, builder.fcmp_ordered("<=", dist, splat(args[2], vty)), lanes)

        return types.int64(squares, d2y, reach2), codegen

    return intrinsic(typer)


def _copy_row(lanes: int) -> Any:
    """An intrinsic ``(g, at, wins, row, word)``: the ``lanes`` bytes of the 2-d uint8 array ``g``
    from byte ``at`` of its data stored at ``wins[row:]``, and the largest of them in the lanes of
    ``word`` (0 in none)."""

    def typer(typingctx: Any, g: Any, at: Any, wins: Any, row: Any, word: Any) -> Any:
        if not (isinstance(g, types.Array) and g.dtype == types.uint8 and g.ndim == 2
                and at in types.integer_domain and _bytes_ok(wins, row) and word == types.int64):  # fmt: skip
            return None

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            _, mask, _, _, _ = _lanes(builder, lanes)
            vty = ir.VectorType(ir.IntType(8), lanes)
            data = context.make_array(sig.args[0])(context, builder, args[0]).data
            src = builder.load(builder.bitcast(builder.gep(data, [args[1]]), vty.as_pointer()), align=1)
            dst = context.make_array(sig.args[2])(context, builder, args[2]).data
            builder.store(src, builder.bitcast(builder.gep(dst, [args[3]]), vty.as_pointer()), align=1)
            kept = builder.select(mask(args[4]), src, ir.Constant(vty, [0] * lanes))
            fn = cgutils.get_or_insert_function(
                builder.module, ir.FunctionType(ir.IntType(8), [vty]), f"llvm.vector.reduce.umax.v{lanes}i8"
            )
            return builder.zext(builder.call(fn, [kept]), ir.IntType(64))

        return types.int64(g, at, wins, row, word), codegen

    return intrinsic(typer)


def _prefetch() -> Any:
    """An intrinsic ``(g, at)``: a hint to fetch the cache line of byte ``at`` of the 2-d uint8
    array ``g``'s data (LLVM's prefetch: no fault, no result)."""

    def typer(typingctx: Any, g: Any, at: Any) -> Any:
        if not (isinstance(g, types.Array) and g.dtype == types.uint8 and at in types.integer_domain):
            return None

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            data = context.make_array(sig.args[0])(context, builder, args[0]).data
            i8p = ir.IntType(8).as_pointer()
            fn = cgutils.get_or_insert_function(
                builder.module, ir.FunctionType(ir.VoidType(), [i8p, _I32, _I32, _I32]), "llvm.prefetch.p0"
            )
            ptr = builder.bitcast(builder.gep(data, [args[1]]), i8p)
            builder.call(fn, [ptr, ir.Constant(_I32, 0), ir.Constant(_I32, 3), ir.Constant(_I32, 1)])
            return context.get_dummy_value()

        return types.none(g, at), codegen

    return intrinsic(typer)


prefetch = _prefetch()  # a hint to fetch a frame's cache line


def _row_sums(lanes: int, weights: bool) -> Any:
    """An intrinsic ``(wins, w, pos, at, stride, lo, hi, h)``: over the rows i = lo .. hi of a
    window at ``wins[at:]`` (row i's pixels from ``at + i stride + 1``, their offset y = i - 1 -
    h) and the pixels j of each row's words ``w[i]`` and ``pos[i]`` (1-d int64 arrays): the sums
    over the pixels of ``w`` of 1, j, j^2, y and y^2 (0 unless ``weights``), and over those of
    ``pos`` of 1, j, y, v, v j and v y (v = the pixel's level; int64), each kept lane by lane in a
    vector over the rows (the lanes summed once, not every row's: a row's sums across its lanes
    wait on one another)."""

    def typer(typingctx: Any, wins: Any, w: Any, pos: Any, at: Any, stride: Any, lo: Any, hi: Any,
              h: Any) -> Any:  # fmt: skip
        words_ok = all(isinstance(a, types.Array) and a.dtype == types.int64 and a.ndim == 1
                       and a.layout == "C" for a in (w, pos))  # fmt: skip
        if not (words_ok and _bytes_ok(wins, at) and all(a == types.int64 for a in (stride, lo, hi, h))):
            return None

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            vi32, mask, total, const, splat = _lanes(builder, lanes)
            i64 = ir.IntType(64)
            wd = context.make_array(sig.args[1])(context, builder, args[1]).data
            pd = context.make_array(sig.args[2])(context, builder, args[2]).data
            at, stride, lo, hi, h = args[3], args[4], args[5], args[6], args[7]
            zero, one = const([0] * lanes), const([1] * lanes)
            acc = [cgutils.alloca_once_value(builder, zero) for _ in range(7)]
            count = builder.sub(builder.add(hi, ir.Constant(i64, 1)), lo)
            with cgutils.for_range(builder, count) as loop:
                i = builder.add(lo, loop.index)
                bw = mask(builder.load(builder.gep(wd if weights else pd, [i])))
                bp = mask(builder.load(builder.gep(pd, [i])))
                first = builder.add(at, builder.add(builder.mul(i, stride), ir.Constant(i64, 1)))
                v = builder.zext(_row(context, builder, sig.args[0], args[0], first, lanes), vi32)
                y = builder.sub(builder.sub(i, ir.Constant(i64, 1)), h)
                yv = splat(builder.trunc(y, _I32), vi32)
                vp = builder.select(bp, v, zero)
                adds = (builder.select(bw, one, zero), builder.select(bw, yv, zero),
                        builder.select(bw, splat(builder.trunc(builder.mul(y, y), _I32), vi32), zero),
                        builder.select(bp, one, zero),
                        builder.select(bp, yv, zero), vp, builder.mul(vp, yv))  # fmt: skip
                for a, add in list(zip(acc, adds, strict=True))[0 if weights else 3 :]:
                    builder.store(builder.add(builder.load(a), add), a)
            r = [builder.load(a) for a in acc]
            j, j2 = const(range(lanes)), const([k * k for k in range(lanes)])
            sums = [total(r[0]), total(builder.mul(r[0], j)), total(builder.mul(r[0], j2)), total(r[1]),
                    total(r[2]), total(r[3]), total(builder.mul(r[3], j)), total(r[4]), total(r[5]),
                    total(builder.mul(r[5], j)), total(r[6])]  # fmt: skip
            return context.make_tuple(builder, sig.return_type, sums)

        return types.UniTuple(types.int64, 11)(wins, w, pos, at, stride, lo, hi, h), codegen

    return intrinsic(typer)


# one intrinsic per number of lanes (numba calls a global function, not one from a tuple)
_at_most_16, _at_most_32, _at_most_64 = _at_most(16), _at_most(32), _at_most(64)
_within_16, _within_32, _within_64 = _within(16), _within(32), _within(64)
_copy_row_16, _copy_row_32, _copy_row_64 = _copy_row(16), _copy_row(32), _copy_row(64)
_row_sums_16, _row_sums_32, _row_sums_64 = _row_sums(16, True), _row_sums(32, True), _row_sums(64, True)
_pos_sums_16, _pos_sums_32, _pos_sums_64 = _row_sums(16, False), _row_sums(32, False), _row_sums(64, False)
_ONE = np.int64(1)


@numba.njit(cache=True, inline="always")
def lanes_of(n: int) -> int:
    """The fewest lanes (16, 32, 64) that hold a row of ``n`` <= 63 columns."""
    return 16 if n <= 16 else (32 if n <= 32 else 64)


@numba.njit(cache=True, inline="always")
def at_most(wins: np.ndarray, row: int, n: int, level: int) -> np.int64:
    """The word with bit j set for the columns j (0 .. n - 1) of the row at ``wins[row:]`` whose
    grey level is at most ``level`` (any int: below 0 none, 255 or more all)."""
    full = (_ONE << np.int64(n)) - _ONE
    if level < 0:
        return np.int64(0)
    if level >= 255:
        return full
    lanes, lv = lanes_of(n), np.int64(level)
    if lanes == 16:
        return _at_most_16(wins, row, lv) & full
    if lanes == 32:
        return _at_most_32(wins, row, lv) & full
    return _at_most_64(wins, row, lv) & full


@numba.njit(cache=True, inline="always")
def column_squares(n: int, h: int, c: float, squares: np.ndarray) -> None:
    """``squares[j]`` = the squared offset ``((j - h) - c)^2`` of each column j (0 .. n - 1) from
    the centre ``c`` (column offset from column ``h``), and +inf in the lanes past the row (never
    within reach); ``squares``: float64, at least 64."""
    for j in range(n):
        dx = (j - h) - c
        squares[j] = dx * dx
    for j in range(n, lanes_of(n)):
        squares[j] = np.inf


def _by_lanes(on16: Any, on32: Any, on64: Any) -> Any:
    """A compiled ``(n, a, b, c)`` calling, with ``(a, b, c)``, the one of three intrinsics of 16,
    32 and 64 lanes with the fewest lanes that hold a row of ``n`` columns (numba calls a function
    it knows when compiling, not one picked from a tuple)."""

    @numba.njit(cache=True, inline="always")
    def call(n: int, a: Any, b: Any, c: Any) -> Any:
        lanes = lanes_of(n)
        if lanes == 16:
            return on16(a, b, c)
        if lanes == 32:
            return on32(a, b, c)
        return on64(a, b, c)

    return call


_within_by_lanes = _by_lanes(_within_16, _within_32, _within_64)


@numba.njit(cache=True, inline="always")
def within(n: int, squares: np.ndarray, d2y: float, reach2: float) -> np.int64:
    """The word with bit j set for the columns j of a row whose squared distance from the centre
    (``squares[j]`` of :func:`column_squares`, plus the row's ``d2y``) is at most ``reach2``: the
    test ``dx * dx + d2y <= reach2`` of every pixel at once."""
    if not d2y <= reach2:  # (no pixel of the row is: its words need no vector)
        return np.int64(0)
    return _within_by_lanes(n, squares, d2y, reach2)


@numba.njit(cache=True, inline="always")
def copy_row(g: np.ndarray, at: int, wins: np.ndarray, row: int, n: int) -> int:
    """Copy the ``n`` <= 63 pixels of a frame row (the 2-d uint8 array ``g``'s bytes from ``at`` of its
    data; readable a whole vector of lanes on) to ``wins[row:]`` (and bytes past them, up to the
    lanes: ``SLACK``), returning the largest of them."""
    full = (_ONE << np.int64(n)) - _ONE
    lanes = lanes_of(n)
    if lanes == 16:
        return _copy_row_16(g, at, wins, row, full)
    if lanes == 32:
        return _copy_row_32(g, at, wins, row, full)
    return _copy_row_64(g, at, wins, row, full)


@numba.njit(cache=True, inline="always")
def row_sums(wins: np.ndarray, w: np.ndarray, pos: np.ndarray, at: int, n: int, lo: int, hi: int) -> tuple:
    """Over the rows lo .. hi of an ``n``-column (padded) window at ``wins[at:]`` (row i's pixels
    from ``at + i (n + 2) + 1``; its offset y = i - 1 - n // 2) and the pixels j (its columns) of
    each row's words ``w[i]`` and ``pos[i]``: the sums over those of ``w`` of 1, j, j^2, y and y^2,
    and over those of ``pos`` of 1, j, y, v, v j and v y (v: the pixel's level; int64)."""
    lanes, h, stride = lanes_of(n), np.int64(n // 2), np.int64(n + 2)
    first, last = np.int64(lo), np.int64(hi)
    if lanes == 16:
        return _row_sums_16(wins, w, pos, at, stride, first, last, h)
    if lanes == 32:
        return _row_sums_32(wins, w, pos, at, stride, first, last, h)
    return _row_sums_64(wins, w, pos, at, stride, first, last, h)


@numba.njit(cache=True, inline="always")
def pos_sums(wins: np.ndarray, pos: np.ndarray, at: int, n: int, lo: int, hi: int) -> tuple:
    """:func:`row_sums` over the pixels of the words ``pos`` only: the sums of 1, j, y, v, v j and
    v y."""
    lanes, h, stride = lanes_of(n), np.int64(n // 2), np.int64(n + 2)
    first, last = np.int64(lo), np.int64(hi)
    if lanes == 16:
        r = _pos_sums_16(wins, pos, pos, at, stride, first, last, h)
    elif lanes == 32:
        r = _pos_sums_32(wins, pos, pos, at, stride, first, last, h)
    else:
        r = _pos_sums_64(wins, pos, pos, at, stride, first, last, h)
    return r[5], r[6], r[7], r[8], r[9], r[10]
