"""Engine pieces that must match the reference bit for bit."""

from __future__ import annotations

import numpy as np

from aw.pose import pca_frame, quat_to_matrix
from aw_eval import reference as ref
from aw_eval.engine import mean_squared_norm, starts_for
from aw_eval.fixtures import make_points_geometry


def test_starts_equal_the_reference_bitwise():
    """The batched starts (24 PCA starts, then one same-ID start per part) are the reference's
    numbers exactly: exact mode's registration starts where the protocol's does."""
    for seed in range(5):
        rng = np.random.default_rng(seed)
        pred, target = rng.normal(size=(200, 3)) * [3, 2, 1], rng.normal(size=(200, 3)) * [1, 2, 3]
        poses = np.concatenate([rng.normal(size=(4, 3)), rng.normal(size=(4, 4))], axis=1)
        target_poses = np.concatenate([rng.normal(size=(4, 3)), rng.normal(size=(4, 4))], axis=1)
        r0, t0 = starts_for(pred, pca_frame(target), poses, target_poses, 1.7)
        want = ref.pca_starts(pred, target) + ref.part_starts(poses, target_poses, 1.7)
        assert len(r0) == len(want) == 28
        for k, (r, t) in enumerate(want):
            assert np.array_equal(r0[k], r) and np.array_equal(t0[k], t)
        given = starts_for(pred, pca_frame(target), poses, target_poses, 1.7,
                           (quat_to_matrix(poses[:, 3:]), quat_to_matrix(target_poses[:, 3:])))
        assert np.array_equal(given[0], r0) and np.array_equal(given[1], t0)
    r0, t0 = starts_for(pred, pca_frame(target), np.zeros((0, 7)), np.zeros((0, 7)), 1.0)
    assert r0.shape == (24, 3, 3) and t0.shape == (24, 3)


def test_mean_squared_norm_sums_like_numpy_reduction():
    """The part distances' mean squared norm is NumPy's ``mean(sum(d * d, axis=1))`` bit for bit
    (what the reference computes), on every scale and length."""
    rng = np.random.default_rng(0)
    for n in (1, 2, 3, 7, 8, 9, 100, 1001, 4096):
        d = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-8, 4, size=(n, 1))
        assert mean_squared_norm(d) == float(np.mean(np.sum(d * d, axis=1)))


def test_geometry_rotations_follow_the_poses():
    """The per-checkpoint rotation cache returns each poses' own matrices (never a previous
    checkpoint's), read-only, and the target's once per task."""
    geom, _ = make_points_geometry(3, 40, seed=1)
    rng = np.random.default_rng(2)
    seen = []
    for _ in range(4):
        poses = geom.check_poses(np.concatenate([rng.normal(size=(3, 3)), rng.normal(size=(3, 4))], axis=1))
        rot = geom.rotations(poses)
        assert np.array_equal(rot, quat_to_matrix(poses[:, 3:])) and not rot.flags.writeable
        assert geom.rotations(poses.copy()) is rot  # same poses: the cached matrices
        seen.append((poses, rot))
    for poses, rot in seen:  # going back to earlier poses recomputes them
        assert np.array_equal(geom.rotations(poses), rot)
    both = np.stack([seen[0][0], seen[1][0]])  # a batch is keyed by its shape too
    assert geom.rotations(both).shape == (2, 3, 3, 3)
    assert np.array_equal(geom.target_rotations(), quat_to_matrix(geom.target_poses[:, 3:]))
