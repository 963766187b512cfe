"""The compiled KD-tree: exact neighbours, warm starts, second-nearest distances, Chamfer."""

from __future__ import annotations

import numpy as np
import pytest

from aw.kernels.kdtree import STACK, build_tree, nearest2


def _brute(x, ref):
    d = ((x[:, None, :] - ref[None, :, :]) ** 2).sum(-1)
    return d


@pytest.mark.parametrize("n", [1, 2, 7, 9, 500])
def test_query_equals_brute_force(n):
    rng = np.random.default_rng(n)
    ref = rng.normal(size=(n, 3)) * [1.0, 0.3, 0.05]
    x = rng.normal(size=(300, 3)) * 2.0
    x[:20] += 50.0  # far queries
    d, rows = build_tree(ref).query(x)
    want = _brute(x, ref)
    assert np.array_equal(rows, want.argmin(1))
    assert np.allclose(d, want.min(1), rtol=1e-15, atol=0)


def test_nearest2_from_any_warm_start_and_second_distance():
    rng = np.random.default_rng(3)
    ref = rng.normal(size=(400, 3))
    tree = build_tree(ref)
    stack = np.empty(STACK, np.int64)
    bounds = np.empty(STACK)
    for q in rng.normal(size=(50, 3)) * 3:
        d = np.sort(_brute(q[None], ref)[0])
        want = int(_brute(q[None], ref)[0].argmin())
        for warm in (-1, 0, 17, 399):
            j, d1, d2 = nearest2(tuple(tree), q[0], q[1], q[2], warm, stack, bounds)
            assert tree.index[j] == want
            assert np.isclose(d1, d[0], rtol=1e-14) and np.isclose(d2, d[1], rtol=1e-14)


def test_duplicate_points_and_flat_clouds():
    ref = np.zeros((40, 3))
    ref[20:, 0] = 1.0  # two stacks of identical points, all on a line
    d, rows = build_tree(ref).query(np.array([[0.2, 0.0, 0.0], [0.9, 0.0, 0.0]]))
    assert rows[0] < 20 <= rows[1]
    assert np.allclose(d, [0.04, 0.01])


def test_empty_cloud_is_rejected():
    with pytest.raises(ValueError, match="at least one point"):
        build_tree(np.zeros((0, 3)))


@pytest.mark.parametrize("kind", ["spread", "ties"])
def test_tree_layout_invariants(kind):
    """Splits separate the children (left <= split <= right), the permutation is complete and
    leaves hold at most LEAF_SIZE points, also with many equal coordinates (quickselect ties)."""
    from aw.kernels.kdtree import LEAF_SIZE

    rng = np.random.default_rng(11)
    pts = rng.normal(size=(3000, 3))
    if kind == "ties":
        pts = np.round(pts * 2) / 2  # a coarse lattice: most coordinates repeat
    tree = build_tree(pts)
    assert np.array_equal(np.sort(tree.index), np.arange(len(pts)))
    assert np.array_equal(tree.points, pts[tree.index])
    for node in range(len(tree.left)):
        a, b = tree.left[node], tree.right[node]
        seg = tree.points[tree.start[node] : tree.end[node]]
        assert np.array_equal(tree.lo[node], seg.min(0)) and np.array_equal(tree.hi[node], seg.max(0))
        if a < 0:
            assert len(seg) <= LEAF_SIZE and np.all(tree.leaf_of[tree.start[node] : tree.end[node]] == node)
            continue
        dim, split = tree.dim[node], tree.split[node]
        assert (
            tree.points[tree.start[a] : tree.end[a], dim].max()
            <= split
            <= tree.points[tree.start[b] : tree.end[b], dim].min()
        )
        assert abs((tree.end[a] - tree.start[a]) - (tree.end[b] - tree.start[b])) <= 1  # median split
    d, rows = tree.query(pts[:200] + 0.01)
    want = _brute(pts[:200] + 0.01, pts)
    assert np.allclose(d, want.min(1), rtol=1e-15, atol=0)
