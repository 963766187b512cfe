"""A task's search structures (``aw_eval.kernels.index``)."""

from __future__ import annotations

import numpy as np

from aw_eval.fixtures import make_points_geometry
from aw_eval.kernels import TaskIndex, mean_squared_norm
from aw_eval.reference import chamfer


def test_mean_squared_norm_sums_like_numpy_reduction():
    """The part distances' mean squared norm is NumPy's ``mean(sum(d * d, axis=1))`` bit for bit
    (what the reference computes), on every scale and length."""
    rng = np.random.default_rng(0)
    for n in (1, 2, 3, 7, 8, 9, 100, 1001, 4096):
        d = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-8, 4, size=(n, 1))
        assert mean_squared_norm(d) == float(np.mean(np.sum(d * d, axis=1)))


def test_part_cd_is_the_chamfer_distance_of_the_moved_parts():
    """``TaskIndex.part_cd`` (forward walks in the target part, backward walks in the baked cloud)
    equals the plain Chamfer distance of a moved predicted part and a target part."""
    geom, _ = make_points_geometry(3, 40, seed=1)
    index = TaskIndex(geom.target_parts(), geom.clouds, geom.target_poses, geom.divisor, geom.target_rotations())
    rng = np.random.default_rng(3)
    poses = np.array(geom.target_poses)
    poses[:, :3] += rng.normal(scale=0.05, size=(3, 3))
    ck = geom.checkpoint(poses)
    # identity registration: c = A y + b with A = div R_i^T, b = -R_i^T t_i
    a = geom.divisor * np.swapaxes(ck.rotations, 1, 2)
    b = -np.einsum("pji,pj->pi", ck.rotations, ck.poses[:, :3])
    for i in range(3):
        for j in range(3):
            want = chamfer(ck.parts[i], geom.target_parts()[j])
            assert abs(index.part_cd(ck.parts, (a, b), i, j) - want) <= 1e-12 * max(want, 1e-300)
