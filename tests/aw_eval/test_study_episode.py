"""A recorded run as arrays: checkpoints, final state, call log and edit magnitudes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from aw.formats import FinalState, TrajectoryCall, TrajectoryEnd, TrajectoryHeader, TrajectoryWriter, write_final
from aw.pose import quat_from_axis_angle
from aw_eval.study.episode import RunUnreadable, edit_magnitudes, read_episode

IDS = ["p01", "p02", "p03"]  # p03 plays a distractor (not scored)
SCORED = ["p02", "p01"]  # the evaluator's order need not be the task's
CENTROIDS = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]])
DIVISOR = 2.0
I7 = [0.0, 0, 0, 1, 0, 0, 0]


def _pose(t=(0, 0, 0), axis=(0, 0, 1), deg=0.0):
    q = quat_from_axis_angle(np.array(axis, float), np.radians(deg))
    return [*map(float, t), *map(float, q)]


def _write(run_dir: Path, calls, end=None, final=None, cut_tail: bytes | None = None, task_id="task-1"):
    header = TrajectoryHeader(
        task_id=task_id, system="S", started_at="2025-01-01T00:00:00Z", part_ids=IDS, initial_poses={p: I7 for p in IDS}
    )
    w = TrajectoryWriter(run_dir / "trajectory.jsonl", header)
    for c in calls:
        w.call(c)
    if end is not None:
        w.end(end)
    else:
        w.close()
    if cut_tail is not None:
        with open(run_dir / "trajectory.jsonl", "ab") as fh:
            fh.write(cut_tail)
    if final is not None:
        write_final(run_dir / "final.json", final)


def _episode_calls():
    s1 = {"p01": _pose((0.5, 0, 0)), "p02": I7, "p03": I7}
    s2 = {**s1, "p02": _pose((0, 0, 0), (0, 0, 1), 90)}
    s3 = {**s2, "p01": _pose((0.8, 0, 0), (1, 0, 0), 0.2)}
    s4 = {**s3, "p03": _pose((0, 0, 1))}
    s5 = {"p01": _pose((0.8, 1, 0), (1, 0, 0), 0.2), "p02": _pose((0, 1, 0), (0, 0, 1), 90), "p03": s4["p03"]}
    calls = [
        TrajectoryCall(seq=1, t=0.0, tool="start_episode", ok=True),
        TrajectoryCall(seq=2, t=1.0, tool="list_objects", ok=True),
        TrajectoryCall(seq=3, t=2.0, tool="translate_objects", ok=True, changed=["p01"], poses=s1),
        TrajectoryCall(seq=4, t=3.0, tool="capture_scene", ok=True),
        TrajectoryCall(seq=5, t=4.0, tool="rotate_objects", ok=True, changed=["p02"], poses=s2),
        TrajectoryCall(seq=6, t=5.0, tool="set_object_pose", ok=True, changed=["p01"], poses=s3),
        TrajectoryCall(seq=7, t=6.0, tool="translate_objects", ok=False, error="unknown id"),
        TrajectoryCall(seq=8, t=7.0, tool="translate_objects", ok=True, changed=["p03"], poses=s4),
        TrajectoryCall(seq=9, t=8.0, tool="group_objects", ok=True),
        TrajectoryCall(seq=10, t=9.0, tool="translate_objects", ok=True, changed=["p01", "p02"], poses=s5),
    ]
    return calls, s5


def test_full_episode(tmp_path):
    calls, last = _episode_calls()
    _write(
        tmp_path,
        calls,
        TrajectoryEnd(reason="finished", t=10.0, poses=last),
        FinalState(task_id="task-1", reason="finished", poses=last),
    )
    ep = read_episode(tmp_path, "task-1", IDS, SCORED, CENTROIDS, DIVISOR)
    assert ep.ck_seq.tolist() == [0, 3, 5, 6, 8, 10]
    assert ep.ck_t.tolist() == [0.0, 2.0, 4.0, 5.0, 7.0, 9.0]
    assert ep.ck_poses.shape == (6, 2, 7)
    assert ep.ck_poses[1, 1, :3].tolist() == [0.5, 0, 0]  # p01 is the second scored part
    assert ep.final_from == "final.json" and not ep.truncated and ep.end_reason == "finished" and ep.end_t == 10.0
    assert ep.call_kind.tolist() == [3, 0, 2, 1, 2, 2, 2, 2, 3, 2]
    assert ep.call_ok.tolist().count(False) == 1
    # edits: the failed call is no edit; the distractor edit is one
    assert ep.edit_call.tolist() == [2, 4, 5, 7, 9]
    assert ep.edit_translation[0] == pytest.approx(0.5 / DIVISOR)
    # p02 rotated 90 deg about z through its origin: its centroid (0, 2, 0) moves to (-2, 0, 0)
    assert ep.edit_rotation_deg[1] == pytest.approx(90.0)
    assert ep.edit_translation[1] == pytest.approx(np.hypot(2, 2) / DIVISOR)
    assert ep.edit_rotation_deg[2] == pytest.approx(0.2)  # below 0.5 deg: a translation later
    assert ep.edit_translation[4] == pytest.approx(1.0 / DIVISOR)  # group edit: largest part
    assert ep.edit_rotation_deg[4] == pytest.approx(0.0, abs=1e-9)
    assert ep.edit_revisit.tolist() == [False, False, True, False, True]
    assert ep.moved.tolist() == [True, True]
    assert np.allclose(ep.final_poses[1], last["p01"])


def test_truncated_trajectory_without_final_uses_last_state(tmp_path):
    calls, _ = _episode_calls()
    _write(tmp_path, calls[:5], cut_tail=b'{"type": "call", "seq": 6, "t": 5.0, "tool": "set_obj')
    ep = read_episode(tmp_path, "task-1", IDS, SCORED, CENTROIDS, DIVISOR)
    assert ep.truncated and ep.final_from == "trajectory" and ep.end_reason is None
    assert ep.ck_seq.tolist() == [0, 3, 5]
    assert np.allclose(ep.final_poses, ep.ck_poses[-1])
    assert any("cut mid-write" in p for p in ep.problems)
    assert any("last recorded state" in p for p in ep.problems)
    assert ep.end_t == 4.0


def test_final_json_for_another_task_is_ignored(tmp_path):
    calls, last = _episode_calls()
    _write(
        tmp_path,
        calls,
        TrajectoryEnd(reason="timeout", t=10.0, poses=last),
        FinalState(task_id="other", reason="finished", poses=last),
    )
    ep = read_episode(tmp_path, "task-1", IDS, SCORED, CENTROIDS, DIVISOR)
    assert ep.final_from == "trajectory" and ep.end_reason == "timeout"
    assert any("is for task 'other'" in p for p in ep.problems)


def test_final_json_alone(tmp_path):
    poses = {p: _pose((0.1, 0, 0)) if p == "p02" else I7 for p in IDS}
    write_final(tmp_path / "final.json", FinalState(task_id="task-1", reason="error", poses=poses))
    ep = read_episode(tmp_path, "task-1", IDS, SCORED, CENTROIDS, DIVISOR)
    assert not ep.has_trajectory and ep.final_from == "final.json" and len(ep.ck_seq) == 0
    assert ep.moved.tolist() == [True, False]


def test_final_only_keeps_no_checkpoints(tmp_path):
    calls, last = _episode_calls()
    _write(tmp_path, calls, TrajectoryEnd(reason="finished", t=10.0, poses=last))
    ep = read_episode(tmp_path, "task-1", IDS, SCORED, CENTROIDS, DIVISOR, final_only=True)
    assert len(ep.ck_seq) == 0 and ep.ck_poses.shape == (0, 2, 7)
    assert len(ep.edit_call) == 5  # the call log is still read


def test_unreadable_runs(tmp_path):
    (tmp_path / "trajectory.jsonl").write_text("not json at all\n")
    with pytest.raises(RunUnreadable, match="trajectory unreadable"):
        read_episode(tmp_path, "task-1", IDS, SCORED, CENTROIDS, DIVISOR)
    other = tmp_path / "b"
    other.mkdir()
    calls, last = _episode_calls()
    _write(other, calls, TrajectoryEnd(reason="finished", t=10.0, poses=last), task_id="task-2")
    with pytest.raises(RunUnreadable, match="is for task 'task-2'"):
        read_episode(other, "task-1", IDS, SCORED, CENTROIDS, DIVISOR)
    with pytest.raises(RunUnreadable, match="no trajectory"):
        read_episode(tmp_path / "empty", "task-1", IDS, SCORED, CENTROIDS, DIVISOR)


def test_edit_magnitudes_small_angles_and_pivots():
    before = np.array([[0, 0, 0, 1, 0, 0, 0.0]])
    after = np.array([_pose((0, 0, 0), (0, 0, 1), 1e-4)])
    t, r = edit_magnitudes(before, after, np.array([[1.0, 0, 0]]), 1.0)
    assert r[0] == pytest.approx(1e-4, rel=1e-6)
    assert t[0] == pytest.approx(np.radians(1e-4), rel=1e-6)
    after = np.array([_pose((0, 0, 0), (0, 0, 1), 180)])
    t, r = edit_magnitudes(before, after, np.array([[1.0, 0, 0]]), 4.0)
    assert r[0] == pytest.approx(180.0) and t[0] == pytest.approx(0.5)


def test_final_json_contradicting_the_trajectory(tmp_path):
    """A final.json whose poses differ from the recorded end state: a named problem, and the
    trajectory's state is scored unless trust_final."""
    calls, last = _episode_calls()
    forged = {**last, "p02": _pose((0, 0, 0))}  # p02 back at the origin: not what was recorded
    _write(
        tmp_path,
        calls,
        TrajectoryEnd(reason="finished", t=10.0, poses=last),
        FinalState(task_id="task-1", reason="finished", poses=forged),
    )
    ep = read_episode(tmp_path, "task-1", IDS, SCORED, CENTROIDS, DIVISOR)
    assert ep.final_from == "trajectory" and np.allclose(ep.final_poses[0], last["p02"])
    (problem,) = [p for p in ep.problems if "contradicts" in p]
    assert "parts ['p02']" in problem and "scored the trajectory's" in problem
    trusted = read_episode(tmp_path, "task-1", IDS, SCORED, CENTROIDS, DIVISOR, trust_final=True)
    assert trusted.final_from == "final.json" and np.allclose(trusted.final_poses[0], forged["p02"])
    assert any("contradicts" in p and "--trust-final" in p for p in trusted.problems)
    # q and -q are the same rotation: no contradiction
    flipped = {**last, "p02": last["p02"][:3] + [-v for v in last["p02"][3:]]}
    write_final(tmp_path / "final.json", FinalState(task_id="task-1", reason="finished", poses=flipped))
    same = read_episode(tmp_path, "task-1", IDS, SCORED, CENTROIDS, DIVISOR)
    assert same.final_from == "final.json" and not any("contradicts" in p for p in same.problems)


