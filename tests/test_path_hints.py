"""A path given as SUITE, RUNS, TASK_DIR or RUN_DIR that is another of these kinds (or a folder
one level above or below the right one) is refused by the real commands with one line saying
what it is and what to type (aw.cli.paths), exit status 2, before any work."""

from __future__ import annotations

import os

import pytest

from aw.cli.paths import check_paths, classify
from aw.cli.prepare import main as aw_prepare
from aw.formats import read_manifest
from aw.runner.cli import main as aw_run
from aw_eval.cli import main as aw_score
from aw_eval.study.fixtures import box_suite, write_scripted_run
from aw_server.cli import main as aw_serve
from aw_view.cli import main as aw_view

COMMANDS = {"aw-score": aw_score, "aw-run": aw_run, "aw-serve": aw_serve, "aw-prepare": aw_prepare, "aw-view": aw_view}


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """``suite/`` (two tasks) and ``runs/idle/<task>/`` beside it; the tests run in that folder."""
    root = tmp_path_factory.mktemp("paths")
    box_suite(root / "suite", objects_per_source=1, n_parts=2, blocks=(("partnet", ("none", "image")),))
    tasks = sorted(e.task_id for e in read_manifest(root / "suite").tasks)
    for t in tasks:
        write_scripted_run(root / "runs" / "idle" / t, root / "suite", t, system="idle")
    return root, tasks


@pytest.fixture
def here(study, monkeypatch):
    monkeypatch.chdir(study[0])
    return study[1]


