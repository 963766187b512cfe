"""Failures of the scoring tool are errors of the command, never runs scored 0; misread inputs
are refused; a final.json that contradicts its trajectory is named in scores.json and the report."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from score_helpers import make_study, paper_entries, run_from_errors

from aw.formats import FinalState, read_final, read_manifest, write_final
from aw_eval.cli import main
from aw_eval.report import AnalysisSettings
from aw_eval.report.markdown import render_markdown
from aw_eval.report.results import build_results
from aw_eval.study import ScoreSettings, StudyError, score_study
from aw_eval.study.fixtures import box_suite, write_scripted_run
from tests.aw.formats.hostile_json import DEEP, DUPLICATE, HUGE, inject, inject_line

PROTO = ["--protocol", "n_surface=256", "--protocol", "n_fps=64", "--final", "fast"]
FAST = ["--bootstrap", "50", "--permutations", "50", "--no-progress", "--no-plots", "--no-html", "--jobs", "1"]


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    root = tmp_path_factory.mktemp("fail")
    suite = box_suite(
        root / "suite",
        objects_per_source=1,
        n_parts=2,
        blocks=(("fantastic_breaks", ("none",)), ("partnet", ("none",))),
    )
    tasks = [e.task_id for e in read_manifest(suite).tasks]
    runs = root / "runs"
    for t in tasks:
        write_scripted_run(runs / "alpha" / t, suite, t, system="alpha", inspect_moves=False)
    return root, suite, runs, tasks


def test_one_systems_folder_is_refused_with_a_hint(small, tmp_path, capsys):
    root, suite, runs, tasks = small
    with pytest.raises(StudyError, match="looks like one system's folder"):
        score_study(suite, runs / "alpha", tmp_path / "o", ScoreSettings())
    assert main([str(suite), str(runs / "alpha"), "--out", str(tmp_path / "o"), *FAST]) == 2
    err = capsys.readouterr().err
    # aw-score says it first, with the command to type (aw.cli.paths)
    assert f"{runs / 'alpha'} is one system's runs folder; RUNS is the folder above it" in err
    assert f": aw-score {suite} {runs} --out" in err
    assert not (tmp_path / "o" / "scores.json").exists()


def test_contradicting_final_json_is_named_and_the_trajectory_wins(small, tmp_path, capsys):
    root, suite, runs, tasks = small
    forged_runs = tmp_path / "runs"
    import shutil

    shutil.copytree(runs, forged_runs)
    run_dir = forged_runs / "alpha" / tasks[0]
    final = read_final(run_dir / "final.json")
    pid = sorted(final.poses)[0]
    final.poses[pid] = [5.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
    write_final(run_dir / "final.json", FinalState(task_id=final.task_id, reason=final.reason, poses=final.poses))
    out = tmp_path / "out"
    assert main([str(suite), str(forged_runs), "--out", str(out), *PROTO, *FAST]) == 0
    doc = json.loads((out / "scores.json").read_text())
    run = next(r for r in doc["runs"] if r["task_id"] == tasks[0])
    assert run["final_from"] == "trajectory" and run["sr"] == 1.0
    assert any("contradicts the trajectory" in p and pid in p for p in run["problems"])
    assert "contradicts the trajectory" in (out / "report.md").read_text()
    trusted = tmp_path / "trusted"
    assert main([str(suite), str(forged_runs), "--out", str(trusted), "--trust-final", *PROTO, *FAST]) == 0
    doc = json.loads((trusted / "scores.json").read_text())
    run = next(r for r in doc["runs"] if r["task_id"] == tasks[0])
    assert run["final_from"] == "final.json" and run["sr"] == 0.0 and doc["settings"]["trust_final"] is True


def test_hostile_run_files_are_that_runs_named_problem_never_the_commands_death(small, tmp_path):
    """The real command on runs whose files hold what no writer makes: each bad file is named in
    that run's row of scores.json (scored from the other record where one is readable, else an
    unreadable row), the rest is scored, and no traceback is printed."""
    import shutil

    root, suite, runs, tasks = small
    runs_dir, (t0, t1) = tmp_path / "runs", tasks
    for system in ("deep", "numbers", "both"):
        shutil.copytree(runs / "alpha", runs_dir / system)
    (runs_dir / "deep" / t0 / "run.json").write_text(inject({"format": "assemblyworld.run"}, ("format",), DEEP))
    inject_line(runs_dir / "deep" / t1 / "trajectory.jsonl", 3, DEEP)
    final = json.loads((runs_dir / "numbers" / t0 / "final.json").read_text())
    pid = sorted(final["poses"])[0]
    (runs_dir / "numbers" / t0 / "final.json").write_text(inject(final, ("poses", pid, 0), HUGE))
    final["poses"][pid][0] = 1e300
    (runs_dir / "numbers" / t1 / "final.json").write_text(json.dumps(final))
    (runs_dir / "both" / t0 / "final.json").write_text(inject({}, ("poses",), DEEP))
    inject_line(runs_dir / "both" / t0 / "trajectory.jsonl", 1, DEEP)
    (runs_dir / "both" / t1 / "run.json").write_text(inject({"format": "assemblyworld.run"}, ("format",), DUPLICATE))

    out = tmp_path / "out"
    proc = subprocess.run(
        [str(Path(sys.executable).with_name("aw-score")), str(suite), str(runs_dir), "--out", str(out)]
        + [*PROTO, *FAST],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    assert "3 systems x 2 tasks: 0 runs from the cache, 6 scored now, unscored: 1 unreadable" in proc.stderr
    rows = {(r["system"], r["task_id"]): r for r in json.loads((out / "scores.json").read_text())["runs"]}

    def said(system, task):
        r = rows[(system, task)]
        return r["status"], r["problems"], r["run_json_problem"]

    traj = f"trajectory unreadable: {runs_dir}/{{}}/{{}}/trajectory.jsonl: line {{}}: {DEEP.message}"
    assert said("deep", t0) == ("scored", [], f"run.json unreadable: {DEEP.message}")
    assert said("deep", t1) == ("scored", [traj.format("deep", t1, 3)], None)
    status, (problem,), _ = said("numbers", t0)
    assert status == "scored" and problem.startswith(f"final.json unreadable ({HUGE.message}")
    assert said("numbers", t1) == (
        "scored",
        [f"final.json unreadable (poses.{pid}: Value error, pose position beyond +-1e+06 scene units)"],
        None,
    )
    assert said("both", t0) == (
        "unreadable",
        [f"{traj.format('both', t0, 1)}; final.json unreadable ({DEEP.message})"],
        None,
    )
    assert said("both", t1) == ("scored", [], f"run.json unreadable: {DUPLICATE.message}")


SCRIPT = textwrap.dedent("""
    # The library snippet without a __main__ guard: spawned workers re-import this file.
    import sys
    from aw_eval.study import ScoreSettings, score_study
    from aw_eval.report import AnalysisSettings, write_outputs
    settings = ScoreSettings(protocol=(("n_surface", 256.0), ("n_fps", 64.0)))
    study, stats = score_study(sys.argv[1], sys.argv[2], sys.argv[3], settings, n_jobs=2, progress=False)
    write_outputs(study, sys.argv[3], AnalysisSettings(n_draws=50, n_permutations=50), plots=False, html=False)
