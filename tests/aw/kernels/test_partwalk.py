"""Nearest neighbours in a posed assembly by walks in its parts' baked clouds (``aw.kernels.partwalk``)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import aw_eval
from aw.kernels.icp import ICPProblem, build_tree, graph_for
from aw.kernels.partwalk import build_part_clouds, part_maps, parts_pass
from aw.pose import quat_to_matrix
from aw_eval.fixtures import make_points_geometry, trajectory_checkpoints
from aw_eval.registration import checkpoint_starts


def _assembly(rng, n_parts, n=300, divisor=2.5):
    """Baked clouds of ``n_parts`` flat-ish boxes, random poses and the posed, normalized union."""
    clouds = rng.random((n_parts, n, 3)) * [1.0, 0.5, 0.1]
    poses = np.concatenate(
        [rng.normal(size=(n_parts, 3)) * 0.6, Rotation.random(n_parts, random_state=rng).as_quat()[:, [3, 0, 1, 2]]],
        axis=1,
    )
    rot = Rotation.from_quat(poses[:, [4, 5, 6, 3]]).as_matrix()
    posed = (np.einsum("pij,pnj->pni", rot, clouds) + poses[:, None, :3]) / divisor
    trees = [build_tree(c) for c in clouds]
    return build_part_clouds([(t, graph_for(t)) for t in trees]), poses, posed, divisor


def _brute(x, ref):
    d = ((x[:, None, :] - ref[None, :, :]) ** 2).sum(-1)
    return d.argmin(1), np.sort(d, axis=1)


@pytest.mark.parametrize("n_parts", [1, 3, 6])
def test_nearest_in_the_union_along_a_moving_path(n_parts):
    """Every pass (cold, then certified and walked as the queries move) returns the union's
    nearest point, also for far queries between and outside the parts."""
    rng = np.random.default_rng(n_parts)
    clouds, poses, posed, divisor = _assembly(rng, n_parts)
    union = posed[clouds.part_of, clouds.rows]  # rows of the clouds' order
    a, b = part_maps(poses, divisor, quat_to_matrix(poses[:, 3:]))
    x = np.concatenate([rng.normal(size=(200, 3)) * 0.4, rng.normal(size=(100, 3)) * 3.0, union[::7] + 1e-3])
    cand, xref, slack = np.zeros(len(x), np.int64), np.zeros((len(x), 3)), np.zeros((len(x), 2))
    warm, stats = np.zeros(n_parts, np.int64), np.zeros(2, np.int64)
    drift = rng.normal(size=x.shape) * 0.004
    searched = []
    for step in range(25):
        xs = np.ascontiguousarray(x + step * drift + 0.01 * np.sin(step) * np.array([1.0, -0.5, 0.2]))
        searched.append(parts_pass(tuple(clouds), a, b, divisor, xs, cand, xref, slack, step == 0, warm, stats))
        want, _ = _brute(xs, union)
        assert np.array_equal(cand, want), step
    assert searched[0] == len(x) and min(searched[1:]) < len(x) // 2  # the certificates do hold points
    # every search walks at least the part it ends in, at most every part
    assert stats[0] == sum(searched) and stats[0] <= stats[1] <= n_parts * stats[0]


def test_certificate_state_bounds_the_union():
    """The stored second-nearest distance never exceeds the union's, and the stored margin never
    exceeds the distance from the query to the border of its nearest point's Voronoi cell in the
    union (baked units): moves shorter than it cannot change the answer."""
    rng = np.random.default_rng(7)
    clouds, poses, posed, divisor = _assembly(rng, 4)
    union = posed[clouds.part_of, clouds.rows]
    a, b = part_maps(poses, divisor, quat_to_matrix(poses[:, 3:]))
    x = np.ascontiguousarray(rng.normal(size=(300, 3)))
    cand, xref, slack = np.zeros(len(x), np.int64), np.zeros((len(x), 3)), np.zeros((len(x), 2))
    parts_pass(tuple(clouds), a, b, divisor, x, cand, xref, slack, True, np.zeros(4, np.int64), np.zeros(2, np.int64))
    nearest, d = _brute(x, union)
    assert np.array_equal(cand, nearest)
    assert np.all(slack[:, 0] <= d[:, 1] * divisor**2 * (1 + 1e-12))
    d_all = ((x[:, None, :] - union[None, :, :]) ** 2).sum(-1)
    edge = np.linalg.norm(union[None, :, :] - union[nearest][:, None, :], axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        to_border = np.where(edge > 0, (d_all - d[:, :1]) / (2 * edge), np.inf).min(axis=1) * divisor
    held = slack[:, 1] > 0
    assert held.mean() > 0.5
    assert np.all(np.sqrt(slack[held, 1]) <= to_border[held] * (1 + 1e-9))


def test_a_part_without_a_graph_disables_the_assembly_search():
    rng = np.random.default_rng(3)
    flat = np.concatenate([rng.random((40, 2)), np.zeros((40, 1))], axis=1)  # Qhull cannot triangulate it
    round_ = rng.normal(size=(40, 3))
    trees = [build_tree(flat), build_tree(round_)]
    assert build_part_clouds([(t, graph_for(t)) for t in trees]) is None


@pytest.mark.parametrize("n_parts", [2, 5])
def test_assembly_icp_equals_the_prediction_tree_icp(n_parts):
    """ICP through the parts' clouds visits the same states as through a tree and graph of the
    prediction: same iterations, objectives and transforms up to summation order."""
    geom, obj = make_points_geometry(n_parts, 120, seed=n_parts)
    index = geom.index()
    for poses in trajectory_checkpoints(obj, 4, seed=9):
        ck = geom.checkpoint(poses)
        pred = ck.points
        tree_p = build_tree(pred)
        plain = ICPProblem(
            pred, index.target, tree_t=index.tree_t, tree_p=tree_p, graph_t=index.graph_t, graph_p=graph_for(tree_p)
        )
        walked = index.assembly_problem(ck.poses, ck.rotations, ck.parts, geom.divisor)
        assert index.part_clouds is not None
        r0, t0 = checkpoint_starts(geom, ck)
        for k in range(0, len(r0), 3):
            x, y = plain.run(r0[k], t0[k], 100, 1e-9), walked.run(r0[k], t0[k], 100, 1e-9)
            assert x.iterations == y.iterations
            assert abs(x.objective - y.objective) <= 1e-12 * x.objective
            assert np.allclose(x.rotation, y.rotation, atol=1e-10) and np.allclose(
                x.translation, y.translation, atol=1e-10
            )


def test_exact_scores_do_not_depend_on_the_search():
    """``exact`` through the parts' clouds equals ``exact`` with the prediction's own structures
    (the fallback used where a part has no graph)."""
    geom, obj = make_points_geometry(
        3, 60, seed=4, settings=aw_eval.ProtocolSettings(n_fps=60, n_surface=400, max_iters=30)
    )
    cks = trajectory_checkpoints(obj, 3, seed=2)
    walked = [aw_eval.score(geom, c, mode="exact") for c in cks]
    geom.index().part_clouds = None  # as if a part could not be triangulated
    plain = [aw_eval.score(geom, c, mode="exact") for c in cks]
    for w, p in zip(walked, plain, strict=True):
        assert (w.pa, w.sr, w.start_index) == (p.pa, p.sr, p.start_index)
        assert abs(w.scd - p.scd) <= 1e-12 * p.scd
