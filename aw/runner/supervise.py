"""Run one episode process under a wall-clock limit and leave nothing of it behind: the
supervision itself is :mod:`aw.processes` (markers, process trees, :func:`run_supervised`);
here the long-lived worker that runs baseline-agent episodes one at a time.
"""

from __future__ import annotations

import queue
import subprocess
import threading
import time
from pathlib import Path

from aw.processes import (
    MARKER_VAR,
    Supervised,
    kill_all,
    kill_everything,
    marked_processes,
    new_marker,
    process_tree,
    reap_marked,
    register_live,
    run_supervised,
    unregister_live,
)

__all__ = [
    "MARKER_VAR",
    "Supervised",
    "WorkerProcess",
    "kill_all",
    "kill_everything",
    "marked_processes",
    "new_marker",
    "run_supervised",
]


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
        register_live(proc.pid, self.marker, episode_marker)
        try:
            return self._run(proc, spec_line, limit_seconds, episode_marker)
        finally:
            if self.proc is not None:
                register_live(self.proc.pid, self.marker)

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
                unregister_live(proc.pid)
                wall = time.monotonic() - t0
                killed = reap_marked(episode_marker, grace=5.0)
                self.proc = None
                return Supervised(code if code != 0 else 1, False, wall, killed)
            if '"done"' in line:
                return Supervised(0, False, time.monotonic() - t0, reap_marked(episode_marker, grace=5.0))

    def kill(self, episode_marker: str | None = None) -> list[int]:
        if self.proc is None:
            return []
        procs = process_tree(self.proc.pid) + marked_processes(self.marker)
        if episode_marker:
            procs += marked_processes(episode_marker)
        killed = kill_all(procs)
        self.proc.wait()
        unregister_live(self.proc.pid)
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
            unregister_live(self.proc.pid)
        except (subprocess.TimeoutExpired, OSError):
            self.kill()
        self.proc = None
        try:
            if self.log_path.stat().st_size == 0:
                self.log_path.unlink()
        except OSError:
            pass
