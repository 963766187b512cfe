"""Reruns retry what failed: a run that ended in an error (here a bad --initial-poses file) is run
again by the same aw-run command once the input is fixed, which says so; --keep-failed keeps it
(and says that it failed); a finished run is kept."""

from __future__ import annotations

import json

from aw.formats import read_run_info, read_task
from aw.formats.suite import suite_paths
from aw.runner.cli import main as aw_run

TASK = "tiny_shelf_none"


def _poses_file(path, task_id: str, poses: dict) -> None:
    path.write_text(
        json.dumps({"format": "assemblyworld.poses", "format_version": 1, "task_id": task_id, "poses": poses})
    )


def test_a_failed_run_is_retried_once_its_input_is_fixed(tiny_suite, tmp_path, capsys):
    ids = read_task(suite_paths(tiny_suite, TASK)[0]).part_ids
    starts, out = tmp_path / "starts", tmp_path / "runs"
    starts.mkdir()
    good = {pid: [0.1 * k, -0.2, 0.05 * k, 1.0, 0.0, 0.0, 0.0] for k, pid in enumerate(ids)}
    _poses_file(starts / f"{TASK}.json", TASK, {ids[0]: good[ids[0]]})  # names one part of several
    argv = [str(tiny_suite), "--agent", "idle", "--tasks", TASK, "--initial-poses", str(starts)]
    argv += ["--out", str(out), "--no-progress", "--jobs", "1"]
    run_json = out / "idle" / TASK / "run.json"

    assert aw_run(argv) == 1
    failed = read_run_info(run_json)
    assert failed.failure is not None and failed.ended != "finished"
    capsys.readouterr()

    assert aw_run([*argv, "--keep-failed"]) == 0  # kept as it is, and said
    said = capsys.readouterr()
    assert "retrying" not in said.err
    assert "skipped 1 with an existing run.json (same options), 1 of them failed (kept: --keep-failed)" in said.out
    assert f"  {TASK}: kept (--keep-failed); it failed: {failed.failure}" in said.out
    assert read_run_info(run_json) == failed

    _poses_file(starts / f"{TASK}.json", TASK, good)  # the input fixed: the same command retries
    assert aw_run(argv) == 0
    said = capsys.readouterr()
    assert f"aw-run: retrying 1 run that failed: {TASK} ({failed.failure})" in said.err
    assert read_run_info(run_json).ended == "finished"

    assert aw_run(argv) == 0  # a finished run is kept
    said = capsys.readouterr()
    assert "retrying" not in said.err and "skipped 1 with an existing run.json (same options)\n" in said.out
