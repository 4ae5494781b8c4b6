"""triaxtrack.nearest: the nearest point within a reach, as scipy's cKDTree finds it."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from triaxtrack.nearest import crowded, finite_rows, k_nearest, nearest_within


@pytest.mark.parametrize("lattice", [False, True])
def test_nearest_within_compares_as_the_exact_nearest(lattice):
    rng = np.random.default_rng(3)
    for _ in range(40):
        n, q = int(rng.integers(1, 800)), int(rng.integers(1, 60))
        if lattice:  # a grid of dots: ties, and distances equal to the reach
            points = rng.integers(0, 30, (n, 2)).astype(float)
            queries = rng.integers(0, 30, (q, 2)).astype(float)
            reach = rng.integers(0, 5, q).astype(float)
        else:
            points, queries, reach = rng.random((n, 2)) * 3840, rng.random((q, 2)) * 3840, rng.random(q) * 40
        exact, _ = cKDTree(points).query(queries)
        d, j = nearest_within(points, queries, reach)
        within = exact <= reach
        assert (d[within] == exact[within]).all() and np.isinf(d[~within]).all() and (j[~within] == -1).all()
        du, dv = (points[j[within]] - queries[within]).T
        assert (np.sqrt(du * du + dv * dv) == d[within]).all()  # the point found is at that distance
        for threshold in (reach, 0.5 * reach):
            for op in (np.less, np.less_equal, np.greater, np.greater_equal):
                assert (op(d, threshold) == op(exact, threshold)).all()


def test_nearest_within_excluding_self_is_the_second_nearest():
    rng = np.random.default_rng(4)
    points = np.r_[rng.random((500, 2)) * 1000, [[10.0, 10.0], [10.0, 10.0]]]  # a duplicate pair
    reach = rng.random(len(points)) * 30
    (_, second), (_, other) = (a.T for a in cKDTree(points).query(points, k=2))
    d, j = nearest_within(points, points, reach, exclude_self=True)
    close = second < reach
    assert ((d < reach) == close).all() and (d[close] == second[close]).all()
    assert (j[close][:-2] == other[close][:-2]).all() and set(j[-2:]) == {len(points) - 2, len(points) - 1}


def test_nearest_within_degenerate_inputs():
    points = np.array([[np.nan, 2.0], [3.0, 3.0], [1e9, 0.0]])
    queries = [[0.0, 0.0], [np.nan, 1.0], [0.0, 0.0], [1e9, 1.0]]
    d, j = nearest_within(points, queries, [np.inf, 5.0, np.nan, 1.0])
    assert d[0] == np.hypot(3, 3) and j[0] == 1
    assert np.isinf(d[1:3]).all() and (j[1:3] == -1).all()
    assert d[3] == 1.0 and j[3] == 2
    d, j = nearest_within(np.zeros((0, 2)), [[0.0, 0.0]], 1.0)
    assert np.isinf(d).all() and (j == -1).all()
    with pytest.raises(ValueError, match="exclude_self"):
        nearest_within(points, points[:2], 1.0, exclude_self=True)


def test_crowded_marks_both_of_each_close_pair():
    rng = np.random.default_rng(5)
    points = rng.random((300, 2)) * 500
    reach = rng.random(300) * 20
    d, nearest = cKDTree(points).query(points, k=2)  # as the tracker's ambiguity check did
    close = d[:, 1] < reach
    expected = close.copy()
    expected[nearest[close, 1]] = True
    assert expected.any() and (crowded(points, reach) == expected).all()
    assert not crowded(points[:1], reach[:1]).any() and crowded(np.zeros((0, 2)), np.zeros(0)).shape == (0,)


def test_overlapping_discs_are_those_of_the_nearest_that_overlap_with_or_without_a_tree():
    import triaxtrack.nearest as nearest

    rng = np.random.default_rng(4)
    uv = rng.uniform(0, 60, (300, 2))
    uv[7] = np.nan
    rad = rng.uniform(1, 4, 300)
    which = np.array([0, 3, 7 + 1, 150, 299])
    got = nearest.overlapping_discs(uv, rad, which, 6)
    for row, i in enumerate(which):  # brute force, by hand
        d = np.hypot(*(uv - uv[i]).T)
        d[i] = np.nan  # not itself
        near = np.argsort(np.where(np.isfinite(d), d, np.inf), kind="stable")[:6]  # the 6 nearest others
        hit = near[d[near] < rad[i] + rad[near]]
        assert np.array_equal(got[row, : len(hit), :2], uv[hit]) and np.isnan(got[row, len(hit) :]).all()
    tree = nearest.BRUTE_FORCE_PAIRS
    try:
        nearest.BRUTE_FORCE_PAIRS = 0
        assert np.array_equal(nearest.overlapping_discs(uv, rad, which, 6), got, equal_nan=True)
    finally:
        nearest.BRUTE_FORCE_PAIRS = tree


@pytest.mark.parametrize("kind", ["random", "lattice", "line", "far"])
def test_k_nearest_gives_the_trees_numbers(kind):
    """The grid of cells gives cKDTree.query's distances and indices exactly: random points, a
    lattice (ties: the tree's own order), points on a line, queries far outside the points."""
    rng = np.random.default_rng(5)
    for _ in range(30):
        n, q = int(rng.integers(1, 600)), int(rng.integers(1, 50))
        if kind == "lattice":
            points, queries = (
                rng.integers(0, 25, (n, 2)).astype(float),
                rng.integers(0, 25, (q, 2)).astype(float),
            )
        elif kind == "line":
            t = rng.random(n) * 1000
            points, queries = np.c_[t, 0.5 * t + 3], rng.random((q, 2)) * 1000
        else:
            points = rng.random((n, 2)) * 1280
            queries = rng.random((q, 2)) * (1280 if kind == "random" else 20000) - (
                0 if kind == "random" else 9000
            )
        k = int(rng.integers(1, min(n, 20) + 1))
        want_d, want_j = cKDTree(points).query(queries, k=k)
        d, j = k_nearest(points, queries, k)
        assert (d == np.asarray(want_d).reshape(q, k)).all() and (j == np.asarray(want_j).reshape(q, k)).all()


def test_finite_rows_are_those_with_both_coordinates_finite():
    a = np.array([[0.0, 1.0], [np.nan, 1.0], [2.0, np.inf], [3.0, 4.0]])
    assert finite_rows(a).tolist() == [True, False, False, True]
