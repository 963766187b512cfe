"""Proven Chamfer lower bounds: below the distance after every rigid motion, and they rule pairs out."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from aw.shape_bounds import cloud_bounds, lower_bounds


def _cd(x: np.ndarray, y: np.ndarray) -> float:
    a, _ = cKDTree(y).query(x)
    b, _ = cKDTree(x).query(y)
    return float(np.mean(a * a) + np.mean(b * b))


def _box(extents, n: int, seed: int) -> np.ndarray:
    pts, _ = trimesh.sample.sample_surface(trimesh.creation.box(extents=extents), n, seed=seed)
    return np.asarray(pts, dtype=np.float64)


SHAPES = [
    (0.6, 0.1, 0.05),
    (0.6, 0.1, 0.08),
    (0.5, 0.12, 0.05),
    (0.3, 0.3, 0.02),
    (0.2, 0.2, 0.2),
    (0.62, 0.1, 0.05),
    (0.9, 0.3, 0.3),
    (0.6, 0.1, 0.05),
]


def test_bound_is_below_the_distance_after_random_and_aligning_motions():
    rng = np.random.default_rng(7)
    clouds = np.stack([_box(e, 300, k) for k, e in enumerate(SHAPES)])
    bound = lower_bounds(cloud_bounds(clouds))
    assert np.allclose(bound, bound.T) and (bound >= 0).all()
    for i in range(len(clouds)):
        for j in range(len(clouds)):
            motions = [
                (Rotation.random(random_state=rng).as_matrix(), rng.normal(scale=0.05, size=3)) for _ in range(15)
            ]
            motions.append((np.eye(3), clouds[j].mean(0) - clouds[i].mean(0)))  # centroids together, as built
            for r, t in motions:
                assert bound[i, j] <= _cd(clouds[i] @ r.T + t, clouds[j]) * (1 + 1e-12) + 1e-15, (i, j)
    # it does real work: a long bar against a stick, a plate or a cube is ruled out at 1e-4
    assert bound[6, 0] > 1e-4 and bound[3, 0] > 1e-4 and bound[4, 0] > 1e-4


def test_pair_length_term_equals_its_direct_sum_and_beats_the_spread_term():
    from aw.shape_bounds import _forward

    rng = np.random.default_rng(3)
    clouds = np.stack([_box(e, 200, k) for k, e in enumerate([(1.0, 0.2, 0.1), (0.7, 0.2, 0.1), (0.2, 0.2, 0.1)])])
    b = cloud_bounds(clouds)
    direct = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            terms = [np.sum(np.maximum(b.pair_lengths[i, a] - b.diameter[j], 0) ** 2) / (2 * 200) for a in range(3)]
            kyfan = np.max(np.maximum(b.spread[i] - b.reach[j], 0) ** 2)
            direct[i, j] = max(max(terms), kyfan)
    assert np.allclose(_forward(b), direct, rtol=1e-10, atol=1e-15)
    # a 1.0 bar onto a 0.7 bar: the ends stick out; the spread term alone sees nothing
    assert np.max(np.maximum(b.spread[0] - b.reach[1], 0)) == 0 and direct[0, 1] > 1e-3
    del rng


def test_bad_clouds_are_refused():
    with pytest.raises(ValueError, match="shape"):
        cloud_bounds(np.zeros((2, 5, 2)))
