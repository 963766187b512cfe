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


def _stacked_boxes(n_parts: int, n_points: int):
    """Boxes stacked face to face along Z (baked in the assembled frame: identity targets)."""
    import trimesh

    import aw_eval
    from aw_eval.geometry import geometry_from_meshes

    meshes, z = [], 0.0
    for i in range(n_parts):
        ext = np.array([0.5 - 0.05 * i, 0.4 + 0.04 * i, 0.1 + 0.02 * i])
        m = trimesh.creation.box(extents=ext)
        m.apply_translation([0.0, 0.0, z + ext[2] / 2])
        z += ext[2]
        meshes.append(m)
    identity = np.tile([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], (n_parts, 1))
    settings = aw_eval.ProtocolSettings(n_surface=4 * n_points, n_fps=n_points, max_iters=30)
    return geometry_from_meshes([f"p{i}" for i in range(n_parts)], meshes, identity, settings)


def test_exact_searches_the_predictions_own_graph_where_parts_touch():
    """Parts in contact make the backward search walk several parts per query; after the first
    start ``exact`` then searches the prediction's own Delaunay graph, with the same registration
    (to summation order) as the parts' walks; apart parts keep the parts' walks."""
    from aw_eval.engine import (CONTACT_WALKS, _own_graph_where_parts_touch, checkpoint_rotations,
                                prediction_problem, register_points, task_context)

    geom = _stacked_boxes(4, 150)
    poses = np.array(geom.target_poses, dtype=float)
    poses[:, :3] += np.random.default_rng(0).normal(scale=0.01, size=(4, 3)) * geom.divisor
    ctx = task_context(geom)
    pred_parts = geom.pred_parts(poses)
    r0, t0 = starts_for(pred_parts.reshape(-1, 3), ctx.target_frame, poses, geom.target_poses, geom.divisor,
                        checkpoint_rotations(geom, poses))
    st = geom.settings
    prob = prediction_problem(geom, ctx, poses, pred_parts)
    first = prob.run(r0[0], t0[0], st.max_iters, st.tol)
    assert first.part_walks > CONTACT_WALKS * first.part_searches > 0
    hook = _own_graph_where_parts_touch(ctx, pred_parts)
    own = hook(prob, first)
    assert own is not prob and len(own.tree_p.points) == pred_parts.shape[0] * pred_parts.shape[1]
    switched = register_points(prob, r0, t0, st.max_iters, st.tol, hook)
    walked = register_points(prediction_problem(geom, ctx, poses, pred_parts), r0, t0, st.max_iters, st.tol)
    # (starts that converge to the same optimum tie up to summation order: which of them wins
    # may change, the registration does not)
    assert np.allclose(switched.objectives, walked.objectives, rtol=1e-12, atol=0)
    assert abs(switched.scd - walked.scd) <= 1e-12 * walked.scd
    assert np.allclose(switched.rotation, walked.rotation, rtol=0, atol=1e-10)
    assert np.allclose(switched.translation, walked.translation, rtol=0, atol=1e-10)
    # the same parts pulled apart: one walk per query, no graph built
    apart = poses.copy()
    apart[:, 0] += np.arange(4) * 2.0 * geom.divisor
    pp = geom.pred_parts(apart)
    prob = prediction_problem(geom, ctx, apart, pp)
    first = prob.run(r0[0], t0[0], st.max_iters, st.tol)
    assert first.part_walks <= CONTACT_WALKS * first.part_searches
    assert _own_graph_where_parts_touch(ctx, pp)(prob, first) is prob
