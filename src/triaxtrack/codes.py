"""Rotation-invariant ring codes for the circular coded targets (CTs).

A CT carries ``n`` equal code sectors around its centre dot; sector ``k`` spans the angles
``[2 pi k / n, 2 pi (k + 1) / n)`` counter-clockwise from the surface's +theta direction as seen
from outside, and is black for a 1 bit. Because a camera sees the target at an unknown rotation,
a code is a *necklace*: all its cyclic rotations are the same code. The code word of a necklace
is its smallest rotation read as an integer (bit k is sector k).

The family is built greedily over necklaces in increasing order, keeping a word only when its
distance to every kept word, minimised over all rotations, is at least ``min_distance``; words
that equal one of their own non-trivial rotations (periodic) and words with fewer than three
ones or zeros are excluded. With 17 sectors and distance 3 this yields 218 codes; IDs are
assigned the first codes in order, so the table is reproducible from (n, min_distance) alone.
Distance 3 corrects one misread sector; it does not detect two (a two-sector misread can land
within distance 1 of another code), so a reader must reject targets whose sectors it cannot read
with confidence rather than rely on the code to catch them.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

MIN_RUN_BITS = 3  # at least three ones and three zeros: keeps the ring visibly structured


def rotations(word: int, n: int) -> list[int]:
    """All ``n`` cyclic rotations of an ``n``-bit word."""
    mask = (1 << n) - 1
    return [((word << k) | (word >> (n - k))) & mask for k in range(n)]


def necklace_distance(a: int, b: int, n: int) -> int:
    """Hamming distance between two necklaces, minimised over relative rotations."""
    return min(bin(a ^ r).count("1") for r in rotations(b, n))


@lru_cache(maxsize=8)
def code_family(n: int, min_distance: int) -> tuple[int, ...]:
    """Canonical code words of the greedy rotation-invariant family, in assignment order."""
    size = 1 << n
    seen = np.zeros(size, dtype=bool)
    blocked = np.zeros(size, dtype=bool)
    # XOR masks of every error pattern of weight < min_distance
    masks = [0]
    for _ in range(min_distance - 1):
        masks = sorted({m | (1 << i) for m in masks for i in range(n)} | set(masks))
    mask_arr = np.array(masks, dtype=np.int64)
    chosen: list[int] = []
    for word in range(size):
        if seen[word]:
            continue
        rots = rotations(word, n)
        seen[rots] = True
        ones = bin(word).count("1")
        if len(set(rots)) < n or ones < MIN_RUN_BITS or ones > n - MIN_RUN_BITS:
            continue
        if blocked[word]:
            continue
        chosen.append(word)
        for r in rots:
            blocked[r ^ mask_arr] = True
    return tuple(chosen)


def code_table(ids: list[int], n: int, min_distance: int) -> dict[int, int]:
    """Assign code words to CT IDs: the i-th smallest ID gets the i-th code of the family."""
    family = code_family(n, min_distance)
    ids = sorted(ids)
    if len(ids) > len(family):
        raise ValueError(
            f"{len(ids)} coded targets need more codes than the {len(family)} that {n} sectors "
            f"give at distance {min_distance}: use more sectors"
        )
    return {tid: family[i] for i, tid in enumerate(ids)}


def bits_of(word: int, n: int) -> np.ndarray:
    """(n,) uint8 bits of a word, bit k = sector k."""
    return np.array([(word >> k) & 1 for k in range(n)], dtype=np.uint8)


def word_of(bits: np.ndarray) -> int:
    """Inverse of :func:`bits_of`."""
    return int(sum(int(b) << k for k, b in enumerate(np.asarray(bits).astype(int))))


def decode_ring_code(bits: np.ndarray, table: dict[int, int], min_distance: int) -> int | None:
    """ID whose code is nearest to the read ``bits`` (any rotation), or None when ambiguous.

    Accepts the nearest code when it is within ``(min_distance - 1) // 2`` flipped sectors and no
    other code is equally near; otherwise returns None (rejected, never guessed).
    """
    n = len(bits)
    word = word_of(bits)
    dists = sorted((necklace_distance(code, word, n), tid) for tid, code in table.items())
    best, tid = dists[0]
    if best > (min_distance - 1) // 2:
        return None
    if len(dists) > 1 and dists[1][0] == best:
        return None
    return tid
