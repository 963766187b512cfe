"""Registration of a checkpoint: the search-structure switch where parts touch."""

from __future__ import annotations

import numpy as np


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
    from aw_eval.registration import CONTACT_WALKS, _own_graph_where_parts_touch, checkpoint_starts, register_points

    geom = _stacked_boxes(4, 150)
    poses = np.array(geom.target_poses, dtype=float)
    poses[:, :3] += np.random.default_rng(0).normal(scale=0.01, size=(4, 3)) * geom.divisor
    index = geom.index()
    ck = geom.checkpoint(poses)
    pred_parts = ck.parts
    r0, t0 = checkpoint_starts(geom, ck)
    st = geom.settings

    def prediction_problem(c):
        return index.assembly_problem(c.poses, c.rotations, c.parts, geom.divisor)

    prob = prediction_problem(ck)
    first = prob.run(r0[0], t0[0], st.max_iters, st.tol)
    assert first.part_walks > CONTACT_WALKS * first.part_searches > 0
    hook = _own_graph_where_parts_touch(index, pred_parts)
    own = hook(prob, first)
    assert own is not prob and len(own.tree_p.points) == pred_parts.shape[0] * pred_parts.shape[1]
    switched = register_points(prob, r0, t0, st.max_iters, st.tol, hook)
    walked = register_points(prediction_problem(ck), r0, t0, st.max_iters, st.tol)
    # (starts that converge to the same optimum tie up to summation order: which of them wins
    # may change, the registration does not)
    assert np.allclose(switched.objectives, walked.objectives, rtol=1e-12, atol=0)
    assert abs(switched.scd - walked.scd) <= 1e-12 * walked.scd
    assert np.allclose(switched.rotation, walked.rotation, rtol=0, atol=1e-10)
    assert np.allclose(switched.translation, walked.translation, rtol=0, atol=1e-10)
    # the same parts pulled apart: one walk per query, no graph built
    apart = poses.copy()
    apart[:, 0] += np.arange(4) * 2.0 * geom.divisor
    ck_apart = geom.checkpoint(apart)
    prob = prediction_problem(ck_apart)
    first = prob.run(r0[0], t0[0], st.max_iters, st.tol)
    assert first.part_walks <= CONTACT_WALKS * first.part_searches
    assert _own_graph_where_parts_touch(index, ck_apart.parts)(prob, first) is prob
