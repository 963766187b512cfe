"""aw-serve --initial-poses: an episode that starts from given poses (a refiner's, a run's final
state) instead of the task's layout, recorded as such; a bad poses file is one line, exit 2."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest
from aw_server_helpers import server_command, server_params
from mcp import Client

from aw.formats import read_final, read_trajectory
from tests.aw.formats.hostile_json import FRAGMENTS, inject

pytestmark = pytest.mark.anyio

START = {
    "p01": [0.1, 0.2, 0.3, 1.0, 0.0, 0.0, 0.0],
    "p02": [-0.5, 0.0, 0.25, 0.0, 0.0, 0.0, 1.0],
    "p03": [0.0, 0.75, 0.0, 0.5, 0.5, 0.5, 0.5],
}


def _poses_file(path, task_id="box3_none", poses=START, fmt="assemblyworld.poses"):
    path.write_text(json.dumps({"format": fmt, "format_version": 1, "task_id": task_id, "poses": poses}))
    return path


FAR = "poses.p01: Value error, pose position beyond +-1e+06 scene units"  # refused where it is read


def _hostile(fragment):
    """A poses file whose p01 pose is the hostile fragment."""
    doc = {"format": "assemblyworld.poses", "format_version": 1, "task_id": "box3_none", "poses": START}
    return lambda p: p.write_text(inject(doc, ("poses", "p01"), fragment))


async def test_episode_starts_from_the_given_poses(box_task, tmp_path):
    task_dir, _, _ = box_task
    run = tmp_path / "run"
    start = _poses_file(tmp_path / "start.json")
    async with Client(server_params(task_dir, run, "--initial-poses", str(start))) as c:
        obj = (await c.call_tool("get_object", {"id": "p02"})).structured_content
        assert np.allclose(obj["position"], [-0.5, 0.0, 0.25]) and np.allclose(obj["quaternion"], [0, 0, 0, 1])
        await c.call_tool("translate_objects", {"ids": ["p01"], "delta": [0.5, 0, 0]})
    traj = read_trajectory(run / "trajectory.jsonl")
    assert traj.header.initial_poses_from == str(start.resolve())
    for pid, pose in START.items():
        assert np.allclose(traj.header.initial_poses[pid], pose)
    final = read_final(run / "final.json").poses
    assert np.allclose(final["p01"][:3], [0.6, 0.2, 0.3]) and np.allclose(final["p03"], START["p03"])


async def test_a_runs_final_json_is_accepted(box_task, tmp_path):
    task_dir, _, _ = box_task
    final = _poses_file(tmp_path / "final.json", fmt="assemblyworld.final")
    text = json.loads(final.read_text())
    text["reason"] = "finished"
    final.write_text(json.dumps(text))
    async with Client(server_params(task_dir, tmp_path / "run", "--initial-poses", str(final))) as c:
        obj = (await c.call_tool("get_object", {"id": "p01"})).structured_content
        assert np.allclose(obj["position"], [0.1, 0.2, 0.3])


def _refused(task_dir, run, start) -> subprocess.CompletedProcess:
    return subprocess.run(
        server_command(task_dir, run, "--initial-poses", str(start)),
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.mark.parametrize(
    "write, message",
    [
        (lambda p: p.write_text("{not json"), "not valid JSON"),
        (lambda p: _poses_file(p, task_id="other"), "poses are for task 'other', not 'box3_none'"),
        (lambda p: _poses_file(p, poses={k: v for k, v in START.items() if k != "p03"}), "missing ['p03']"),
        (lambda p: _poses_file(p, poses={**START, "p09": START["p01"]}), "unknown ['p09']"),
        (lambda p: _poses_file(p, poses={**START, "p01": [0, 0, 0, 0, 0, 0, 0]}), "zero length"),
        (lambda p: _poses_file(p, fmt="assemblyworld.task"), "expected an assemblyworld.poses file or a final.json"),
        (lambda p: None, "initial-poses file not found"),
        (lambda p: _poses_file(p, poses={**START, "p01": [1e300, 0, 0, 1, 0, 0, 0]}), FAR),
        *((_hostile(f), f.message) for f in FRAGMENTS),
    ],
)
def test_bad_poses_file_is_one_line_naming_it(box_task, tmp_path, write, message):
    task_dir, _, _ = box_task
    start = tmp_path / "start.json"
    write(start)
    proc = _refused(task_dir, tmp_path / "run", start)
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"aw-serve: error: {start}") and message in lines[0], proc.stderr
    assert not (tmp_path / "run" / "trajectory.jsonl").exists()
