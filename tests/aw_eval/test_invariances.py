"""Protocol invariances (issue 3 acceptance), end to end through ``score`` in ``exact`` mode."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from eval_helpers import close, small_task

import aw_eval
from aw.pose import IDENTITY_POSE, apply_pose, compose_poses
from aw_eval.fixtures import random_checkpoints, random_rotation_quat, swap_identical


@pytest.fixture(scope="module")
def task():
    return small_task(6, n_points=24, seed=3, max_iters=30)


def _moved_by(pose_delta, poses):
    return compose_poses(np.broadcast_to(pose_delta, poses.shape), poses)


def test_perfect_assembly_scores_full_marks(task):
    geom, obj = task
    r = aw_eval.score(geom, obj.target_poses)
    assert r.pa == 1.0 and r.sr and r.sra
    assert r.scd < 1e-20 and np.all(r.part_errors < 1e-20)
    assert np.array_equal(r.assignment, np.arange(geom.n_parts))


def test_global_rigid_motion_changes_nothing(task):
    geom, obj = task
    rng = np.random.default_rng(7)
    for poses in random_checkpoints(obj, 3, seed=11, kinds=("near", "small", "medium"), global_motion=False):
        base = aw_eval.score(geom, poses)
        g = np.concatenate([rng.uniform(-4, 4, 3), random_rotation_quat(rng)])
        moved = aw_eval.score(geom, _moved_by(g, poses))
        assert (moved.pa, moved.sr, moved.sra) == (base.pa, base.sr, base.sra)
        assert close(moved.scd, base.scd, rel=1e-6) and close(moved.part_errors, base.part_errors, rel=1e-6)


def test_swapping_identical_parts_changes_nothing(task):
    geom, obj = task
    a, b = obj.identical[0][:2]
    assert any(set((a, b)) <= set(g) for g in geom.groups)
    for poses in random_checkpoints(obj, 3, seed=12, kinds=("tiny", "near", "small")):
        swapped = swap_identical(geom, poses, a, b)
        p1, p2 = geom.pred_parts(poses), geom.pred_parts(swapped)
        assert np.allclose(p1[a], p2[b], atol=1e-9) and np.allclose(p1[b], p2[a], atol=1e-9)
        r1, r2 = aw_eval.score(geom, poses), aw_eval.score(geom, swapped)
        assert (r1.pa, r1.sr) == (r2.pa, r2.sr)
        assert close(r1.scd, r2.scd, rel=1e-6)
        perm = np.arange(geom.n_parts)
        perm[[a, b]] = [b, a]
        assert close(r1.part_errors, r2.part_errors[perm], rel=1e-6)


@pytest.mark.parametrize("k", [1, 3, 5])
def test_one_displaced_part(task, k):
    geom, obj = task
    poses = obj.target_poses.copy()
    # 0.15 normalized units: clearly wrong (CD ~ 0.02), small enough not to drag the registration
    shift = np.array([0.15 * geom.divisor, 0.0, 0.0])
    poses[k] = compose_poses(np.concatenate([shift, [1.0, 0, 0, 0]]), poses[k])
    r = aw_eval.score(geom, poses)
    n = geom.n_parts
    assert r.pa == pytest.approx((n - 1) / n) and not r.sr
    assert r.part_errors[k] > geom.settings.threshold
    assert np.all(np.delete(r.part_errors, k) <= geom.settings.threshold)


def test_never_moved_layout_scores_near_zero(task):
    geom, _ = task
    r = aw_eval.score(geom, np.tile(IDENTITY_POSE, (geom.n_parts, 1)))
    assert r.pa <= 1.0 / geom.n_parts and not r.sr
    assert r.scd > 0.05 and not r.sra


def test_mirrored_prediction_is_not_rescued(task):
    geom, obj = task
    # Mirror the assembled layout through the plane x = 0: every part keeps its target
    # orientation but sits at its mirrored position. A proper rotation cannot undo it.
    cent = np.stack([apply_pose(t, c).mean(0) for t, c in zip(obj.target_poses, geom.clouds, strict=True)])
    poses = obj.target_poses.copy()
    mirrored = cent * np.array([-1.0, 1.0, 1.0])
    poses[:, :3] += mirrored - cent
    r = aw_eval.score(geom, poses)
    assert r.pa < 1.0 and not r.sr
    # and at point level: a chiral cloud against its mirror image stays far apart
    rng = np.random.default_rng(0)
    chiral = np.concatenate(
        [
            rng.normal(size=(60, 3)) * [1.0, 0.3, 0.1] + [0, 0, 0],
            rng.normal(size=(30, 3)) * 0.1 + [0.8, 0.5, 0.0],
            rng.normal(size=(20, 3)) * 0.1 + [-0.6, 0.0, 0.4],
        ]
    )
    settings = aw_eval.ProtocolSettings(n_surface=110, n_fps=110)
    assert aw_eval.register(chiral @ np.diag([-1.0, 1.0, 1.0]), chiral, settings=settings).scd > 1e-2
    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    assert aw_eval.register(chiral @ rot.T + 3.0, chiral, settings=settings).scd < 1e-20


def test_threshold_is_inclusive_at_the_exact_boundary(task):
    geom, obj = task
    poses = obj.target_poses.copy()
    poses[1] = compose_poses(np.array([0.0, 0.02 * geom.divisor, 0.0, 1.0, 0, 0, 0]), poses[1])
    e = aw_eval.score(geom, poses).part_errors[1]
    at = dataclasses.replace(geom, settings=dataclasses.replace(geom.settings, threshold=float(e)), _derived={})
    below = dataclasses.replace(
        geom, settings=dataclasses.replace(geom.settings, threshold=float(np.nextafter(e, 0))), _derived={}
    )
    assert aw_eval.score(at, poses).pa == 1.0
    assert aw_eval.score(below, poses).pa == pytest.approx(5 / 6)
    pa, sr = aw_eval.rescore_thresholds(np.array([[0.01, 0.0], [np.nextafter(0.01, 1), 0.0]]), [0.01])
    assert pa[:, 0].tolist() == [1.0, 0.5] and sr[:, 0].tolist() == [True, False]
