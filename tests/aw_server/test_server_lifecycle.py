"""How sessions end: client killed mid-episode, server signalled, budget exhausted; the HTTP
transport; and start-up refusals."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import anyio
import pytest
from aw_server_helpers import result_text, server_command, server_params
from mcp import Client

from aw.formats import read_final, read_trajectory

pytestmark = pytest.mark.anyio

IDENTITY = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]


def _wait_for(path: Path, timeout: float = 60.0) -> None:
    t0 = time.monotonic()
    while not path.exists():
        assert time.monotonic() - t0 < timeout, f"{path.name} did not appear"
        time.sleep(0.05)


def _server_pids(run_dir: Path) -> list[int]:
    """Pids of aw-serve processes recording into ``run_dir`` (read-only scan of /proc)."""
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                cmd = (d / "cmdline").read_bytes().split(b"\0")
            except OSError:
                continue
            if b"aw_server.cli" in cmd and str(run_dir).encode() in cmd:
                out.append(int(d.name))
    return out


CLIENT_SCRIPT = """
import sys, anyio
from mcp import Client, StdioServerParameters

async def main():
    params = StdioServerParameters(command=sys.argv[1], args=sys.argv[2:], env=dict(__import__("os").environ))
    async with Client(params) as c:
        await c.call_tool("start_episode", {})
        await c.call_tool("translate_objects", {"ids": ["p02"], "delta": [0.5, 0, 0]})
        await c.call_tool("set_object_pose", {"id": "p03", "quaternion": [0, 1, 0, 0]})
        print("READY", flush=True)
        await anyio.sleep(600)

