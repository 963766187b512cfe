"""Public API: batches, diagnostics, threshold sweeps, Chamfer, registration, input errors."""

from __future__ import annotations

import numpy as np
import pytest
from eval_helpers import small_task

import aw_eval
from aw.pose import IDENTITY_POSE, compose_poses
from aw_eval.fixtures import random_checkpoints


@pytest.fixture(scope="module")
def task():
    return small_task(4, n_points=16, seed=5, max_iters=20)


def test_score_batch_dedupes_and_matches_score(task):
    geom, obj = task
    cks = random_checkpoints(obj, 3, seed=2)
    batch_in = np.concatenate([cks, cks[:2], cks[1:2]])  # 6 rows, 3 distinct
    b = aw_eval.score_batch(geom, batch_in)
    assert b.n_unique == 3 and len(b) == 6
    assert b.part_errors.shape == (6, 4) and b.assignment.shape == (6, 4)
    assert b.reg_rotation.shape == (6, 3, 3) and b.reg_translation.shape == (6, 3) and b.start_index.shape == (6,)
    assert b.sr.dtype == bool and b.sra.dtype == bool and b.pa.dtype == np.float64
    for k in range(3):
        one = aw_eval.score(geom, cks[k])
        for row in (k, 3 + k) if k < 2 else (k,):
            assert b.pa[row] == one.pa and b.scd[row] == one.scd and b.start_index[row] == one.start_index
            assert np.array_equal(b.part_errors[row], one.part_errors)
    assert set(b.start_kind.tolist()) <= {"pca", "part"}
    r = b.row(0)
    assert r.start_kind == ("pca" if r.start_index < 24 else "part")
    empty = aw_eval.score_batch(geom, np.zeros((0, 4, 7)))
    assert len(empty) == 0 and empty.part_errors.shape == (0, 4)


@pytest.mark.parametrize(("seconds_a_state", "warns"), [(100.0, False), (200.0, True)])
def test_a_batch_that_will_take_long_warns_once_with_its_estimate(task, monkeypatch, seconds_a_state, warns):
    """On a clock that moves only as states are scored: three states at 200 s each leave 400 s
    after the first, worth a warning (above 300 s); at 100 s each, 200 s are not."""
    import types
    import warnings

    import aw_eval.scoring
    from aw.progress import LongWorkWarning

    ticks = iter(np.arange(100) * seconds_a_state)
    monkeypatch.setattr(aw_eval.scoring, "time", types.SimpleNamespace(perf_counter=lambda: float(next(ticks))))
    geom, obj = task
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        aw_eval.score_batch(geom, random_checkpoints(obj, 3, seed=2), backend="numba")
    slow = [str(w.message) for w in caught if issubclass(w.category, LongWorkWarning)]
    assert slow == (
        ["scoring 3 states of a 4-part task (exact, numba): 2 left, about 7 min on this machine (200.0 s a state)"]
        if warns
        else []
    )


def test_registration_is_returned_and_reusable(task):
    geom, obj = task
    poses = random_checkpoints(obj, 1, seed=4, kinds=("near",))[0]
    r = aw_eval.score(geom, poses)
    assert np.allclose(r.reg_rotation @ r.reg_rotation.T, np.eye(3)) and np.isclose(np.linalg.det(r.reg_rotation), 1)
    reg = aw_eval.register_checkpoint(geom, poses)
    assert reg.start_index == r.start_index and reg.scd == r.scd and reg.objectives.shape == (24 + 4,)
    assert reg.objectives.min() == reg.scd and int(np.argmin(reg.objectives)) == reg.start_index
    pa, sr = aw_eval.rescore_thresholds(r.part_errors, [0.0, 0.01, 1e9])
    assert pa.tolist() == [float(np.mean(r.part_errors <= 0)), r.pa, 1.0] and sr[2]


def test_part_diagnostics(task):
    geom, obj = task
    perfect = aw_eval.score(geom, obj.target_poses)
    d = aw_eval.part_diagnostics(geom, obj.target_poses, perfect)
    assert np.all(d.offset < 1e-9) and np.all(d.centred_cd < 1e-20) and not d.never_moved.any()
    poses = obj.target_poses.copy()
    poses[2] = compose_poses(np.array([0.15 * geom.divisor, 0, 0, 1, 0, 0, 0]), poses[2])
    b = aw_eval.score_batch(geom, poses[None])
    d = aw_eval.part_diagnostics(geom, poses, b, 0)
    r = b.row(0)
    from aw.pose import apply_pose

    moved = apply_pose(poses[2], geom.clouds[2]) / geom.divisor @ r.reg_rotation.T + r.reg_translation
    target = apply_pose(geom.target_poses[r.assignment[2]], geom.clouds[r.assignment[2]]) / geom.divisor
    assert d.offset[2] == pytest.approx(np.linalg.norm(moved.mean(0) - target.mean(0)))
    assert d.offset[2] > 2 * np.delete(d.offset, 2).max()  # the displaced part stands out
    assert d.centred_cd[2] < 1e-3 < d.part_errors[2]  # centring removes a pure translation
    poses[3] = IDENTITY_POSE
    d = aw_eval.part_diagnostics(geom, poses, aw_eval.score(geom, poses))
    assert d.never_moved.tolist() == [False, False, False, True]
    with pytest.raises(ValueError, match="row"):
        aw_eval.part_diagnostics(geom, poses, aw_eval.score_batch(geom, np.stack([poses, obj.target_poses])))


def test_chamfer_hand_values_and_batching():
    x = np.array([[0.0, 0.0, 0.0]])
    y = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    assert aw_eval.chamfer(x, y) == pytest.approx(1.0 + 2.5)
    xs = np.stack([x, x + [1.0, 0, 0]])
    got = aw_eval.chamfer(xs, y)
    assert got.shape == (2,) and got[1] == pytest.approx(0.0 + (0.0 + 5.0) / 2)
    many = np.random.default_rng(0).normal(size=(19, 30, 3))  # more than one chunk
    assert np.allclose(
        aw_eval.chamfer(many, many[::-1]), [aw_eval.chamfer(a, b) for a, b in zip(many, many[::-1], strict=True)]
    )
    with pytest.raises(ValueError):
        aw_eval.chamfer(np.zeros((0, 3)), y)
    with pytest.raises(ValueError):
        aw_eval.chamfer(np.array([[np.nan, 0, 0]]), y)


def test_bad_inputs_raise_clear_errors(task):
    geom, obj = task
    with pytest.raises(ValueError, match="shape"):
        aw_eval.score(geom, obj.target_poses[:3])
    with pytest.raises(ValueError, match="non-finite"):
        bad = obj.target_poses.copy()
        bad[0, 0] = np.nan
        aw_eval.score(geom, bad)
    with pytest.raises(ValueError, match="zero quaternion"):
        bad = obj.target_poses.copy()
        bad[1, 3:] = 0
        aw_eval.score(geom, bad)
    with pytest.raises(ValueError, match="mode"):
        aw_eval.score(geom, obj.target_poses, mode="approximate")
    with pytest.raises(ValueError, match="score_batch"):
        aw_eval.score(geom, obj.target_poses[None])
    with pytest.raises(ValueError):
        aw_eval.ProtocolSettings(n_fps=0)
    with pytest.raises(ValueError):
        aw_eval.ProtocolSettings(n_surface=10, n_fps=20)
    with pytest.raises(ValueError):
        aw_eval.rescore_thresholds(np.zeros(3), [np.inf])
