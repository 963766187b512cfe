"""Leaf-box certificates (the jax backend's neighbours): every certified lookup is the
brute-force first minimum, and the queries without a certificate are flagged, never guessed."""

from __future__ import annotations

import numpy as np
import pytest

from aw_eval.kernels.leafbox import brute_first_min, build_leaf_boxes, build_part_leaves, leaf_lookup


def _cloud(seed: int, m: int = 300) -> np.ndarray:
    """Points on two thin sheets and a dense blob, with exact duplicates of some points."""
    rng = np.random.default_rng(seed)
    a = np.c_[rng.uniform(-1, 1, (m // 3, 2)), np.zeros(m // 3)]
    b = np.c_[rng.uniform(-1, 1, m // 3), np.full(m // 3, 0.5), rng.uniform(0, 0.4, m // 3)]
    c = rng.normal(size=(m - 2 * (m // 3), 3)) * 0.03 + [0.3, -0.2, 0.2]
    pts = np.concatenate([a, b, c])
    pts[rng.integers(len(pts), size=20)] = pts[rng.integers(len(pts), size=20)]  # duplicates
    return pts


def _queries(pts: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    near = pts[rng.integers(len(pts), size=2000)] + rng.normal(size=(2000, 3)) * 0.05
    wide = rng.uniform(-1.5, 1.5, (2000, 3))
    far = rng.normal(size=(200, 3)) * 50.0  # far outside the cloud
    return np.concatenate([near, wide, far, pts[:100]])  # the points themselves: exact hits


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_certified_lookups_are_the_brute_force_first_minimum(seed):
    pts = _cloud(seed)
    leaves = build_leaf_boxes(pts, leaf=16)
    x = _queries(pts, seed + 10)
    idx, ok = leaf_lookup(leaves, x[None], x, pts, candidates=4)
    want = brute_first_min(x, pts)
    assert np.array_equal(idx[ok], want[ok])
    assert ok.mean() > 0.8  # the bound is per query: most are certified, far ones included
    far = slice(4000, 4200)
    assert ok[far].mean() > 0.5


def test_leaves_partition_the_cloud_with_own_point_padding():
    pts = _cloud(3, m=301)
    leaves = build_leaf_boxes(pts, leaf=16)
    lo, hi, index = (a[0] for a in leaves)
    assert index.shape[1] <= 16 and len(index) == 32  # 2^5 balanced leaves of at most 16
    assert set(index.ravel().tolist()) == set(range(301))
    for b in range(len(index)):
        own = np.unique(index[b])
        assert np.all(pts[own] >= lo[b]) and np.all(pts[own] <= hi[b])
    # every point in exactly one leaf (padding repeats the leaf's own points only)
    assert sum(len(np.unique(r)) for r in index) == 301


def test_exact_ties_take_the_lowest_index_across_leaves():
    """Duplicated points split into different leaves, and queries equidistant from two points
    (mirror pairs): the lowest index wins, as brute force's first minimum."""
    rng = np.random.default_rng(5)
    base = rng.uniform(-1, 1, (64, 3))
    pts = np.concatenate([base, base[::-1], base * [1, 1, -1]])  # duplicates at other indices, mirrors
    leaves = build_leaf_boxes(pts, leaf=4)
    assert len({tuple(np.flatnonzero(np.any(leaves.index[0] == i, axis=1))) for i in (0, 127)}) == 2
    x = np.concatenate([base, base * [1, 1, 0]])  # exact hits; points on the mirror plane
    idx, ok = leaf_lookup(leaves, x[None], x, pts, candidates=64)
    want = brute_first_min(x, pts)
    assert np.array_equal(idx[ok], want[ok]) and ok.all()
    assert np.all(idx[:64] == np.arange(64))


def test_knife_edge_near_ties_are_certified_or_flagged():
    """Two points whose distances to the query differ by a few ulps, in different leaves: the
    lookup never returns the farther one as certified."""
    rng = np.random.default_rng(6)
    pts = rng.uniform(-1, 1, (200, 3))
    pts[150] = pts[10] + [1e-15, 0, 0]
    x = pts[10] + np.array([0.1, 0.0, 0.0]) * 0.5 + np.array([0.5e-15, 0, 0])
    q = np.stack([x, pts[10] + [0.5e-15, 0.02, 0.0]])
    for leaf in (2, 8, 64):
        for cand in (1, 2, 8):
            idx, ok = leaf_lookup(build_leaf_boxes(pts, leaf=leaf), q[None], q, pts, candidates=cand)
            want = brute_first_min(q, pts)
            assert np.array_equal(idx[ok], want[ok]), (leaf, cand)


def test_part_leaves_index_the_joined_clouds_and_one_part_answers_all():
    rng = np.random.default_rng(7)
    parts = rng.normal(size=(3, 50, 3))
    parts[2] = parts[0]  # identical parts: the lower part's index must win every tie
    leaves = build_part_leaves(parts, leaf=8)
    assert leaves.index.shape == (3, 8, 7)
    for q in range(3):
        assert set(leaves.index[q].ravel().tolist()) == set(range(50 * q, 50 * q + 50))
    ref = parts.reshape(-1, 3)
    x = np.concatenate(
        [ref[rng.integers(150, size=300)] + rng.normal(size=(300, 3)) * 0.01, rng.normal(size=(50, 3)) * 20]
    )
    idx, ok = leaf_lookup(leaves, np.broadcast_to(x, (3,) + x.shape), x, ref, candidates=4)
    assert np.array_equal(idx[ok], brute_first_min(x, ref)[ok]) and ok.mean() > 0.5
    assert not np.any(idx[ok] >= 100)  # part 2 duplicates part 0: never the first minimum
    one = build_leaf_boxes(ref[:5], leaf=32)  # a single leaf: every query certified
    i1, o1 = leaf_lookup(one, x[None], x, ref[:5])
    assert o1.all() and np.array_equal(i1, brute_first_min(x, ref[:5]))


def test_empty_cloud_is_refused():
    with pytest.raises(ValueError, match="at least one point"):
        build_leaf_boxes(np.zeros((0, 3)))
