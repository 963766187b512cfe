"""aw-run --initial-poses DIR: each episode starts from DIR/<task_id>.json (or a run's
final.json), recorded in the trajectory header and run.json; a task without one is refused
before anything runs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from aw.formats import read_run_info, read_task, read_trajectory
from aw.formats.suite import suite_paths
from aw.runner.cli import main as aw_run
from tests.aw.formats.hostile_json import DEEP, inject

TASK = "tiny_shelf_none"


def test_episodes_start_from_poses_files(tiny_suite, tmp_path):
    ids = read_task(suite_paths(tiny_suite, TASK)[0]).part_ids
    poses = {pid: [0.1 * k, -0.2, 0.05 * k, 0.0, 1.0, 0.0, 0.0] for k, pid in enumerate(ids)}
    starts = tmp_path / "starts"
    starts.mkdir()
    (starts / f"{TASK}.json").write_text(
        json.dumps({"format": "assemblyworld.poses", "format_version": 1, "task_id": TASK, "poses": poses})
    )
    out = tmp_path / "runs"
    assert (
        aw_run(
            [
                str(tiny_suite),
                "--agent",
                "idle",
                "--tasks",
                TASK,
                "--initial-poses",
                str(starts),
                "--out",
                str(out),
                "--no-progress",
                "--jobs",
                "1",
            ]
        )
        == 0
    )
    run = out / "idle" / TASK
    assert read_run_info(run / "run.json").extra["initial_poses"] == str((starts / f"{TASK}.json").resolve())
    traj = read_trajectory(run / "trajectory.jsonl")
    assert traj.header.initial_poses_from == str((starts / f"{TASK}.json").resolve())
    for pid in ids:
        assert np.allclose(traj.header.initial_poses[pid], poses[pid])
        assert np.allclose(traj.final_poses()[pid], poses[pid])  # the idle agent left them there


def test_a_task_without_a_start_state_is_refused_up_front(tiny_suite, tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    code = aw_run(
        [
            str(tiny_suite),
            "--agent",
            "idle",
            "--tasks",
            TASK,
            "--initial-poses",
            str(tmp_path / "empty"),
            "--out",
            str(tmp_path / "runs"),
            "--no-progress",
        ]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert err[0] == (
        f"aw-run: error: --initial-poses {tmp_path / 'empty'}: no start state for {TASK} "
        f"({TASK}/final.json or {TASK}.json)"
    )
    assert not (tmp_path / "runs" / "idle" / TASK).exists()


FAR = "poses.part_00: Value error, pose position beyond +-1e+06 scene units"


@pytest.mark.parametrize(
    "fragment, message",
    [(DEEP, DEEP.message), ("far", FAR)],
    ids=["deep", "far"],
)
def test_a_bad_start_state_is_named_before_anything_runs(tiny_suite, tmp_path, fragment, message):
    """The real command: the start state is read by the one JSON reader (and the recording's pose
    rule) before any episode starts, so a hostile file is one line, never an episode that fails
    as "MCP connection failed" with a traceback in server.log."""
    ids = read_task(suite_paths(tiny_suite, TASK)[0]).part_ids
    doc = {"format": "assemblyworld.poses", "format_version": 1, "task_id": TASK}
    doc["poses"] = {pid: [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0] for pid in ids}
    start = tmp_path / "starts" / f"{TASK}.json"
    start.parent.mkdir()
    if fragment == "far":
        doc["poses"][ids[0]] = [1e300, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
        start.write_text(json.dumps(doc))
    else:
        start.write_text(inject(doc, ("poses", ids[0]), fragment))
    proc = subprocess.run(
        [str(Path(sys.executable).with_name("aw-run")), str(tiny_suite), "--agent", "idle", "--tasks", TASK]
        + ["--initial-poses", str(start.parent), "--out", str(tmp_path / "runs"), "--no-progress"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    (line,) = proc.stderr.splitlines()
    assert line.startswith(f"aw-run: error: {start.resolve()}: {message.replace('part_00', ids[0])}")
    assert not (tmp_path / "runs" / "idle" / TASK).exists()
