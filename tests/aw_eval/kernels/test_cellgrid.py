"""Cell-grid candidate lists (the jax backend's neighbours): every answered lookup is the
brute-force first minimum, and the queries the grid cannot answer are flagged, never guessed."""

from __future__ import annotations

import numpy as np
import pytest

from aw_eval.kernels.cellgrid import brute_first_min, build_cell_grid, build_part_grids, grid_lookup, leaf_of


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
    far = rng.normal(size=(200, 3)) * 50.0  # far outside the grid
    return np.concatenate([near, wide, far, pts[:100]])  # the points themselves: exact hits


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_answered_lookups_are_the_brute_force_first_minimum(seed):
    pts = _cloud(seed)
    grid = build_cell_grid(pts, k=16, max_nodes=200_000)
    x = _queries(pts, seed + 10)
    idx, ok = grid_lookup(grid, x, pts)
    want = brute_first_min(x, pts)
    assert np.array_equal(idx[ok], want[ok])
    assert np.all(idx[~ok] == -1)
    node, inside = leaf_of(grid, x)
    assert not inside[-300:-100].any()  # the far queries: outside, so never answered by the grid
    assert ok[:2000].mean() > 0.9  # near the cloud the grid answers almost every query
    leaves = grid.child < 0
    assert np.all(grid.count[leaves & ~grid.over] <= 16) and np.all(grid.count[grid.over] > 16)


def test_duplicates_and_exact_ties_take_the_lowest_index():
    """A lattice with power-of-two coordinates (exact squared distances) and duplicated points:
    queries at midpoints tie exactly between lattice points; the lookup takes the lowest index
    as the brute-force first minimum does."""
    g = np.arange(6) * 0.25
    lattice = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    pts = np.concatenate([lattice[::-1], lattice[:40]])  # every one of the first 40 twice, reversed order first
    grid = build_cell_grid(pts, k=32)
    mids = (lattice[:-1] + lattice[1:]) / 2
    x = np.concatenate([mids, lattice, lattice + 0.125])
    idx, ok = grid_lookup(grid, x, pts)
    want = brute_first_min(x, pts)
    assert ok.mean() > 0.9 and np.array_equal(idx[ok], want[ok])
    d = np.sum((x[:, None] - pts[None]) ** 2, axis=-1)
    assert np.sum(np.sum(d == d.min(axis=1, keepdims=True), axis=1) > 1) > 100  # many exact ties tested


def test_overflowing_cells_are_flagged_not_truncated():
    """A dense blob with K = 2: many lists are longer than K; those leaves overflow and their
    queries are not answered (the caller's brute-force path), the rest still are exact."""
    rng = np.random.default_rng(5)
    pts = rng.normal(size=(400, 3)) * 0.01
    grid = build_cell_grid(pts, k=2, depth=1)
    assert grid.over.any()
    x = pts[rng.integers(400, size=1000)] + rng.normal(size=(1000, 3)) * 0.002
    idx, ok = grid_lookup(grid, x, pts)
    node, inside = leaf_of(grid, x)
    assert np.array_equal(ok, inside & ~grid.over[node]) and (~ok).any()
    assert np.array_equal(idx[ok], brute_first_min(x[ok], pts))


def test_part_grids_index_the_joined_clouds():
    parts = np.stack([_cloud(7, 120), _cloud(8, 120) + 3.0])
    pg = build_part_grids(parts, k=16)
    assert pg.cand.shape[0] == 2 and pg.cand[1].min() >= 120 and pg.cand[0].max() < 120
    assert np.array_equal(pg.box_lo, parts.min(axis=1)) and np.array_equal(pg.box_hi, parts.max(axis=1))
