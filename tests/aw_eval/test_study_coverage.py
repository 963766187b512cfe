"""Runs that do not match the suite: no run of it at all (an error, not a table of zeros), a
system with runs for only some tasks (a loud warning), and the ``aw-serve --record-under``
layout (one system per attempt)."""

from __future__ import annotations

import json

import pytest

from aw_eval.cli import main
from aw_eval.study import discover_runs
from aw_eval.study.fixtures import box_suite, write_scripted_run
from aw_server.cli import next_attempt_dir

FB = (("fantastic_breaks", ("none",)),)
TASKS = ["fantastic_breaks-box000-none", "fantastic_breaks-box001-none"]
QUICK = [
    "--final-only",
    "--protocol-setting",
    "n_surface=192",
    "--protocol-setting",
    "n_fps=48",
    "--bootstrap",
    "50",
    "--permutations",
    "50",
    "--no-progress",
    "--no-html",
    "--no-plots",
    "--jobs",
    "1",
]


@pytest.fixture(scope="module")
def suite(tmp_path_factory):
    return box_suite(tmp_path_factory.mktemp("cov") / "suite", objects_per_source=2, n_parts=2, blocks=FB)


def _score(suite, runs, out, capsys):
    rc = main([str(suite), str(runs), "--out", str(out), *QUICK])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def test_runs_of_another_suite_are_an_error_with_the_numbers(suite, tmp_path, capsys):
    other = box_suite(tmp_path / "other", objects_per_source=3, n_parts=2, blocks=(("partnet", ("none",)),))
    for i in range(3):
        t = f"partnet-box{i:03d}-none"
        write_scripted_run(tmp_path / "runs" / "S" / t, other, t, system="S", inspect_moves=False)
    rc, out, err = _score(suite, tmp_path / "runs", tmp_path / "rep", capsys)
    assert rc == 2
    assert "no run matches a task of suite box-suite" in err
    assert "3 runs found: 0 for the suite's 2 tasks, 3 for tasks not in the suite" in err
    assert "SR 0.00%" not in out and not (tmp_path / "rep" / "report.md").exists()


def test_a_system_missing_on_some_tasks_says_so(suite, tmp_path, capsys):
    runs = tmp_path / "runs"
    for t in TASKS:
        write_scripted_run(runs / "full" / t, suite, t, system="full", inspect_moves=False)
    write_scripted_run(runs / "half" / TASKS[0], suite, TASKS[0], system="half", inspect_moves=False)
    write_scripted_run(runs / "half" / "not-a-task", suite, TASKS[1], system="half", inspect_moves=False)
    rc, out, err = _score(suite, runs, tmp_path / "rep", capsys)
    assert rc == 0
    assert "warning: system half has runs for 1 of the 2 tasks; the other 1 count as missing" in err
    assert "warning: 1 run for tasks not in suite box-suite ignored (4 runs found: 3 for the suite's 2 tasks" in err
    assert "system full" not in err
    half = next(line for line in out.splitlines() if line.startswith("half:"))
    full = next(line for line in out.splitlines() if line.startswith("full:"))
    assert "WARNING: runs for only 1 of 2 tasks" in half and "WARNING" not in full
    assert "1 task:" not in err and "1 tasks" not in err + out


def test_record_under_layout_is_one_system_per_attempt(suite, tmp_path, capsys):
    runs = tmp_path / "runs"
    for t in TASKS:  # two sessions on the first task, one on the second, as aw-serve --record-under lays them out
        for _ in range(2 if t == TASKS[0] else 1):
            d = next_attempt_dir(runs / "mine", t)
            write_scripted_run(d, suite, t, system="mine", inspect_moves=False)
        write_scripted_run(runs / "idle" / t, suite, t, system="idle", correct=[], inspect_moves=False)
    systems, found, unknown = discover_runs(runs, set(TASKS))
    assert systems == ["idle", "mine/attempt-1", "mine/attempt-2"]
    assert found[("mine/attempt-2", TASKS[0])] == runs / "mine" / "attempt-2" / TASKS[0]
    assert ("mine/attempt-2", TASKS[1]) not in found and not unknown
    rc, out, err = _score(suite, runs, tmp_path / "rep", capsys)
    assert rc == 0
    assert f"{runs / 'mine'} holds aw-serve --record-under recordings: scored as 2 systems, one per attempt" in err
    doc = json.loads((tmp_path / "rep" / "scores.json").read_text())
    assert doc["systems"] == ["idle", "mine/attempt-1", "mine/attempt-2"]
    assert any(line.startswith("mine/attempt-1: Overall SR 100.00%") for line in out.splitlines())
    assert doc["roles"]["idle"] == "floor"  # printed marked, as the report's tables mark it
    assert any(line.startswith("idle (floor): Overall SR ") for line in out.splitlines()), out
    assert "warning: system mine/attempt-2 has runs for 1 of the 2 tasks" in err


def test_a_system_folder_with_its_own_task_runs_is_not_split_into_attempts(tmp_path):
    (tmp_path / "S" / "t1").mkdir(parents=True)
    (tmp_path / "S" / "t1" / "final.json").write_text("{}")
    (tmp_path / "S" / "attempt-1" / "t1").mkdir(parents=True)  # not a task: reported as nothing
    systems, found, _ = discover_runs(tmp_path, {"t1"})
    assert systems == ["S"] and list(found) == [("S", "t1")]