def test_end_record_contradicting_the_recorded_calls_is_flagged(tmp_path):
    """What a full disk used to leave: edits applied but not recorded, so the end record and
    final.json (both the live scene) agree with each other and with no recorded call. Flagged."""
    calls, last = _episode_calls()
    unrecorded = {**last, "p01": _pose((1.85, 1, 0), (1, 0, 0), 0.2)}  # a further, unrecorded move of p01
    _write(
        tmp_path,
        calls,
        TrajectoryEnd(reason="disconnect", t=10.0, poses=unrecorded),
        FinalState(task_id="task-1", reason="disconnect", poses=unrecorded),
    )
    ep = read_episode(tmp_path, "task-1", IDS, SCORED, CENTROIDS, DIVISOR)
    (problem,) = [p for p in ep.problems if "end record" in p]
    assert "parts ['p01']" in problem and "not recorded" in problem
    # a consistent run has no such problem
    consistent = tmp_path / "ok"
    consistent.mkdir()
    _write(
        consistent,
        calls,
        TrajectoryEnd(reason="disconnect", t=10.0, poses=last),
        FinalState(task_id="task-1", reason="disconnect", poses=last),
    )
    assert not [
        p for p in read_episode(consistent, "task-1", IDS, SCORED, CENTROIDS, DIVISOR).problems if "end record" in p
    ]


