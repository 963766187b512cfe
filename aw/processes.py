"""Run a child process under a wall-clock limit and leave nothing of it behind.

A child can start processes in sessions of their own (MCP clients start their servers so; a
refiner may call ``setsid()``), and an orphan leaves its parent's tree, so killing the child's
process group, or its tree, is not enough. Every process started here carries a marker in its
environment (``AW_EPISODE``); at the end the supervisor kills the child's process tree and any of
its own user's processes that carry the marker, by pid. Used by ``aw-run`` for episodes
(:mod:`aw.runner.supervise`) and refiners (:mod:`aw.refine.plugins`).
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import psutil

MARKER_VAR = "AW_EPISODE"


def new_marker() -> str:
    return uuid.uuid4().hex


# Every live episode process and its markers, so that an interrupted batch can stop them all.
_live_lock = threading.Lock()
_live: dict[int, tuple[str, ...]] = {}


def register_live(pid: int, *markers: str) -> None:
    with _live_lock:
        _live[pid] = markers


def unregister_live(pid: int) -> None:
    with _live_lock:
        _live.pop(pid, None)


def kill_everything() -> list[int]:
    """Kill every registered episode process with its tree and marked processes (Ctrl-C)."""
    with _live_lock:
        live = dict(_live)
    procs: list[psutil.Process] = []
    for pid, markers in live.items():
        procs += process_tree(pid)
        for m in markers:
            procs += marked_processes(m)
    return kill_all(procs)


@dataclass
class Supervised:
    """How the process ended. ``returncode`` is None when it was killed at the limit."""

    returncode: int | None
    timed_out: bool
    wall_seconds: float
    killed: list[int] = field(default_factory=list)


def marked_processes(marker: str) -> list[psutil.Process]:
    """This user's live processes whose environment carries ``AW_EPISODE=marker``."""
    me = os.getuid()
    out = []
    for proc in psutil.process_iter(["uids"]):
        try:
            if proc.info["uids"] is None or proc.info["uids"].real != me or proc.pid == os.getpid():
                continue
            if proc.environ().get(MARKER_VAR) == marker:
                out.append(proc)
        except (psutil.Error, OSError):
            continue
    return out


def process_tree(pid: int) -> list[psutil.Process]:
    try:
        root = psutil.Process(pid)
        return [root, *root.children(recursive=True)]
    except psutil.Error:
        return []


def kill_all(procs: list[psutil.Process], grace: float = 0.0) -> list[int]:
    """SIGTERM (if ``grace``) then SIGKILL each process; returns the pids that were signalled."""
    alive = []
    for p in procs:
        try:
            if p.is_running() and p.status() != psutil.STATUS_ZOMBIE:
                alive.append(p)
        except psutil.Error:
            continue
    if not alive:
        return []
    if grace > 0:
        for p in alive:
            try:
                p.send_signal(signal.SIGTERM)
                p.send_signal(signal.SIGCONT)  # a stopped process must run to act on SIGTERM
            except psutil.Error:
                pass
        _, alive_after = psutil.wait_procs(alive, timeout=grace)
    else:
        alive_after = alive
    for p in alive_after:
        try:
            p.kill()
        except psutil.Error:
            pass
    psutil.wait_procs(alive_after, timeout=5)
    return [p.pid for p in alive]


def run_supervised(
    cmd: list[str],
    *,
    env: dict[str, str],
    marker: str,
    limit_seconds: float,
    cwd: Path | None = None,
    stdin_data: bytes | None = None,
    stdout_path: Path | None = None,
    stderr_path: Path | None = None,
    leftover_grace: float = 5.0,
) -> Supervised:
    """Run ``cmd`` in a new session with ``env`` + the marker; kill everything at the limit.

    After a normal exit, marked leftovers (servers a harness did not stop) get ``leftover_grace``
    seconds to finish writing their records before they are terminated. ``stderr_path`` equal to
    ``stdout_path``: both streams go to that one file.
    """
    env = dict(env)
    env[MARKER_VAR] = marker
    out = open(stdout_path, "wb") if stdout_path else subprocess.DEVNULL
    err = (
        subprocess.STDOUT
        if stderr_path is not None and stderr_path == stdout_path
        else open(stderr_path, "wb")
        if stderr_path
        else subprocess.DEVNULL
    )
    t0 = time.monotonic()
    try:
        proc = subprocess.Popen(
            cmd,
            env=env,
            cwd=cwd,
            stdin=subprocess.PIPE if stdin_data is not None else subprocess.DEVNULL,
            stdout=out,
            stderr=err,
            start_new_session=True,
        )
    finally:
        for f in (out, err):
            if not isinstance(f, int):  # DEVNULL, STDOUT
                f.close()
    if stdin_data is not None and proc.stdin is not None:
        try:
            proc.stdin.write(stdin_data)
            proc.stdin.close()
        except (BrokenPipeError, OSError):
            pass
    timed_out = False
    killed: list[int] = []
    register_live(proc.pid, marker)
    try:
        proc.wait(timeout=limit_seconds)
    except subprocess.TimeoutExpired:
        timed_out = True
        # Collect the whole tree before killing anything: orphans would leave it.
        procs = process_tree(proc.pid) + marked_processes(marker)
        killed = kill_all(procs, grace=0.0)
        proc.wait()
    finally:
        unregister_live(proc.pid)
    wall = time.monotonic() - t0
    killed += reap_marked(marker, 0.0 if timed_out else leftover_grace)
    return Supervised(
        returncode=None if timed_out else proc.returncode, timed_out=timed_out, wall_seconds=wall, killed=killed
    )


def reap_marked(marker: str, grace: float) -> list[int]:
    """Wait up to ``grace`` for marked processes to exit on their own, then kill the rest."""
    deadline = time.monotonic() + grace
    left = marked_processes(marker)
    while left and time.monotonic() < deadline:
        time.sleep(0.1)
        left = marked_processes(marker)
    return kill_all(left, grace=1.0) if left else []
