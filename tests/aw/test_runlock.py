"""aw.runlock: one live recorder per run directory, a refusal that names the holder, and no
stale lock after the holder dies (kill -9 included)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pytest
import trimesh

from aw.episode import Episode, RunDirError
from aw.formats import Task, TaskPart, read_trajectory
from aw.prompt import task_prompt
from aw.runlock import LOCK_FILE, RunDirBusy, RunDirLock, holder_of

HOLD = textwrap.dedent("""
    import sys, time
    from aw.runlock import RunDirLock
    RunDirLock(sys.argv[1], command="holder-under-test").acquire()
    print("locked", flush=True)
    time.sleep(120)
""")


@pytest.fixture
def holder(tmp_path):
    """A separate process holding ``tmp_path / 'run'``'s lock: (run_dir, Popen)."""
    run = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(run)],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
    )
    assert proc.stdout.readline().strip() == "locked"
    yield run, proc
    proc.kill()
    proc.wait()
    proc.stdout.close()


def _task():
    task = Task(
        task_id="lk",
        source="custom",
        dataset="test",
        object_id="lk",
        prompt=task_prompt("none"),
        parts=[TaskPart(id="p01", mesh="parts/p01.obj")],
    )
    return task, [trimesh.creation.box([0.3, 0.2, 0.1])]


def test_a_held_run_dir_is_refused_naming_the_holder(holder):
    run, proc = holder
    (run / "trajectory.jsonl").write_text("live\n")
    task, meshes = _task()
    with pytest.raises(RunDirError, match=rf"being recorded by pid {proc.pid} on .*holder-under-test"):
        Episode(task, meshes, run, overwrite=True)
    assert (run / "trajectory.jsonl").read_text() == "live\n"  # nothing removed
    assert f"pid {proc.pid}" in holder_of(run)
    with pytest.raises(RunDirBusy):
        RunDirLock(run).acquire()


def test_a_killed_holder_leaves_no_stale_lock(holder):
    run, proc = holder
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert (run / LOCK_FILE).exists() and holder_of(run) is None
    task, meshes = _task()
    ep = Episode(task, meshes, run, overwrite=True)
    assert holder_of(run) is not None  # held by this process while the episode is open
    ep.call("list_objects")
    ep.close()
    assert holder_of(run) is None
    assert len(read_trajectory(run / "trajectory.jsonl").calls) == 1


def test_lock_is_exclusive_within_a_process_too(tmp_path):
    with RunDirLock(tmp_path / "r", command="first"):
        with pytest.raises(RunDirBusy, match="first"):
            RunDirLock(tmp_path / "r").acquire()
    with RunDirLock(tmp_path / "r"):
        pass


def test_the_lock_file_names_its_holder_during_and_after(tmp_path):
    """docs/harnesses.md: ``.aw-lock`` names pid, host and command (it used to be emptied on release)."""
    import json
    import socket

    lock = RunDirLock(tmp_path / "run", command="aw-score suite runs --out x").acquire()
    during = json.loads((tmp_path / "run" / LOCK_FILE).read_text())
    lock.release()
    after = json.loads((tmp_path / "run" / LOCK_FILE).read_text())
    assert (
        during == after == {"pid": os.getpid(), "host": socket.gethostname(), "command": "aw-score suite runs --out x"}
    )
    assert holder_of(tmp_path / "run") is None  # the record of an ended holder holds nothing


def test_live_holder_tells_a_live_lock_from_a_stale_one_without_taking_it(holder):
    """Unlike holder_of, live_holder never takes the lock (a watcher must never make a starting
    recorder refuse its directory): while it looks, the holder still holds the lock exclusively,
    and a new recorder can take it the moment the holder dies."""
    from aw.runlock import kernel_flocks, live_holder

    run, proc = holder
    assert f"pid {proc.pid}" in live_holder(run)
    assert f"pid {proc.pid}" in live_holder(run, flocks=None)  # no kernel list: the recorded pid is alive
    listed = kernel_flocks()
    assert listed is not None and f"pid {proc.pid}" in live_holder(run, listed)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert live_holder(run) is None and live_holder(run, flocks=None) is None
    with RunDirLock(run):
        assert f"pid {os.getpid()}" in live_holder(run)
    assert live_holder(tmp_path_missing := run / "nowhere") is None and not tmp_path_missing.exists()
