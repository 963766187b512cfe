"""The aw-view command: one-line usage errors, and a token for any address but this machine's;
aw-run --view starts it on the batch's runs folder; aw-score --viewer-url links the report to it."""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from view_helpers import ONE_TASK, fetch, get_json, viewer

from aw.formats import read_manifest
from aw_view.cli import main


def _bin(name: str) -> str:
    return str(Path(sys.executable).with_name(name))


def _error(capsys, argv: list[str]) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("aw-view: error: "), err
    return err[0]


def test_usage_errors_are_one_line(tmp_path, capsys):
    (tmp_path / "runs").mkdir()
    runs = str(tmp_path / "runs")
    assert "no such directory" in _error(capsys, [str(tmp_path / "nope")])
    assert "--cache applies with --suite" in _error(capsys, [runs, "--cache", str(tmp_path / "c")])
    assert "--suite" in _error(capsys, [runs, "--suite", str(tmp_path / "nope")])
    (tmp_path / "suite").mkdir()
    assert "manifest.json" in _error(capsys, [runs, "--suite", str(tmp_path / "suite")])
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    try:
        line = _error(capsys, [runs, "--port", str(busy.getsockname()[1])])
        assert "cannot serve on 127.0.0.1" in line and "another --port" in line
    finally:
        busy.close()


def test_another_address_needs_the_token_in_the_printed_url(tmp_path):
    (tmp_path / "runs").mkdir()
    proc = subprocess.Popen(
        [_bin("aw-view"), str(tmp_path / "runs"), "--host", "0.0.0.0", "--port", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = proc.stdout.readline()
        m = re.search(r" at http://[^:]+:(\d+)/\?token=(\S+)$", line.strip())
        assert m, line
        port, token = m.groups()
        base = f"http://127.0.0.1:{port}/"
        assert fetch(base + "api/runs")[0] == 403
        assert fetch(base + "api/runs?token=wrong")[0] == 403
        status, _, headers = fetch(f"{base}?token={token}")
        assert status == 200 and "HttpOnly" in headers["Set-Cookie"]
        cookie = headers["Set-Cookie"].split(";")[0]
        assert fetch(base + "api/runs", {"Cookie": cookie})[0] == 200  # the page's own requests
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    err = proc.stderr.read()
    assert "warning: serving on 0.0.0.0" in err and "token" in err and "Traceback" not in err
    proc.stdout.close()
    proc.stderr.close()


def test_loopback_answers_only_requests_addressed_to_this_machine(tmp_path):
    (tmp_path / "runs").mkdir()
    with viewer(tmp_path / "runs") as url:
        assert fetch(url + "api/runs")[0] == 200
        status, body, _ = fetch(url + "api/runs", {"Host": "attacker.example:80"})  # DNS rebinding
        assert status == 403 and b"127.0.0.1 or localhost" in body
        assert fetch(url + "api/nothing")[0] == 404


@pytest.fixture(scope="module")
def small_suite(tmp_path_factory):
    from aw_eval.study.fixtures import box_suite

    return box_suite(tmp_path_factory.mktemp("cli") / "suite", objects_per_source=1, n_parts=2, blocks=ONE_TASK)


def test_aw_run_view_starts_the_viewer_on_the_batch_and_stops_it_with_the_batch(small_suite, tmp_path):
    out = tmp_path / "runs"
    proc = subprocess.Popen(
        [_bin("aw-run"), str(small_suite), "--agent", "idle", "--out", str(out), "--view", "--no-progress"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYOPENGL_PLATFORM": os.environ.get("PYOPENGL_PLATFORM", "egl")},
    )
    first = proc.stdout.readline()
    m = re.match(r"aw-run: watch the episodes at (http://127\.0\.0\.1:\d+/)$", first.strip())
    assert m, first
    rows = get_json(m.group(1) + "api/runs")["rows"]  # the batch has started: queued or running
    (task_id,) = [t.task_id for t in read_manifest(small_suite).tasks]
    assert [r["id"] for r in rows] in ([], [f"idle/{task_id}"])
    rest, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err
    assert "idle: 1 episode" in rest and "the viewer stopped with the batch" in err
    with pytest.raises(OSError):  # the viewer is gone
        socket.create_connection(("127.0.0.1", int(m.group(1).rsplit(":", 1)[1].strip("/"))), timeout=5).close()
    plan = (out / "idle" / ".aw-batch.json").read_text()
    assert task_id in plan and '"finished_unix": null' not in plan
    proc.stdout.close()
    proc.stderr.close()


def test_view_applies_to_batches_only(small_suite, tmp_path):
    proc = subprocess.run(
        [_bin("aw-run"), str(small_suite), "--harness", "codex", "--check", "--view"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2 and "aw-run: error: --view applies to --agent and --harness batches" in proc.stderr
