"""Run one episode process under a wall-clock limit and leave nothing of it behind.

MCP clients (the SDK's, Claude Code's, Codex's) start their servers in sessions of their own, so
killing the episode's process group is not enough. Every process of an episode carries a marker
in its environment (``AW_EPISODE``); at the end the supervisor kills the episode's process tree
and any of its own user's processes that carry the marker, by pid.
"""

from __future__ import annotations

import os
import queue
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


def _register(pid: int, *markers: str) -> None:
    with _live_lock:
        _live[pid] = markers


def _unregister(pid: int) -> None:
    with _live_lock:
        _live.pop(pid, None)


def kill_everything() -> list[int]:
    """Kill every registered episode process with its tree and marked processes (Ctrl-C)."""
    with _live_lock:
        live = dict(_live)
    procs: list[psutil.Process] = []
    for pid, markers in live.items():
        procs += _tree(pid)
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


def _tree(pid: int) -> list[psutil.Process]:
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
    seconds to finish writing their records before they are terminated.
    """
    env = dict(env)
    env[MARKER_VAR] = marker
    out = open(stdout_path, "wb") if stdout_path else subprocess.DEVNULL
    err = open(stderr_path, "wb") if stderr_path else subprocess.DEVNULL
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
            if not isinstance(f, int):  # a file, not DEVNULL
                f.close()
    if stdin_data is not None and proc.stdin is not None:
        try:
            proc.stdin.write(stdin_data)
            proc.stdin.close()
        except (BrokenPipeError, OSError):
            pass
    timed_out = False
    killed: list[int] = []
    _register(proc.pid, marker)
    try:
        proc.wait(timeout=limit_seconds)
    except subprocess.TimeoutExpired:
        timed_out = True
        # Collect the whole tree before killing anything: orphans would leave it.
        procs = _tree(proc.pid) + marked_processes(marker)
        killed = kill_all(procs, grace=0.0)
        proc.wait()
    finally:
        _unregister(proc.pid)
    wall = time.monotonic() - t0
    killed += _reap_marked(marker, 0.0 if timed_out else leftover_grace)
    return Supervised(
        returncode=None if timed_out else proc.returncode, timed_out=timed_out, wall_seconds=wall, killed=killed
    )


class WorkerProcess:
    """A long-lived ``python -m aw.runner.episode --worker``: one episode at a time, each under a
    wall-clock limit. A worker that overruns is killed with everything it started (its servers
    carry the episode's marker) and replaced by a fresh one on the next episode."""

    def __init__(self, cmd: list[str], env: dict[str, str], log_path: Path):
        self.cmd = cmd
        self.env = env
        self.log_path = log_path
        self.marker = new_marker()
        self.proc: subprocess.Popen[bytes] | None = None
        self._lines: queue.Queue[str | None] = queue.Queue()

    def _start(self) -> subprocess.Popen[bytes]:
        env = dict(self.env)
        env[MARKER_VAR] = self.marker
        self._lines = queue.Queue()
        with open(self.log_path, "ab") as log:
            proc = subprocess.Popen(
                self.cmd, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log, start_new_session=True
            )
        self.proc = proc
        lines = self._lines
        out = proc.stdout

        def pump() -> None:
            for raw in out or ():
                lines.put(raw.decode(errors="replace"))
            lines.put(None)

        threading.Thread(target=pump, daemon=True).start()
        return proc

    @property
    def pid(self) -> int | None:
        return self.proc.pid if self.proc else None

    def run(self, spec_line: str, limit_seconds: float, episode_marker: str) -> Supervised:
        """Send one spec; wait for its ``done`` line. ``returncode`` is 0 when done, the worker's
        exit code when it died mid-episode, None when it was killed at the limit."""
        proc = self.proc
        if proc is None or proc.poll() is not None:
            proc = self._start()
        _register(proc.pid, self.marker, episode_marker)
        try:
            return self._run(proc, spec_line, limit_seconds, episode_marker)
        finally:
            if self.proc is not None:
                _register(self.proc.pid, self.marker)

    def _run(
        self, proc: subprocess.Popen[bytes], spec_line: str, limit_seconds: float, episode_marker: str
    ) -> Supervised:
        t0 = time.monotonic()
        try:
            if proc.stdin is not None:
                proc.stdin.write(spec_line.encode() + b"\n")
                proc.stdin.flush()
        except (BrokenPipeError, OSError):
            pass
        deadline = t0 + limit_seconds
        while True:
            try:
                line = self._lines.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                killed = self.kill(episode_marker)
                return Supervised(None, True, time.monotonic() - t0, killed)
            if line is None:  # the worker died
                code = proc.wait()
                _unregister(proc.pid)
                wall = time.monotonic() - t0
                killed = _reap_marked(episode_marker, grace=5.0)
                self.proc = None
                return Supervised(code if code != 0 else 1, False, wall, killed)
            if '"done"' in line:
                return Supervised(0, False, time.monotonic() - t0, _reap_marked(episode_marker, grace=5.0))

    def kill(self, episode_marker: str | None = None) -> list[int]:
        if self.proc is None:
            return []
        procs = _tree(self.proc.pid) + marked_processes(self.marker)
        if episode_marker:
            procs += marked_processes(episode_marker)
        killed = kill_all(procs)
        self.proc.wait()
        _unregister(self.proc.pid)
        self.proc = None
        return killed

    def close(self, timeout: float = 10.0) -> None:
        """Ask the worker to exit (stdin closed); kill it if it does not."""
        if self.proc is None:
            return
        try:
            if self.proc.stdin is not None:
                self.proc.stdin.close()
            self.proc.wait(timeout=timeout)
            _unregister(self.proc.pid)
        except (subprocess.TimeoutExpired, OSError):
            self.kill()
        self.proc = None
        try:
            if self.log_path.stat().st_size == 0:
                self.log_path.unlink()
        except OSError:
            pass


def _reap_marked(marker: str, grace: float) -> list[int]:
    """Wait up to ``grace`` for marked processes to exit on their own, then kill the rest."""
    deadline = time.monotonic() + grace
    left = marked_processes(marker)
    while left and time.monotonic() < deadline:
        time.sleep(0.1)
        left = marked_processes(marker)
    return kill_all(left, grace=1.0) if left else []
