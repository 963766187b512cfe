"""aw-run --refinement-study end to end (the idle agent, a real external refiner script): four
systems with their start states recorded, refinement_study.json, aw-score's section; a refiner
that answers wrongly or hangs fails its arms by name and the agent's arm is kept."""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path

import numpy as np
import pytest

from aw.formats import read_final, read_run_info, read_trajectory
from aw.runner.cli import main as aw_run
from aw_eval.analyses.refinement import refinement_study
from aw_eval.report.refinement import render_refinement, write_refinement_plot

SCRIPT = Path(__file__).with_name("scripted_refiner.py")
TASKS = ["frac_cylinder_1", "frac_hex_prism_2"]
SYSTEMS = {
    "agent": "idle",
    "refiner": "scripted",
    "agent_refiner": "idle-then-scripted",
    "refiner_agent": "scripted-then-idle",
}


def _study(suite: Path, out: Path, behaviour: str, *extra: str) -> int:
    command = f"{shlex.quote(sys.executable)} {shlex.quote(str(SCRIPT))}"
    return aw_run(
        [
            str(suite),
            "--refinement-study",
            "--agent",
            "idle",
            "--refiner",
            "scripted",
            "--refiner-command",
            command,
            "--refiner-option",
            f"behaviour={behaviour}",
            "--refiner-option",
            "dx=0.125",
            "--out",
            str(out),
            "--jobs",
            "1",
            "--no-progress",
            *extra,
        ]
    )


@pytest.fixture(scope="module")
def good(fracture_suite, tmp_path_factory):
    out = tmp_path_factory.mktemp("study") / "runs"
    assert _study(fracture_suite, out, "shift") == 0
    return out


def test_four_systems_and_the_study_file(good, capsys):
    doc = json.loads((good / "refinement_study.json").read_text())
    assert doc["format"] == "assemblyworld.refinement-study" and doc["tasks"] == TASKS
    assert {a["arm"]: a["system"] for a in doc["arms"]} == SYSTEMS
    assert all(a["status"] == "ok" and a["failed_tasks"] == {} for a in doc["arms"])
    assert doc["agent"] == "idle" and doc["refiner"] == "scripted" and doc["refiner_steps"] == 20
    for system in SYSTEMS.values():
        for tid in TASKS:
            assert read_run_info(good / system / tid / "run.json").ended == "finished"


def test_composed_arms_start_from_the_first_arms_final_states(good):
    for tid in TASKS:
        refined = read_final(good / "scripted" / tid / "final.json").poses
        info = read_run_info(good / "scripted-then-idle" / tid / "run.json")
        assert info.extra["initial_poses"] == str((good / "scripted" / tid / "final.json").resolve())
        header = read_trajectory(good / "scripted-then-idle" / tid / "trajectory.jsonl").header
        assert header.initial_poses_from == info.extra["initial_poses"]
        for pid, pose in refined.items():
            assert np.allclose(header.initial_poses[pid], pose)
        # the refiner moved the non-anchor part by dx from where the idle agent left it (the layout)
        after = read_run_info(good / "idle-then-scripted" / tid / "run.json")
        assert after.extra["initial_poses"] == str((good / "idle" / tid / "final.json").resolve())
        moved = read_final(good / "idle-then-scripted" / tid / "final.json").poses
        shifts = sorted(round(moved[p][0], 9) for p in moved)
        assert shifts == [0.0, 0.125]


def test_score_section_table_pairs_and_plot(good, fracture_suite, tmp_path):
    section = refinement_study(fracture_suite, good)
    assert section["matched"] == TASKS and all(not f for f in section["failures"].values())
    table = section["table"]
    # the idle agent keeps the refiner's poses and the refiner shifts the idle agent's layout the same way
    for k in ("re", "te", "pa", "cd"):
        assert table["refiner"][k] == table["agent_refiner"][k] == table["refiner_agent"][k]
    assert table["agent"]["pa"] == 0.5  # the layout: only the anchor is in place
    by = {(p["arm"], p["baseline"], p["metric"]): p for p in section["pairs"]}
    assert by[("agent_refiner", "refiner", "pa")]["unchanged"] == 2
    assert by[("refiner_agent", "refiner", "cd")]["unchanged"] == 2
    text = render_refinement(section, "plots/x.png")
    assert (
        "| Refiner -> Agent | `scripted-then-idle` |" in text and "| Method | System | RE (deg) | TE (x100) |" in text
    )
    assert "Failed runs" not in text
    name = write_refinement_plot(section, tmp_path)
    assert (tmp_path / name).stat().st_size > 1000


