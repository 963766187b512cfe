"""A run still being recorded is never scored as finished: a real aw-serve, driven by the MCP SDK
client over stdio, keeps its session (and its run directory's lock) open while aw-score runs.
By default the run is left out (status running), said on stderr, in the printed table and the
report, and aw-score exits 1; with --allow-running it is scored at its last state and marked
running in scores.json, tasks.csv, report.md and report.html's card; once the session ends it is
scored as any finished run."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import anyio
import pytest
from mcp import Client, StdioServerParameters

from aw.formats import read_manifest, read_task
from aw.formats.suite import suite_paths
from aw.runlock import run_in_progress
from aw_eval.study.fixtures import box_suite, write_scripted_run

pytestmark = pytest.mark.anyio

FAST = ["--protocol-setting", "n_surface=256", "--protocol-setting", "n_fps=64"]
FAST += ["--bootstrap", "200", "--permutations", "500", "--no-progress", "--no-plots", "--jobs", "1"]


@pytest.fixture
def anyio_backend():
    return "asyncio"


def _aw_score(suite: Path, runs: Path, out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "aw_eval.cli", str(suite), str(runs), "--out", str(out), *FAST, *extra],
        capture_output=True,
        text=True,
        timeout=900,
    )


def _run_of(out: Path, system: str, task_id: str) -> dict:
    doc = json.loads((out / "scores.json").read_text())
    return next(r for r in doc["runs"] if r["system"] == system and r["task_id"] == task_id)


def _csv_row(out: Path, system: str, task_id: str) -> dict:
    with open(out / "tasks.csv", newline="") as fh:
        return next(r for r in csv.DictReader(fh) if r["system"] == system and r["task_id"] == task_id)


async def test_a_live_aw_serve_run_is_left_out_or_scored_as_running(tmp_path):
    suite = box_suite(tmp_path / "suite", objects_per_source=1, n_parts=[3])
    ids = [e.task_id for e in read_manifest(suite).tasks][:2]
    runs = tmp_path / "runs"
    write_scripted_run(runs / "alpha" / ids[0], suite, ids[0], system="alpha", jitter_edits=3)
    live_task, live_dir = ids[1], runs / "alpha" / ids[1]
    task_dir = suite_paths(suite, live_task)[0]
    part = read_task(task_dir).part_ids[0]
    cmd = [sys.executable, "-m", "aw_server.cli", str(task_dir), "--record", str(live_dir), "--system", "alpha"]
    params = StdioServerParameters(command=cmd[0], args=cmd[1:], env=dict(os.environ))
    async with Client(params) as c:
        await c.call_tool("start_episode", {})
        await c.call_tool("translate_objects", {"ids": [part], "delta": [0.2, 0.0, 0.0]})
        assert run_in_progress(live_dir) is not None  # the one check aw-score (and aw-view) make

        left_out = await anyio.to_thread.run_sync(lambda: _aw_score(suite, runs, tmp_path / "out", "--no-html"))
        assert left_out.returncode == 1, left_out.stderr
        assert "Traceback" not in left_out.stderr
        assert f"WARNING: 1 run is still being recorded (alpha/{live_task}; pid " in left_out.stderr
        assert left_out.stderr.strip().splitlines()[-1].startswith("aw-score: error: 1 run is still being recorded")
        assert "[WARNING: 1 run still running, left out (counted 0)]" in left_out.stdout
        run = _run_of(tmp_path / "out", "alpha", live_task)
        assert run["status"] == "running" and run["running"] and run["pa"] == 0
        assert _csv_row(tmp_path / "out", "alpha", live_task)["ended"] == "running"
        report = (tmp_path / "out" / "report.md").read_text()
        assert "1 run was still being recorded when scored (a live lock): left out" in report

        scored = await anyio.to_thread.run_sync(lambda: _aw_score(suite, runs, tmp_path / "out2", "--allow-running"))
        assert scored.returncode == 0, scored.stderr
        assert "[WARNING: 1 run still running, scored at its last state]" in scored.stdout
        run = _run_of(tmp_path / "out2", "alpha", live_task)
        assert run["status"] == "scored" and run["running"]
        assert any("scored at its last state" in p for p in run["problems"])
        assert _csv_row(tmp_path / "out2", "alpha", live_task)["ended"] == "running"
        assert "**running**, final state from" in (tmp_path / "out2" / "report.md").read_text()
        assert "running: scored at its last state" in (tmp_path / "out2" / "report.html").read_text()
        assert _run_of(tmp_path / "out2", "alpha", ids[0])["running"] is False

    assert run_in_progress(live_dir) is None  # the session ended: the run is finished
    done = _aw_score(suite, runs, tmp_path / "out2", "--no-html")  # the same --out: the live score was not cached
    assert done.returncode == 0, done.stderr
    run = _run_of(tmp_path / "out2", "alpha", live_task)
    assert run["status"] == "scored" and not run["running"] and run["final_from"] == "final.json"
    assert "still running" not in done.stdout