anyio.run(main)
"""


def test_client_killed_mid_episode(box_task, tmp_path):
    task_dir, _, _ = box_task
    run = tmp_path / "run"
    script = tmp_path / "client.py"
    script.write_text(textwrap.dedent(CLIENT_SCRIPT))
    client = subprocess.Popen(
        [sys.executable, str(script), *server_command(task_dir, run)], stdout=subprocess.PIPE, text=True
    )
    try:
        line = client.stdout.readline()
        assert line.strip() == "READY"
        assert not (run / "final.json").exists()
        client.kill()  # SIGKILL: the client cannot say goodbye; the server sees stdin close
        client.wait(timeout=30)
        _wait_for(run / "final.json")
    finally:
        client.kill()
        client.wait()
        client.stdout.close()
    t0 = time.monotonic()
    while _server_pids(run) and time.monotonic() - t0 < 30:
        time.sleep(0.1)
    leftover = _server_pids(run)
    for pid in leftover:
        os.kill(pid, signal.SIGKILL)
    assert not leftover, "aw-serve did not exit after its client died"

    final = read_final(run / "final.json")
    assert final.reason == "disconnect"
    assert final.poses["p02"] == [0.5, 0, 0, 1, 0, 0, 0]
    assert final.poses["p03"] == [0, 0, 0, 0, 1, 0, 0]
    assert final.poses["p01"] == IDENTITY
    traj = read_trajectory(run / "trajectory.jsonl")
    assert traj.end is not None and traj.end.reason == "disconnect" and traj.end.poses == final.poses
    assert [c.tool for c in traj.calls] == ["start_episode", "translate_objects", "set_object_pose"]


def _rpc(proc, id_, method, params=None):
    msg = {"jsonrpc": "2.0", "method": method}
    if id_ is not None:
        msg["id"] = id_
    if params is not None:
        msg["params"] = params
    proc.stdin.write(json.dumps(msg) + "\n")
    proc.stdin.flush()
    if id_ is None:
        return None
    while True:
        line = proc.stdout.readline()
        assert line, "server closed stdout"
        reply = json.loads(line)
        if reply.get("id") == id_:
            return reply


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_server_signalled(box_task, tmp_path, signum):
    task_dir, _, _ = box_task
    run = tmp_path / "run"
    proc = subprocess.Popen(
        server_command(task_dir, run), stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    watchdog = threading.Timer(90, proc.kill)
    watchdog.start()
    try:
        init = {"protocolVersion": "2025-06-18", "capabilities": {}, "clientInfo": {"name": "t", "version": "0"}}
        _rpc(proc, 1, "initialize", init)
        _rpc(proc, None, "notifications/initialized")
        _rpc(proc, 2, "tools/call", {"name": "start_episode", "arguments": {}})
        r = _rpc(
            proc, 3, "tools/call", {"name": "translate_objects", "arguments": {"ids": ["p01"], "delta": [0, 0, 2]}}
        )
        assert r["result"]["isError"] is False
        proc.send_signal(signum)
        code = proc.wait(timeout=60)
    finally:
        watchdog.cancel()
        proc.kill()
        proc.wait()
        for f in (proc.stdin, proc.stdout, proc.stderr):
            f.close()
    assert code == 128 + signum
    final = read_final(run / "final.json")
    assert final.reason == "interrupted" and final.poses["p01"] == [0, 0, 2, 1, 0, 0, 0]
    traj = read_trajectory(run / "trajectory.jsonl")
    assert traj.end.reason == "interrupted" and signal.Signals(signum).name in traj.end.message


async def test_budget_exhausted(box_task, tmp_path):
    task_dir, _, _ = box_task
    run = tmp_path / "run"
    async with Client(server_params(task_dir, run, "--budget-minutes", "0.01")) as c:  # 0.6 s
        # The first edit starts the clock even without start_episode, which then changes nothing.
        await c.call_tool("translate_objects", {"ids": ["p01"], "delta": [1, 0, 0]})
        r = await c.call_tool("start_episode", {})
        assert r.structured_content["episode"]["budget_minutes"] == 0.01
        assert "already started" in r.structured_content["message"]
        ok = await c.call_tool("translate_objects", {"ids": ["p02"], "delta": [0, 1, 0]})
        assert not ok.is_error
        await anyio.sleep(1.0)
        # The timer keeps the final state as soon as the budget runs out, before anyone asks.
        _wait_for(run / "final.json", timeout=10)
        assert read_final(run / "final.json").reason == "timeout"
        for tool, args in [
            ("translate_objects", {"ids": ["p02"], "delta": [0, 1, 0]}),
            ("rotate_objects", {"ids": ["p02"], "angles": [0, 0, 10]}),
            ("set_object_pose", {"id": "p03", "position": [0, 0, 0]}),
            ("group_objects", {"ids": ["p01", "p02"]}),
        ]:
            refused = await c.call_tool(tool, args)
            assert refused.is_error and "budget" in result_text(refused) and "refused" in result_text(refused)
        # Queries and the camera still work; nothing moved.
        st = await c.call_tool("get_state", {})
        assert not st.is_error and st.structured_content["episode"]["timed_out"] is True
        assert st.structured_content["poses"]["p02"]["position"] == [0, 1, 0]
        assert not (await c.call_tool("move_camera", {"yaw": 5})).is_error
        again = await c.call_tool("start_episode", {})
        assert "already started" in again.structured_content["message"]
    final = read_final(run / "final.json")
    assert final.reason == "timeout"
    assert final.poses["p01"] == [1, 0, 0, 1, 0, 0, 0] and final.poses["p02"] == [0, 1, 0, 1, 0, 0, 0]
    traj = read_trajectory(run / "trajectory.jsonl")
    assert traj.end.reason == "timeout"
    assert [c.ok for c in traj.calls if c.tool != "get_state"] == [
        True,
        True,
        True,
        False,
        False,
        False,
        False,
        True,
        True,
    ]
    assert traj.calls[0].episode_active is True and 0.0 <= traj.calls[0].t <= traj.calls[1].t  # its edit started it


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def test_http_transport(box_task, tmp_path):
    task_dir, _, _ = box_task
    run = tmp_path / "run"
    port = _free_port()
    proc = subprocess.Popen(
        server_command(task_dir, run, "--transport", "http", "--port", str(port)),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        t0 = time.monotonic()
        while True:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    break
            assert proc.poll() is None, proc.stderr.read()
            assert time.monotonic() - t0 < 60, "HTTP server did not come up"
            await anyio.sleep(0.1)
        async with Client(f"http://127.0.0.1:{port}/mcp") as c:
            assert len((await c.list_tools()).tools) == 12
            await c.call_tool("start_episode", {})
            r = await c.call_tool("translate_objects", {"ids": ["p03"], "delta": [0, 0, 0.5]})
            assert not r.is_error
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=60)
        err = proc.stderr.read()
    finally:
        proc.kill()
        proc.wait()
        proc.stderr.close()
    assert f"http://127.0.0.1:{port}/mcp" in err
    final = read_final(run / "final.json")
    assert final.reason == "interrupted" and final.poses["p03"] == [0, 0, 0.5, 1, 0, 0, 0]


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "aw_server.cli", *args],
        capture_output=True,
        text=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
    )


def test_startup_refusals(box_task, tmp_path):
    task_dir, _, _ = box_task
    run = tmp_path / "run"
    run.mkdir()
    (run / "trajectory.jsonl").write_text("{}\n")
    busy = _cli(str(task_dir), "--record", str(run))
    assert busy.returncode == 2 and "already holds a recording" in busy.stderr and "--overwrite" in busy.stderr
    assert (run / "trajectory.jsonl").read_text() == "{}\n"
    missing = _cli(str(tmp_path / "nope"), "--record", str(run))
    assert missing.returncode == 2 and "task directory not found" in missing.stderr
    no_record = _cli(str(task_dir))
    assert no_record.returncode == 2 and "--record" in no_record.stderr
    bad_budget = _cli(str(task_dir), "--record", str(run), "--budget-minutes", "0")
    assert bad_budget.returncode == 2 and "positive" in bad_budget.stderr
    nan_budget = _cli(str(task_dir), "--record", str(run), "--budget-minutes", "nan")
    assert nan_budget.returncode == 2
    for huge in ("1e9", "1e308"):  # once a traceback in the expiry timer, or Infinity in results
        res = _cli(str(task_dir), "--record", str(run), "--budget-minutes", huge)
        assert res.returncode == 2 and "at most 100000" in res.stderr and "Traceback" not in res.stderr


async def test_overwrite_of_a_live_recording_is_refused(box_task, tmp_path):
    """A second ``aw-serve --overwrite`` on a directory a live server records into is refused,
    naming the live server; the first server's recording is complete."""
    task_dir, _, _ = box_task
    run = tmp_path / "run"
    async with Client(server_params(task_dir, run)) as c:
        await c.call_tool("translate_objects", {"ids": ["p02"], "delta": [0.5, 0, 0]})
        (live_pid,) = _server_pids(run)
        second = await anyio.to_thread.run_sync(lambda: _cli(str(task_dir), "--record", str(run), "--overwrite"))
        assert second.returncode == 2
        assert f"is being recorded by pid {live_pid}" in second.stderr and "cli.py" in second.stderr.split("(", 1)[1]
        await c.call_tool("set_object_pose", {"id": "p03", "position": [0, 0, 1]})
    traj = read_trajectory(run / "trajectory.jsonl")
    assert [c.tool for c in traj.calls] == ["translate_objects", "set_object_pose"] and traj.end.reason == "disconnect"
    assert read_final(run / "final.json").poses["p03"] == [0, 0, 1, 1, 0, 0, 0]
    assert sorted(p.name for p in (run / "captures").iterdir()) == []