def test_final_json_naming_an_unknown_part(tmp_path):
    calls, last = _episode_calls()
    _write(
        tmp_path,
        calls,
        TrajectoryEnd(reason="finished", t=10.0, poses=last),
        FinalState(task_id="task-1", reason="finished", poses={**last, "p99": I7}),
    )
    ep = read_episode(tmp_path, "task-1", IDS, SCORED, CENTROIDS, DIVISOR)
    assert ep.final_from == "trajectory"
    assert any("names parts ['p99']" in p and "does not have" in p for p in ep.problems)


def test_final_json_with_extreme_poses_is_named_not_scored(tmp_path):
    """Poses of 1e308 once reached the evaluator ("Eigenvalues did not converge")."""
    calls, last = _episode_calls()
    _write(tmp_path, calls, TrajectoryEnd(reason="finished", t=10.0, poses=last))
    (tmp_path / "final.json").write_text(
        '{"format": "assemblyworld.final", "format_version": 1, "task_id": "task-1", "reason": "finished", "poses": '
        '{"p01": [1e308, 0, 0, 1, 0, 0, 0], "p02": [0, 0, 0, 1, 0, 0, 0], "p03": [0, 0, 0, 1, 0, 0, 0]}}'
    )
    ep = read_episode(tmp_path, "task-1", IDS, SCORED, CENTROIDS, DIVISOR)
    assert ep.final_from == "trajectory" and np.isfinite(ep.final_poses).all()
    assert any("final.json unreadable" in p and "position beyond +-1e+06" in p for p in ep.problems)
