"""A window row's pixels as one vector, for the packed rows of :mod:`triaxtrack.window_rows`:
LLVM's vector instructions through numba intrinsics, on rows of at most 63 columns held in 16,
32 or 64 lanes (the fewest that hold the row; a pixel loop over a row of ~20 columns runs mostly
in its scalar remainder, and a compare's result is then one bit a lane in a word at once):

* :func:`at_most`: the word of a row's pixels at most a grey level (the bytes compared at once);
* :func:`within`: the word of a row's pixels within a reach of a centre, from the squared
  column offsets of the centre (:func:`column_squares`, once per centre) plus the row's;
* :func:`pixel_sums`: over the pixels of a word, the sums of their levels ``v`` and of ``v j``;
* :func:`column_sums`: over the columns of a word, the sums of ``j`` and ``j^2``;
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


def _pixel_sums(lanes: int) -> Any:
    """An intrinsic ``(wins, at, word)``: the sums of ``v = wins[at + j]`` and of ``v j`` over the
    lanes j of ``word`` (in int32 lanes: at most 255 x 2016, exact)."""

    def typer(typingctx: Any, wins: Any, at: Any, word: Any) -> Any:
        if not (_bytes_ok(wins, at) and word == types.int64):
            return None

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            vi32, mask, total, const, _ = _lanes(builder, lanes)
            row = builder.zext(_row(context, builder, sig.args[0], args[0], args[1], lanes), vi32)
            v = builder.select(mask(args[2]), row, const([0] * lanes))
            sums = [total(v), total(builder.mul(v, const(range(lanes))))]
            return context.make_tuple(builder, sig.return_type, sums)

        return types.UniTuple(types.int64, 2)(wins, at, word), codegen

    return intrinsic(typer)


def _column_sums(lanes: int) -> Any:
    """An intrinsic ``(word)``: the sums of ``j`` and of ``j^2`` over the lanes j of ``word``."""

    def typer(typingctx: Any, word: Any) -> Any:
        if word != types.int64:
            return None

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            _, mask, total, const, _ = _lanes(builder, lanes)
            bits, zero = mask(args[0]), const([0] * lanes)
            sums = [total(builder.select(bits, const([j**p for j in range(lanes)]), zero)) for p in (1, 2)]
            return context.make_tuple(builder, sig.return_type, sums)

        return types.UniTuple(types.int64, 2)(word), codegen

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


# one intrinsic per number of lanes (numba calls a global function, not one from a tuple)
_at_most_16, _at_most_32, _at_most_64 = _at_most(16), _at_most(32), _at_most(64)
_within_16, _within_32, _within_64 = _within(16), _within(32), _within(64)
_pixel_sums_16, _pixel_sums_32, _pixel_sums_64 = _pixel_sums(16), _pixel_sums(32), _pixel_sums(64)
_column_sums_16, _column_sums_32, _column_sums_64 = _column_sums(16), _column_sums(32), _column_sums(64)
_copy_row_16, _copy_row_32, _copy_row_64 = _copy_row(16), _copy_row(32), _copy_row(64)
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
_pixel_sums_by_lanes = _by_lanes(_pixel_sums_16, _pixel_sums_32, _pixel_sums_64)


@numba.njit(cache=True, inline="always")
def within(n: int, squares: np.ndarray, d2y: float, reach2: float) -> np.int64:
    """The word with bit j set for the columns j of a row whose squared distance from the centre
    (``squares[j]`` of :func:`column_squares`, plus the row's ``d2y``) is at most ``reach2``: the
    test ``dx * dx + d2y <= reach2`` of every pixel at once."""
    if not d2y <= reach2:  # (no pixel of the row is: its words need no vector)
        return np.int64(0)
    return _within_by_lanes(n, squares, d2y, reach2)


@numba.njit(cache=True, inline="always")
def pixel_sums(wins: np.ndarray, row: int, n: int, word: np.int64) -> tuple[int, int]:
    """Over the pixels of bits ``word`` of the row at ``wins[row:]`` (``n`` columns): the sums of
    their levels v and of v j."""
    return _pixel_sums_by_lanes(n, wins, row, word)


@numba.njit(cache=True, inline="always")
def column_sums(n: int, word: np.int64) -> tuple[int, int]:
    """Over the columns j of bits ``word`` (of a row of ``n``): the sums of j and of j^2."""
    lanes = lanes_of(n)
    if lanes == 16:
        return _column_sums_16(word)
    if lanes == 32:
        return _column_sums_32(word)
    return _column_sums_64(word)


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
