"""A high score on a state far from assembled is explained, on the task's card in report.html and
in report.md's Runs section: which parts passed and by what margin, and that SR^a is
shape-level. The suite is made by ``aw-prepare folder`` from box meshes (a table: a top on two
panel legs), the runs are recorded trajectories, and ``aw-score`` scores them."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import trimesh

from aw.cli.prepare import main as aw_prepare
from aw.formats import (
    FinalState,
    TrajectoryCall,
    TrajectoryEnd,
    TrajectoryHeader,
    TrajectoryWriter,
    read_manifest,
    read_targets,
    read_task,
    write_final,
)
from aw.formats.suite import suite_paths
from aw.meshes import load_task_meshes
from aw.pose import quat_to_matrix
from aw_eval.cli import main as aw_score


def _record(run_dir, task, poses: dict[str, list[float]]) -> None:
    """A run that sets every part to ``poses`` in one call."""
    start = {p: [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0] for p in task.part_ids}
    w = TrajectoryWriter(
        run_dir / "trajectory.jsonl",
        TrajectoryHeader(
            task_id=task.task_id,
            system=run_dir.parent.name,
            started_at="2026-01-01T00:00:00Z",
            part_ids=task.part_ids,
            initial_poses=start,
        ),
    )
    w.call(TrajectoryCall(seq=1, t=1.0, tool="set_object_pose", args={}, ok=True, changed=task.part_ids, poses=poses))
    w.end(TrajectoryEnd(reason="disconnect", t=2.0, poses=poses))
    write_final(run_dir / "final.json", FinalState(task_id=task.task_id, reason="disconnect", poses=poses))


@pytest.fixture(scope="module")
def scored(tmp_path_factory):
    root = tmp_path_factory.mktemp("heap")
    table = root / "objects" / "table"
    table.mkdir(parents=True)
    for name, size, centre in (
        ("top", (1.0, 0.6, 0.04), (0, 0, 0.72)),
        ("leg_a", (0.04, 0.5, 0.7), (-0.45, 0, 0.35)),
        ("leg_b", (0.04, 0.5, 0.7), (0.45, 0, 0.35)),
    ):
        trimesh.creation.box(extents=size).apply_translation(centre).export(table / f"{name}.obj")
    suite = root / "suite"
    assert aw_prepare(["folder", str(root / "objects"), "--out", str(suite), "--jobs", "1", "--no-progress"]) == 0
    task_id = read_manifest(suite).tasks[0].task_id
    task_dir, targets_path = suite_paths(suite, task_id)
    task, targets = read_task(task_dir), read_targets(targets_path)
    target = {p: list(targets.parts[p].pose) for p in task.part_ids}
    # where each part's centre lies when assembled; the legs are the two parts below the top
    centres = {}
    for p, mesh in zip(task.part_ids, load_task_meshes(task), strict=True):
        pose = np.asarray(target[p])
        centres[p] = quat_to_matrix(pose[3:]) @ np.asarray(mesh.vertices).mean(axis=0) + pose[:3]
    middle = np.mean(list(centres.values()), axis=0)
    top = min(task.part_ids, key=lambda p: float(np.linalg.norm(centres[p] - middle)))

    def legs_in(share: float) -> dict[str, list[float]]:
        """The legs pushed ``share`` of the way towards the middle, the top in place."""
        out = {p: list(v) for p, v in target.items()}
        for p in task.part_ids:
            if p != top:
                out[p][:3] = (np.asarray(target[p][:3]) + share * (middle - centres[p])).tolist()
        return out

    runs = root / "runs"
    _record(runs / "heap" / task_id, task, legs_in(0.35))  # the legs piled in under the top
    _record(runs / "close" / task_id, task, legs_in(0.05))  # nearly assembled
    _record(runs / "exact" / task_id, task, target)
    out = root / "report"
    argv = [str(suite), str(runs), "--out", str(out), "--final-only", "--jobs", "1"]
    assert aw_score(argv + ["--bootstrap", "20", "--permutations", "20", "--no-progress"]) == 0
    return out, top, task_id


def test_scores_json_says_which_runs_score_on_a_heap(scored):
    out, top, _ = scored
    runs = {r["system"]: r for r in json.loads((out / "scores.json").read_text())["runs"]}
    heap = runs["heap"]["far_from_assembled"]
    assert runs["heap"]["pa"] == pytest.approx(100 / 3) and runs["heap"]["sra"] == 1
    assert heap["n_parts"] == 3 and len(heap["displaced"]) == 2 and top not in heap["displaced"]
    assert [p["part"] for p in heap["passed"]] == [top] and heap["passed"][0]["cd"] < 1e-4
    assert "far_from_assembled" not in runs["close"] and "far_from_assembled" not in runs["exact"]


def test_report_md_and_the_card_explain_the_heap(scored):
    out, top, task_id = scored
    md = (out / "report.md").read_text()
    assert "- **Warning:** 1 run scores PA of 25% or more, or SR^a, on a state far from assembled" in md
    runs = md.split("## Runs")[1].split("\n## ")[0]
    line = next(x for x in runs.splitlines() if x.startswith(f"  - heap / {task_id}: "))
    assert "PA 33.3% and SR^a 1 on a state far from assembled: 2 of 3 parts" in line
    assert re.search(rf"1 part passes: {top} \(CD 0\.0\d, 0\.00 diagonals off\)\.", line)  # x1000, of 10
    assert "SR^a is shape-level" in line and "SR, part by part, is 0" in line
    assert "close /" not in runs and "exact /" not in runs
    page = (out / "report.html").read_text()
    card = page.split(f'id="task-{re.sub(r"[^a-z0-9]+", "-", task_id.lower()).strip("-")}"')[1]
    assert "heap: PA 33.3% and SR^a 1 on a state far from assembled" in card
    assert "close: PA" not in card
