"""A killed agent, a hung server and an overrun are recorded as such, and the batch goes on."""

from __future__ import annotations

import os
import signal
import threading
import time

import psutil

from aw.formats import read_final, read_run_info, read_trajectory
from aw.runner.batch import BatchConfig, run_batch


def _server_of(task_id: str) -> psutil.Process | None:
    """The running aw-serve child (any depth) of this test process serving ``task_id``."""
    for p in psutil.Process().children(recursive=True):
        try:
            cmd = " ".join(p.cmdline())
        except psutil.Error:
            continue
        if "aw-serve" in cmd and f"/{task_id} " in cmd + " " and "--record" in cmd:
            return p
    return None


def _wait_for_calls(run_dir, n: int, timeout: float = 60.0) -> None:
    path = run_dir / "trajectory.jsonl"
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if path.is_file() and path.read_text().count("\n") >= n + 1:
            return
        time.sleep(0.05)
    raise AssertionError(f"{path} never reached {n} calls")


def _leftovers(out) -> list[str]:
    left = []
    for p in psutil.process_iter(["cmdline"]):
        cmd = " ".join(p.info["cmdline"] or [])
        if str(out) in cmd:
            left.append(cmd)
    return left


def test_killed_agent_and_hung_server_are_recorded_and_the_batch_goes_on(tiny_suite, tmp_path):
    out = tmp_path / "runs"
    cfg = BatchConfig(
        suite_dir=tiny_suite,
        system="random",
        out_dir=out,
        agent="random",
        jobs=3,
        think_seconds=0.5,
        call_timeout=4.0,
        timeout_minutes=2.0,
        progress=False,
    )
    base = out / "random"
    actions: dict[str, str] = {}

    def saboteur() -> None:
        # Kill the agent process of one task, freeze the server of another, mid-episode.
        _wait_for_calls(base / "tiny_table_none", 8)
        server = _server_of("tiny_table_none")
        agent = server.parent()
        assert "aw.runner.episode" in " ".join(agent.cmdline())
        os.kill(agent.pid, signal.SIGKILL)
        actions["killed"] = "tiny_table_none"
        _wait_for_calls(base / "tiny_shelf_none", 8)
        os.kill(_server_of("tiny_shelf_none").pid, signal.SIGSTOP)
        actions["stopped"] = "tiny_shelf_none"

    t = threading.Thread(target=saboteur, daemon=True)
    t.start()
    res = run_batch(cfg)
    t.join(5)
    assert actions == {"killed": "tiny_table_none", "stopped": "tiny_shelf_none"}
    ended = {r.task_id: r for r in res.runs}
    assert ended["tiny_table_none"].ended == "crashed", ended["tiny_table_none"].error
    assert "died" in ended["tiny_table_none"].error
    assert ended["tiny_shelf_none"].ended == "hung", ended["tiny_shelf_none"].error
    assert "did not answer" in ended["tiny_shelf_none"].error
    assert ended["tiny_table_image"].ended == "finished"

    # The orphaned server of the killed agent saw its client go and closed the record itself.
    crashed = base / "tiny_table_none"
    assert read_trajectory(crashed / "trajectory.jsonl").end.reason == "disconnect"
    assert read_run_info(crashed / "run.json").extra["final_source"] == "server"
    # The frozen server was killed before it could write final.json: the runner wrote it from
    # the last state the trajectory recorded, and says so.
    hung = base / "tiny_shelf_none"
    info = read_run_info(hung / "run.json")
    assert info.extra["final_source"].startswith("runner")
    traj = read_trajectory(hung / "trajectory.jsonl")
    assert traj.end is None
    final = read_final(hung / "final.json")
    assert final.reason == "interrupted" and final.poses == traj.final_poses()
    assert _leftovers(out) == []


def test_an_episode_over_its_wall_clock_limit_is_killed_as_timeout(tiny_suite, tmp_path):
    out = tmp_path / "runs"
    cfg = BatchConfig(
        suite_dir=tiny_suite,
        system="slow",
        out_dir=out,
        agent="random",
        jobs=1,
        tasks=["tiny_shelf_none"],
        think_seconds=5.0,
        timeout_minutes=0.3,
        progress=False,
    )
    res = run_batch(cfg)
    (info,) = res.runs
    assert info.ended == "timeout", info.error
    assert info.wall_seconds >= 18.0  # killed at the limit, not before
    run_dir = out / "slow" / "tiny_shelf_none"
    assert read_run_info(run_dir / "run.json").ended == "timeout"
    assert (run_dir / "final.json").is_file()
    assert _leftovers(out) == []


def test_a_server_that_cannot_start_is_an_error_with_its_message(tiny_suite, tmp_path):
    import shutil

    suite = tmp_path / "suite"
    shutil.copytree(tiny_suite, suite)
    (suite / "tasks" / "tiny_shelf_none" / "task.json").write_text("{")
    cfg = BatchConfig(
        suite_dir=suite,
        system="idle",
        out_dir=tmp_path / "runs",
        agent="idle",
        jobs=1,
        tasks=["tiny_shelf_none", "tiny_table_none"],
        progress=False,
    )
    res = run_batch(cfg)
    ended = {r.task_id: r for r in res.runs}
    bad = ended["tiny_shelf_none"]
    assert bad.ended == "error" and "not valid JSON" in bad.error
    assert read_run_info(tmp_path / "runs" / "idle" / "tiny_shelf_none" / "run.json").extra["final_source"] is None
    # The same worker went on with the next task.
    assert ended["tiny_table_none"].ended == "finished"


def test_ctrl_c_stops_every_episode_and_leaves_only_finished_runs(tiny_suite, tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    out = tmp_path / "runs"
    proc = subprocess.Popen(
        [
            str(Path(sys.executable).with_name("aw-run")),
            str(tiny_suite),
            "--agent",
            "random",
            "--think-seconds",
            "1",
            "--out",
            str(out),
            "--jobs",
            "2",
            "--no-progress",
        ],
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # a shell's background jobs ignore it
    )
    _wait_for_calls(out / "random" / "tiny_table_none", 4)
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=60) == 130
    assert "interrupted" in proc.stderr.read()
    assert _leftovers(out) == []
    # Episodes cut short leave nothing behind, so a rerun does them again.
    assert not (out / "random" / "tiny_table_none").exists()
