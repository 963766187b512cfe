"""System labels from folder names follow aw-run's rule: a folder under RUNS whose name would be
markup in report.md or report.html (a newline, a heading, a table bar, a tag) is refused before
anything is scored, in one line that quotes the name with its escapes; aw-run refuses the same
names for --system."""

from __future__ import annotations

import pytest

from aw.formats import read_manifest
from aw.formats.run import system_label_problem
from aw.runner.cli import main as aw_run
from aw_eval.cli import main as aw_score
from aw_eval.study.fixtures import box_suite, write_scripted_run

HOSTILE = [
    "evil\n# injected | x | y",
    "| a | b |",
    "# heading",
    "<img src=x onerror=alert(1)>",
    "a*b*",
    "[link](x)",
    "two words",
    "_under",
    "-dash",
    ".",
    "",
    "x" * 101,
]


@pytest.mark.parametrize("name", [n for n in HOSTILE if n not in (".", "")])  # both name no folder of their own
def test_a_hostile_system_folder_is_refused_in_one_line(tmp_path, capsys, name):
    suite = box_suite(tmp_path / "suite", objects_per_source=1, n_parts=[3])
    task = read_manifest(suite).tasks[0].task_id
    write_scripted_run(tmp_path / "runs" / "alpha" / task, suite, task, system="alpha", jitter_edits=1)
    write_scripted_run(tmp_path / "runs" / name / task, suite, task, system="alpha", jitter_edits=1)
    code = aw_score([str(suite), str(tmp_path / "runs"), "--out", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert f"a system folder's name {ascii(name)} is not a system label" in err
    assert not (tmp_path / "out" / "report.md").exists()


@pytest.mark.parametrize("name", [n for n in HOSTILE if n])  # an empty --system gives the default label
def test_aw_run_refuses_the_same_names(tmp_path, capsys, name):
    assert system_label_problem(name) is not None
    suite = box_suite(tmp_path / "suite", objects_per_source=1, n_parts=[3])
    code = aw_run([str(suite), "--agent", "idle", f"--system={name}", "--out", str(tmp_path / "runs"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and f"--system {ascii(name)} is not a system label" in err, err


@pytest.mark.parametrize("name", ["alpha", "oracle-noise0.5", "claude_code+opus@2=x", "système", "r-then-a"])
def test_ordinary_labels_pass(name):
    assert system_label_problem(name) is None
    assert system_label_problem("") is not None
