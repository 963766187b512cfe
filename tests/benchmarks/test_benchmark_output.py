"""Benchmarks write into the folder the user names and never over an existing file."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _bench_eval(out: Path) -> subprocess.CompletedProcess:
    # no part counts and no agreement: the run measures nothing and only writes its JSON
    return subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_eval.py"), "--parts", "--out", str(out), "--name", "empty"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )


def test_bench_eval_writes_into_out_and_refuses_to_overwrite(tmp_path):
    first = _bench_eval(tmp_path / "runs")
    assert first.returncode == 0, first.stderr
    written = tmp_path / "runs" / "empty.json"
    assert written.is_file() and '"command"' in written.read_text()
    before = written.read_text()
    again = _bench_eval(tmp_path / "runs")
    assert again.returncode == 1
    assert again.stderr.strip().splitlines() == [
        f"{written}: exists already; name another --out folder (benchmarks never overwrite results)"
    ]
    assert written.read_text() == before


def test_out_is_required():
    res = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_score.py")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert res.returncode == 2 and "--out" in res.stderr