def test_wrong_answers_fail_the_refiner_arms_and_keep_the_agent(fracture_suite, tmp_path, capsys):
    out = tmp_path / "runs"
    assert _study(fracture_suite, out, "nan") == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == (
        "aw-run: error: arms not complete: refiner, agent_refiner, refiner_agent (the others are "
        "written; see refinement_study.json)"
    )
    arms = {a["arm"]: a for a in json.loads((out / "refinement_study.json").read_text())["arms"]}
    assert arms["agent"]["status"] == "ok"
    assert arms["refiner"]["status"] == arms["agent_refiner"]["status"] == "failed"
    assert arms["refiner"]["failed_tasks"][TASKS[0]].startswith("refiner scripted: non-finite pose for fragment_")
    assert arms["refiner_agent"]["failed_tasks"] == {
        t: "no start state: arm refiner failed on this task" for t in TASKS
    }
    assert not (out / "scripted-then-idle").exists()  # the agent never ran from a failed refinement
    info = read_run_info(out / "scripted" / TASKS[0] / "run.json")
    assert info.ended == "error" and "non-finite pose" in info.error
    # the failed refinement leaves its start state, recorded as an error
    traj = read_trajectory(out / "scripted" / TASKS[0] / "trajectory.jsonl")
    assert traj.end.reason == "error" and traj.final_poses() == traj.header.initial_poses
    section = refinement_study(fracture_suite, out)
    assert section["matched"] == [] and len(section["failures"]["refiner"]) == 2
    assert "Failed runs (left out of the table)" in render_refinement(section)


def test_refiner_alone_past_its_time_limit(fracture_suite, tmp_path, capsys):
    command = f"{shlex.quote(sys.executable)} {shlex.quote(str(SCRIPT))}"
    code = aw_run(
        [
            str(fracture_suite),
            "--refiner-command",
            command,
            "--refiner-option",
            "behaviour=sleep",
            "--refiner-timeout",
            "1",
            "--tasks",
            TASKS[0],
            "--out",
            str(tmp_path / "runs"),
            "--no-progress",
        ]
    )
    captured = capsys.readouterr()
    assert code == 1
    assert f"{TASKS[0]}: refiner scripted_refiner.py: timed out after 1 s (killed)" in captured.out
    assert captured.err.strip().startswith("aw-run: error: the refiner failed on every task")


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--refiner", "nope", "--out", "x"], "aw-run: error: unknown refiner 'nope'; available: classical"),
        (
            ["--refiner", "classical", "--agent", "idle", "--out", "x"],
            "to compose it with an agent use --refinement-study",
        ),
        (["--refinement-study", "--refiner", "classical", "--out", "x"], "--refinement-study needs --agent NAME"),
        (["--out", "x"], "give --agent NAME, --harness NAME or --refiner NAME"),
    ],
)
def test_usage_errors(fracture_suite, argv, message, capsys):
    assert aw_run([str(fracture_suite), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_refiner_options_keep_words_that_read_as_non_finite_numbers():
    from aw.runner.refiner_cli import _option

    assert _option("behaviour=nan") == ("behaviour", "nan")
    assert _option("mode=inf") == ("mode", "inf")
    assert _option("dx=0.125") == ("dx", 0.125) and _option("n=3") == ("n", 3)


def test_aw_score_outputs_carry_the_section(good, fracture_suite, tmp_path):
    """write_outputs (aw-score's last step) adds the section to report.md, report.html and
    scores.json when RUNS holds refinement_study.json; the rest of the report is another study."""
    sys.path.insert(0, str(Path(__file__).parents[2] / "aw_eval"))
    from score_helpers import table1_study

    from aw_eval.report import AnalysisSettings, write_outputs

    res = write_outputs(
        table1_study(),
        tmp_path / "out",
        AnalysisSettings(n_draws=50, n_permutations=50),
        suite_dir=str(fracture_suite),
        runs_dir=str(good),
        plots=True,
        html=True,
    )
    md = (tmp_path / "out" / "report.md").read_text()
    assert "## Bidirectional refinement" in md and "| Agent -> Refiner | `idle-then-scripted` |" in md
    assert (
        "(plots/refinement_paired_cd.png)" in md and (tmp_path / "out" / "plots" / "refinement_paired_cd.png").is_file()
    )
    assert res["doc"]["refinement"]["matched"] == TASKS
    page = (tmp_path / "out" / "report.html").read_text()
    assert "Bidirectional refinement" in page and 'src="plots/refinement_paired_cd.png"' in page
    plain = tmp_path / "plain"
    write_outputs(
        table1_study(),
        plain,
        AnalysisSettings(n_draws=50, n_permutations=50),
        suite_dir=str(fracture_suite),
        runs_dir=str(tmp_path),
        plots=False,
        html=False,
    )  # no study file: no section
    assert "Bidirectional refinement" not in (plain / "report.md").read_text()