""")


def test_a_broken_process_pool_is_an_error_not_zeros(small, tmp_path):
    root, suite, runs, tasks = small
    script = tmp_path / "score_script.py"
    script.write_text(SCRIPT)
    out = tmp_path / "out"
    res = subprocess.run(
        [sys.executable, str(script), str(suite), str(runs), str(out)],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
    )
    assert res.returncode != 0
    assert "ScoringFailed: scoring failed: a scoring worker process died or broke" in res.stderr
    assert "BrokenProcessPool" in res.stderr and 'if __name__ == "__main__":' in res.stderr
    assert not (out / "scores.json").exists() and not (out / "report.md").exists()


def test_runs_the_tool_failed_to_score_mark_the_study_partial():
    entries = paper_entries(n_objects=2)
    runs = {("A", e.task_id): run_from_errors("A", e.task_id, [0.001, 0.002]) for e in entries}
    doc = build_results(make_study(entries, runs), AnalysisSettings(n_draws=20, n_permutations=20))
    assert doc["partial"] is False and "PARTIAL" not in render_markdown(doc)
    runs[("A", entries[0].task_id)] = run_from_errors("A", entries[0].task_id, [], status="error")
    doc = build_results(make_study(entries, runs), AnalysisSettings(n_draws=20, n_permutations=20))
    assert doc["partial"] is True and doc["unscored_runs"]["error"][0]["task_id"] == entries[0].task_id
    assert "**PARTIAL STUDY: 1 run could not be scored" in render_markdown(doc)


def test_a_lost_dask_worker_is_an_error_not_zeros(small, tmp_path):
    import signal
    import threading
    import time

    import dask
    import psutil
    from distributed import Client, LocalCluster

    from aw_eval.study import ScoringFailed

    root, suite, runs, tasks = small
    outcome: dict = {}

    def score(address: str) -> None:
        try:
            outcome["study"] = score_study(
                suite, runs, tmp_path / "o", ScoreSettings(), scheduler=address, progress=False
            )
        except Exception as exc:
            outcome["error"] = exc

    # No retry on another worker: the first worker lost mid-task fails the task (KilledWorker).
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
            thread = threading.Thread(target=score, args=(cluster.scheduler_address,))
            thread.start()
            with Client(cluster.scheduler_address) as watcher:
                while not any(watcher.processing().values()):
                    assert thread.is_alive(), outcome
                    time.sleep(0.02)
                workers = [
                    p for p in psutil.Process().children(recursive=True) if "spawn_main" in " ".join(p.cmdline())
                ]
                assert workers
                for p in workers:
                    os.kill(p.pid, signal.SIGKILL)
                thread.join(600)
    assert "study" not in outcome
    err = outcome["error"]
    assert isinstance(err, ScoringFailed) and "a Dask worker died or broke while scoring task" in str(err)
    assert "KilledWorker" in str(err)