def _error(prog: str, argv: list[str], capsys) -> str:
    assert COMMANDS[prog](argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_kinds(here):
    first = here[0]
    kinds = {
        "suite": "suite",
        "suite/tasks": "tasks",
        "suite/targets": "targets",
        f"suite/tasks/{first}": "task",
        "runs": "runs",
        "runs/idle": "system",
        f"runs/idle/{first}": "run",
        "suite/manifest.json": "file",
        "nowhere": "missing",
        ".": "other",
    }
    assert {p: classify(p).kind for p in kinds} == kinds
    assert classify("suite").inside == tuple(sorted(here))


@pytest.mark.parametrize(
    "prog, argv, message",
    [
        (
            "aw-score",
            ["runs", "suite", "--out", "r"],
            "runs is a runs folder (systems idle) and suite is a suite (2 tasks): SUITE and RUNS are swapped: "
            "aw-score suite runs --out r",
        ),
        (
            "aw-score",
            ["suite", "runs/idle", "--out", "r"],
            "runs/idle is one system's runs folder; RUNS is the folder above it, which holds every system: "
            "aw-score suite runs --out r",
        ),
        (
            "aw-score",
            ["suite", "runs/idle/{first}", "--out", "r"],
            "runs/idle/{first} is one run (of task {first}); RUNS is the folder two levels above it, which holds "
            "every system: aw-score suite runs --out r",
        ),
        (
            "aw-score",
            ["suite", "suite", "--out", "r"],
            "suite is a suite (2 tasks), not a runs folder; RUNS holds <system>/<task_id>/ runs (aw-run SUITE ... "
            "--out RUNS writes them): aw-score suite RUNS --out r",
        ),
        (
            "aw-score",
            ["suite/tasks", "runs", "--out", "r"],
            "suite/tasks is a suite's tasks folder; SUITE is the suite itself: aw-score suite runs --out r",
        ),
        (
            "aw-score",
            ["suite/manifest.json", "runs", "--out", "r"],
            "suite/manifest.json is a file; SUITE is the folder that holds it: aw-score suite runs --out r",
        ),
        (
            "aw-score",
            [".", "runs", "--out", "r"],
            ". holds a suite (2 tasks) in suite/; SUITE is that folder: aw-score suite runs --out r",
        ),
        (
            "aw-run",
            ["suite/tasks", "--agent", "idle", "--out", "r"],
            "suite/tasks is a suite's tasks folder; SUITE is the suite itself: aw-run suite --agent idle --out r",
        ),
        (
            "aw-run",
            ["suite/tasks/{first}", "--agent", "idle", "--out", "r"],
            "suite/tasks/{first} is one task of a suite; SUITE is the suite, two folders up: "
            "aw-run suite --agent idle --out r",
        ),
        (
            "aw-run",
            ["runs", "--agent", "idle", "--out", "r"],
            "runs is a runs folder (systems idle), not a suite; SUITE is the suite the tasks come from "
            "(manifest.json, tasks/, targets/): aw-run SUITE --agent idle --out r",
        ),
        (
            "aw-run",
            ["suite", "--agent", "idle", "--out", "suite"],
            "suite is a suite (2 tasks), not a runs folder; RUNS holds <system>/<task_id>/ runs (aw-run SUITE ... "
            "--out RUNS writes them): aw-run suite --agent idle --out RUNS",
        ),
        (
            "aw-serve",
            ["suite", "--print-prompt"],
            "suite is a suite (2 tasks); TASK_DIR is one task's folder: aw-serve suite/tasks/{first} --print-prompt",
        ),
        (
            "aw-serve",
            ["suite/tasks", "--print-prompt"],
            "suite/tasks is a suite's tasks folder; TASK_DIR is one of the task folders in it: "
            "aw-serve suite/tasks/{first} --print-prompt",
        ),
        (
            "aw-serve",
            ["runs/idle/{first}", "--print-prompt"],
            "runs/idle/{first} is one run (of task {first}), not a task; TASK_DIR is the task's folder in its "
            "suite: aw-serve SUITE/tasks/{first} --print-prompt",
        ),
        (
            "aw-serve",
            ["suite/tasks/{first}/task.json", "--print-prompt"],
            "suite/tasks/{first}/task.json is a file; TASK_DIR is the folder that holds it: "
            "aw-serve suite/tasks/{first} --print-prompt",
        ),
        (
            "aw-view",
            ["suite", "--suite", "runs", "--port", "0"],
            "suite is a suite (2 tasks) and runs is a runs folder (systems idle): PATH and SUITE are swapped: "
            "aw-view runs --suite suite --port 0",
        ),
        (
            "aw-view",
            ["runs", "--suite", "suite/tasks", "--port", "0"],
            "suite/tasks is a suite's tasks folder; SUITE is the suite itself: aw-view runs --suite suite --port 0",
        ),
        (
            "aw-view",
            ["suite/tasks", "--port", "0"],
            "suite/tasks is a suite's tasks folder, not runs; PATH is a runs folder or one run: aw-view PATH --port 0",
        ),
        (
            "aw-prepare",
            ["official-export", "runs/idle", "--suite", "suite", "--out", "x.zip"],
            "runs/idle is one system's runs folder; RUN_DIR is one of the runs in it: "
            "aw-prepare official-export runs/idle/{first} --suite suite --out x.zip",
        ),
    ],
)
def test_wrong_kind_says_what_to_type(here, capsys, prog, argv, message):
    first = here[0]
    argv = [a.format(first=first) for a in argv]
    assert _error(prog, argv, capsys) == f"{prog}: error: {message.format(first=first)}"
    assert not os.path.exists("r")  # refused before any work


def test_right_paths_and_new_outputs_pass(here, capsys):
    """The check never refuses what the commands accept: a task folder, a new --out."""
    assert aw_serve([f"suite/tasks/{here[0]}", "--print-prompt"]) == 0
    assert capsys.readouterr().out.strip()  # the prompt

    check_paths("aw-run", ["suite", "--out", "new-runs"], [("suite", "suite"), ("new-runs", "out runs")])
    check_paths("aw-score", ["suite", "runs"], [("suite", "suite"), ("runs", "runs")])
    check_paths("aw-run", ["suite", "--out", "."], [("suite", "suite"), (".", "out runs")])  # a folder of anything
