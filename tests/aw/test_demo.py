"""``aw-demo`` end to end on the smallest suite it can build (one fracture pair)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from aw.demo import plan_line, summary_from_report, systems
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
    labels = [s[0] for s in systems((0.5, 1.5))]
    for label in labels:
        (run_dir,) = [p for p in (out / "runs" / label).iterdir() if p.is_dir()]  # beside aw-run's .aw-batch.json
        assert read_run_info(run_dir / "run.json").ended == "finished"
        assert label in proc.stdout  # every system is in the printed summary
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
    line = plan_line(5, None, (0.5, 1.5), 2)  # the defaults on 2 cores
    assert line.startswith(
        "aw-demo: builds a synthetic suite of 25 tasks, runs 4 systems on every task "
        "(100 episodes through aw-serve, 2 at a time)"
    )
    assert line.endswith("expect about 3 to 10 minutes on 2 cores, longer when other work shares the cores")
    assert plan_line(1, "fantastic_breaks", (0.5, 1.5), 2).endswith(
        "expect under a minute on 2 cores (scaled from 3 to 10 minutes with the defaults on 2 cores), longer when "
        "other work shares the cores"
    )
    assert "of 6 tasks, runs 3 systems" in plan_line(2, "partnet,ikea_manual,nonsense", (0.5,), 16)
