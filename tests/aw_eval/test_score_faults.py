"""aw-score under faults, with real processes and real files: a second aw-score on a busy --out
is refused, a write that fails (file size limit, as a full disk) is one line and leaves no
temporary file, stale ones of a killed run are removed, and the scoring workers end with their
parent (SIGKILL, SIGTERM, SIGINT), the last two as an interrupt (exit 128 + the signal)."""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import time

import psutil
import pytest

from aw.formats import read_manifest
from aw.runlock import RunDirLock
from aw_eval.cli import main
from aw_eval.study.fixtures import box_suite, write_scripted_run

FAST = [
    "--protocol-setting",
    "n_surface=256",
    "--protocol-setting",
    "n_fps=64",
    "--bootstrap",
    "200",
    "--permutations",
    "500",
    "--no-progress",
    "--no-plots",
    "--no-html",
]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    root = tmp_path_factory.mktemp("faults")
    suite = box_suite(root / "suite", objects_per_source=1, n_parts=[4, 5])
    for t in [e.task_id for e in read_manifest(suite).tasks]:
        write_scripted_run(root / "runs" / "alpha" / t, suite, t, system="alpha", jitter_edits=20)
    return suite, root / "runs"


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)  # as in a terminal (a shell's background job starts with it ignored)


def _aw_score(study, out, *extra, preexec=_default_sigint, **kw) -> subprocess.Popen:
    suite, runs = study
    # No bytecode written: under a file size limit CPython would install .pyc files cut short.
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path), "PYTHONDONTWRITEBYTECODE": "1"}
    return subprocess.Popen(
        [sys.executable, "-m", "aw_eval.cli", str(suite), str(runs), "--out", str(out), *extra],
        env=env,
        preexec_fn=preexec,
        stderr=subprocess.PIPE,
        text=True,
        **kw,
    )


def test_a_busy_out_is_refused_naming_its_holder(study, tmp_path, capsys):
    suite, runs = study
    with RunDirLock(tmp_path / "out", command="aw-score other"):
        assert main([str(suite), str(runs), "--out", str(tmp_path / "out"), "--jobs", "1", *FAST]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"in use by pid {os.getpid()}" in err and "(aw-score other)" in err
    assert not (tmp_path / "out" / "scores.json").exists()


def _limit_file_size(limit: int):
    def pre() -> None:
        _default_sigint()
        signal.signal(
            signal.SIGXFSZ, signal.SIG_IGN
        )  # a write past the limit fails with EFBIG, as ENOSPC on a full disk
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return pre


@pytest.mark.parametrize("limit", [3_000, 20_000], ids=["geometry-cache", "scores-json"])
def test_a_failed_write_is_one_line_and_leaves_no_temporary_file(study, tmp_path, limit):
    """The write that fails first: the evaluator's geometry cache (a tool failure, not task errors), or scores.json."""
    out = tmp_path / "out"
    stale = out / "cache" / "runs" / "alpha" / "t" / "0123.npz.tmp999999999"  # as a killed run leaves it
    stale.parent.mkdir(parents=True)
    stale.write_bytes(b"half")
    proc = _aw_score(study, out, "--jobs", "1", "--final-only", *FAST, preexec=_limit_file_size(limit))
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 1 and "Traceback" not in err, err
    (line,) = [x for x in err.splitlines() if "error:" in x]
    assert (
        line.startswith("aw-score: error: ")
        and str(out) in line
        and "File too large" in line
        and "task_error" not in err
    )
    assert [p for p in out.rglob("*") if ".tmp" in p.name] == []


def _outputs(out) -> dict[str, bytes]:
    """Every output file's bytes (the cache and the lock file are not outputs)."""
    return {
        str(p.relative_to(out)): p.read_bytes()
        for p in sorted(out.rglob("*"))
        if p.is_file() and p.relative_to(out).parts[0] not in ("cache", ".aw-lock")
    }


def test_a_failed_report_write_names_its_file_keeps_the_report_and_clears_temporaries(study, tmp_path):
    """report.html's plotly bundle (about 5 MB) past a 1 MB limit: the error names it, the report
    before it stays byte for byte, no temporary file is left, and the next call removes those an
    older call left (as report_files/plotly-*.min.js.tmp<pid> after a full disk)."""
    out = tmp_path / "out"
    with_html = [a for a in FAST if a != "--no-html"]
    first = _aw_score(study, out, "--jobs", "1", "--final-only", *FAST)
    assert first.wait(timeout=600) == 0, first.stderr.read()
    first.stderr.close()
    before = _outputs(out)
    stale = [out / "report_files" / "plotly-0.0.min.js.tmp999999999", out / "report.html.tmp999999999"]
    stale[0].parent.mkdir()
    for p in stale:
        p.write_bytes(b"half")
    proc = _aw_score(study, out, "--jobs", "1", "--final-only", *with_html, preexec=_limit_file_size(1_000_000))
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 1 and "Traceback" not in err, err
    (line,) = [x for x in err.splitlines() if "error:" in x]
    assert line.startswith(f"aw-score: error: {out / 'report_files' / 'plotly-'}") and "File too large" in line
    assert {k: v for k, v in _outputs(out).items() if ".tmp" not in k} == before  # nothing replaced
    assert sorted(p.name for p in out.rglob("*") if ".tmp" in p.name) == sorted(p.name for p in stale)
    assert not [p for p in out.iterdir() if p.name.startswith(".report-")]  # no staging folder left
    again = _aw_score(study, out, "--jobs", "1", "--final-only", *with_html)
    assert again.wait(timeout=900) == 0, again.stderr.read()
    again.stderr.close()
    assert [p for p in out.rglob("*") if ".tmp" in p.name] == [] and (out / "report.html").is_file()


def _workers(proc: psutil.Process) -> list[psutil.Process]:
    return [c for c in proc.children(recursive=True) if "spawn_main" in " ".join(c.cmdline())]


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM, signal.SIGINT], ids=["SIGKILL", "SIGTERM", "SIGINT"])
def test_workers_end_with_their_parent(study, tmp_path, sig):
    proc = _aw_score(study, tmp_path / "out", "--jobs", "2", "--checkpoint-mode", "exact", *FAST)
    parent = psutil.Process(proc.pid)
    workers: list[psutil.Process] = []
    deadline = time.monotonic() + 300
    while len(workers) < 2 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
        workers = _workers(parent)
    assert len(workers) == 2, "the workers did not start"
    try:
        proc.send_signal(sig)
        code = proc.wait(timeout=60)
        _, alive = psutil.wait_procs(workers, timeout=60)  # before: they scored on for minutes
        assert alive == []
        assert code == (-signal.SIGKILL if sig == signal.SIGKILL else 128 + sig)  # 143 for SIGTERM, 130 for SIGINT
        if sig != signal.SIGKILL:
            err = proc.stderr.read()
            assert "aw-score: interrupted" in err and "leaked semaphore" not in err
    finally:
        for w in workers:
            if w.is_running():
                w.kill()
        proc.stderr.close()
