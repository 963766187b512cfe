"""``aw-demo`` end to end on the smallest suite it can build (one fracture pair)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from aw.demo import DEFAULT_PER_SOURCE, FULL_PER_SOURCE, parse_args, plan_line, summary_from_report, systems
from aw.formats import read_run_info


def test_demo_runs_the_whole_loop(tmp_path):
    demo = Path(sys.executable).with_name("aw-demo")
    out = tmp_path / "demo"
    proc = subprocess.run(
        [str(demo), "--out", str(out), "--per-source", "1", "--blocks", "fantastic_breaks", "--jobs", "2"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert proc.stdout.startswith(
        "aw-demo: builds a synthetic suite of 1 task, runs 4 systems on every task "
        "(4 episodes through aw-serve, 2 at a time)"
    )
    for n in range(1, 5):
        assert f"[{n}/4]" in proc.stdout
    # A line on stdout as each stage and each system finishes.
    assert "  suite ready (" in proc.stdout and "  scored and reported in " in proc.stdout
    labels = [s[0] for s in systems((0.5, 1.5))]
    for label in labels:
        (run_dir,) = [p for p in (out / "runs" / label).iterdir() if p.is_dir()]  # beside aw-run's .aw-batch.json
        assert read_run_info(run_dir / "run.json").ended == "finished"
        assert f"\n  {label}: finished 1 (" in proc.stdout
        assert label in proc.stdout.split("[4/4]")[1]  # every system is in the printed summary
    report = out / "report" / "report.md"
    assert report.is_file() and str(report) in proc.stdout
    page = out / "report" / "report.html"
    assert page.is_file() and str(page) in proc.stdout and 'section class="card"' in page.read_text()
    assert list((out / "report").rglob("*.png"))
    assert "never results" in proc.stdout and "95% CI" in proc.stdout
    # A second run reuses the suite and every finished episode.
    again = subprocess.run(
        [str(demo), "--out", str(out), "--per-source", "1", "--blocks", "fantastic_breaks", "--jobs", "2"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert again.returncode == 0 and "reusing the suite" in again.stdout
    assert "  idle: nothing to run, 1 reused (" in again.stdout


def test_summary_is_table_1_with_its_intervals(tmp_path):
    md = tmp_path / "r.md"
    md.write_text(
        "# Report\n\nintro\n\n## Table 1: results\n\n| system | SR |\n|---|---|\n| idle | 0.0 |\n\n"
        "## Other\n\n| a |\n|---|\n\n## Table A-3: with bootstrap intervals\n\n| System | SR | 95% CI |\n"
    )
    s = summary_from_report(md)
    assert s.startswith("## Table 1: results") and "| idle | 0.0 |" in s and "95% CI" in s and "Other" not in s
    md.write_text("# Report\n\nintro\n\n## Scores\n\n| a |\n|---|\n")
    assert summary_from_report(md).startswith("## Scores")


def test_the_demo_says_up_front_what_it_does_and_how_long_it_takes():
    line = plan_line(DEFAULT_PER_SOURCE, None, (0.5, 1.5), 2)  # the defaults on 2 cores
    assert line.startswith(
        "aw-demo: builds a synthetic suite of 5 tasks, runs 4 systems on every task "
        "(20 episodes through aw-serve, 2 at a time)"
    )
    assert line.endswith("expect about 2 minutes on 2 idle cores, longer when other work shares the cores")
    full = plan_line(FULL_PER_SOURCE, None, (0.5, 1.5), 2)
    assert "of 25 tasks" in full and "(100 episodes" in full and "expect about 7 minutes on 2 idle cores" in full
    assert "expect about 3 minutes on 1 idle core," in plan_line(DEFAULT_PER_SOURCE, None, (0.5, 1.5), 1)
    assert "expect about a minute on 2 idle cores" in plan_line(1, "fantastic_breaks", (0.5, 1.5), 2)
    assert "of 6 tasks, runs 3 systems" in plan_line(2, "partnet,ikea_manual,nonsense", (0.5,), 16)


def test_defaults_and_full_choose_the_suite_size():
    assert parse_args([]).per_source == DEFAULT_PER_SOURCE == 1
    assert parse_args(["--full"]).per_source == FULL_PER_SOURCE == 5
    assert parse_args(["--per-source", "3"]).per_source == 3


def test_full_and_per_source_together_are_a_usage_error(tmp_path):
    demo = Path(sys.executable).with_name("aw-demo")
    proc = subprocess.run(
        [str(demo), "--full", "--per-source", "3", "--out", str(tmp_path / "d")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2 and "not allowed with argument" in proc.stderr
    assert not (tmp_path / "d").exists()