async def test_record_under_numbers_the_sessions_of_one_config(box_task, tmp_path):
    """One command line (as in a .mcp.json) for many sessions: each records in a new attempt dir."""
    task_dir, _, _ = box_task
    parent = tmp_path / "runs"
    cmd = [sys.executable, "-m", "aw_server.cli", str(task_dir), "--record-under", str(parent)]
    from mcp import StdioServerParameters

    params = StdioServerParameters(command=cmd[0], args=cmd[1:], env=dict(os.environ))
    for _ in range(2):
        async with Client(params) as c:
            await c.call_tool("start_episode", {})
    for n in (1, 2):
        run_dir = parent / f"attempt-{n}" / "box3_none"
        assert read_trajectory(run_dir / "trajectory.jsonl").calls[0].tool == "start_episode"
        assert read_final(run_dir / "final.json").reason == "disconnect"
    assert sorted(p.name for p in parent.iterdir()) == ["attempt-1", "attempt-2"]


async def test_a_refused_start_reaches_the_mcp_client_as_its_message(box_task, tmp_path):
    task_dir, _, _ = box_task
    from mcp import StdioServerParameters
    from mcp.shared.exceptions import MCPError

    run = tmp_path / "busy"
    run.mkdir()
    (run / "trajectory.jsonl").write_text("{}\n")
    params = StdioServerParameters(
        command=sys.executable, args=["-m", "aw_server.cli", str(task_dir), "--record", str(run)], env=dict(os.environ)
    )
    with pytest.raises(BaseException) as caught:
        async with Client(params):
            pass
    errors = [caught.value]
    while isinstance(errors[0], BaseExceptionGroup):
        errors = list(errors[0].exceptions)
    assert isinstance(errors[0], MCPError), caught.value
    assert "already holds a recording" in str(errors[0]) and "--overwrite" in str(errors[0])
    assert (run / "trajectory.jsonl").read_text() == "{}\n"
