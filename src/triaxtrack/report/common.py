"""What the report's figures and movie share: the choice of frames and colour ranges."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

__all__ = ["RANGE_PERCENTILE", "MIN_RANGE", "chosen_frames", "half_range", "number"]

# Colour ranges ignore the most extreme 1 % of values, so that one bad dot does not wash out a
# map; values beyond the range are drawn in the end colour (the colour bar says the range).
RANGE_PERCENTILE = 99.0
MIN_RANGE = 1e-9  # the half range of an all-zero quantity (the reference frame)


def chosen_frames(frames: Iterable[int], n: int) -> list[int]:
    """``n`` frames spread over a test: the first, the last and evenly between (nearest by index
    in the sorted unique ``frames``). All of them when there are ``n`` or fewer; with ``n == 1``
    the last (the most deformed: the first is the undeformed reference); none for ``n <= 0``."""
    unique = sorted({int(f) for f in frames})
    if n <= 0 or not unique:
        return []
    if len(unique) <= n:
        return unique
    if n == 1:
        return [unique[-1]]
    idx = np.round(np.linspace(0, len(unique) - 1, n)).astype(int)
    return [unique[i] for i in sorted(set(idx.tolist()))]


def half_range(values: np.ndarray) -> float:
    """The symmetric colour range of signed values: a high percentile of their magnitude (1.0
    when none is finite)."""
    v = np.abs(np.asarray(values, float))
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 1.0
    return max(float(np.percentile(v, RANGE_PERCENTILE)), MIN_RANGE)


def number(value: object) -> float:
    """A JSON value as a float: NaN unless it is a (non-boolean) number."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return float("nan")
    return float(value)
