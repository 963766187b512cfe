"""Reruns retry what failed: a run that ended in an error (here a part mesh that cannot be read)
is run again by the same aw-run command once the input is fixed, which says so; --keep-failed
keeps it (and says that it failed); a finished run is kept."""

from __future__ import annotations

from tiny_suite import make_tiny_suite  # tests/aw/runner, on the path from conftest.py

from aw.formats import read_run_info, read_task
from aw.formats.suite import suite_paths
from aw.runner.cli import main as aw_run

TASK = "tiny_shelf_none"


def test_a_failed_run_is_retried_once_its_input_is_fixed(tmp_path, capsys):
    suite = make_tiny_suite(tmp_path / "suite")  # its own copy: a part of it is broken below
    task_dir = suite_paths(suite, TASK)[0]
    mesh = task_dir / read_task(task_dir).parts[0].mesh
    good_mesh = mesh.read_bytes()
    mesh.write_bytes(b"not a mesh\n")  # the episode's server refuses the task
    out = tmp_path / "runs"
    argv = [str(suite), "--agent", "idle", "--tasks", TASK, "--out", str(out), "--no-progress", "--jobs", "1"]
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

    mesh.write_bytes(good_mesh)  # the input fixed: the same command retries
    assert aw_run(argv) == 0
    said = capsys.readouterr()
    assert f"aw-run: retrying 1 run that failed: {TASK} ({failed.failure})" in said.err
    assert read_run_info(run_json).ended == "finished"

    assert aw_run(argv) == 0  # a finished run is kept
    said = capsys.readouterr()
    assert "retrying" not in said.err and "skipped 1 with an existing run.json (same options)\n" in said.out
