"""Official package + archives -> scoring suite + runs (every recorded frame a checkpoint)."""

from __future__ import annotations

import numpy as np
import pytest

from aw.cli.prepare import main
from aw.formats import read_final, read_manifest, read_run_info, read_targets, read_trajectory
from aw.official import convert, suite_eval_inputs

from official_fixtures import episode_members, episode_poses, write_archive, write_package

IDS = ["p01", "p02", "p03"]
SIZES = [(0.1, 0.05, 0.02), (0.05, 0.05, 0.05), (0.2, 0.01, 0.03)]


def _official(tmp_path, n_frames=6, end_reason="finished"):
    rng = np.random.default_rng(3)
    targets = np.concatenate([rng.normal(size=(3, 3)), rng.normal(size=(3, 4))], axis=1)
    targets[:, 3:] /= np.linalg.norm(targets[:, 3:], axis=1, keepdims=True)
    targets[:, 3:] *= np.sign(targets[:, 3:4])
    pkg = write_package(tmp_path / "pkg", [
        {"sample_id": "partnet/obj 1/image", "source": "partnet", "condition": "image", "object_id": "obj1", "category": "chair", "n_parts": 3,
         "eval": "eval/s1.npz"},
    ], {"s1": dict(part_ids=np.array(IDS), points=rng.normal(size=(3, 1000, 3)), target_poses=targets,
                   scale_divisor=np.float64(1.25), equivalence_groups=np.array([0, 1, 1]))})
    poses = episode_poses(targets, n_frames)
    eps = tmp_path / "episodes"
    write_archive(eps / "agent-a" / "s1" / "final.episode.zip", episode_members(IDS, SIZES, poses, end_reason=end_reason),
                  {"sample_id": "partnet/obj 1/image", "started_at": "2025-05-01T10:00:00Z"})
    return pkg, eps, poses, targets


def test_convert(tmp_path):
    pkg, eps, poses, targets = _official(tmp_path)
    manifest, runs = convert(pkg, eps, tmp_path / "suite", tmp_path / "runs")
    (entry,) = manifest.tasks
    assert entry.task_id == "partnet_obj_1_image" and entry.source == "partnet" and entry.condition == "image"
    assert read_manifest(tmp_path / "suite").tasks == manifest.tasks
    t = read_targets(tmp_path / "suite" / "targets" / f"{entry.task_id}.json")
    assert t.eval_divisor == 1.25 and t.equivalence_hint == [["p02", "p03"]]
    np.testing.assert_allclose([t.parts[p].pose for p in IDS], targets)
    inputs = suite_eval_inputs(tmp_path / "suite", entry.task_id)
    assert inputs.part_ids == IDS and inputs.groups == [["p01"], ["p02", "p03"]]
    assert suite_eval_inputs(tmp_path / "suite", "native-task") is None

    (run,) = runs
    assert run == tmp_path / "runs" / "agent-a" / entry.task_id
    traj = read_trajectory(run / "trajectory.jsonl")
    assert not traj.truncated and traj.end.reason == "finished"
    cps = traj.checkpoints()
    assert len(cps) == len(poses)  # every recorded frame is a checkpoint
    for cp, want in zip(cps, poses):
        np.testing.assert_allclose([cp.poses[p] for p in IDS], want)
    # calls keep their tools and order; the camera call carries no state
    assert [c.tool for c in traj.calls] == ["set_object_pose"] * 5 + ["capture_scene"]
    assert traj.calls[-1].poses is None and traj.calls[0].changed == ["p02"]
    np.testing.assert_allclose([read_final(run / "final.json").poses[p] for p in IDS], poses[-1])
    info = read_run_info(run / "run.json")
    assert info.system == "agent-a" and info.mcp_calls == 6 and info.ended == "finished" and info.extra["frames"] == 6

    with pytest.raises(FileExistsError):
        convert(pkg, eps, tmp_path / "suite", tmp_path / "runs")
    convert(pkg, eps, tmp_path / "suite", tmp_path / "runs", system="renamed", force=True)
    assert (tmp_path / "runs" / "renamed" / entry.task_id / "trajectory.jsonl").is_file()


def test_episode_without_end(tmp_path):
    pkg, eps, poses, _ = _official(tmp_path, end_reason=None)
    _, (run,) = convert(pkg, eps, tmp_path / "suite", tmp_path / "runs")
    traj = read_trajectory(run / "trajectory.jsonl")
    assert traj.end is None and traj.truncated
    np.testing.assert_allclose([traj.final_poses()[p] for p in IDS], poses[-1])
    assert read_final(run / "final.json").reason == "interrupted"


def test_cli(tmp_path, capsys):
    pkg, eps, _, _ = _official(tmp_path)
    assert main(["official", str(pkg), "--episodes", str(eps), "--out", str(tmp_path / "s"), "--runs", str(tmp_path / "r")]) == 0
    assert "wrote 1 tasks" in capsys.readouterr().out
    assert main(["official", str(pkg), "--episodes", str(eps), "--out", str(tmp_path / "s"), "--runs", str(tmp_path / "r")]) == 1
    assert "already holds a suite" in capsys.readouterr().err
    assert main(["official", str(tmp_path / "nope"), "--out", str(tmp_path / "s2")]) == 1
    assert "package manifest not found" in capsys.readouterr().err
