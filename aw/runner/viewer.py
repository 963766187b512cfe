"""``aw-run --view``: the live viewer (``aw-view``) on the batch's runs folder, in a process of
its own, so that a browser can neither slow nor stop an episode; it stops with the batch.

The viewer is started by command, like ``aw-serve`` (``aw`` does not import the viewer's
package, which sits above the evaluator)."""

from __future__ import annotations

import os
import selectors
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["ViewerProcess", "aw_view_command", "ViewerFailed"]

START_SECONDS = 60.0  # the viewer prints its URL once it listens (its imports take a few seconds)


class ViewerFailed(Exception):
    """The viewer did not start (its own one-line reason)."""


def aw_view_command() -> list[str]:
    """The command that starts ``aw-view``: beside this interpreter, else on PATH, else the module."""
    beside = Path(sys.executable).with_name("aw-view")
    if beside.is_file() and os.access(beside, os.X_OK):
        return [str(beside)]
    found = shutil.which("aw-view")
    return [found] if found else [sys.executable, "-m", "aw_view.cli"]


class ViewerProcess:
    """``aw-view RUNS --port PORT --tasks TASKS_DIR`` running; ``url`` once it listens."""

    def __init__(self, runs: Path, port: int, tasks_dir: Path | None = None):
        runs.mkdir(parents=True, exist_ok=True)
        cmd = aw_view_command() + [str(runs), "--port", str(port)]
        if tasks_dir is not None and tasks_dir.is_dir():
            cmd += ["--tasks", str(tasks_dir)]
        self._log = tempfile.TemporaryFile()
        self.proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=self._log, stdin=subprocess.DEVNULL, start_new_session=True
        )
        self.url = self._wait_for_url()

    def _wait_for_url(self) -> str:
        assert self.proc.stdout is not None
        sel = selectors.DefaultSelector()
        sel.register(self.proc.stdout, selectors.EVENT_READ)
        deadline = time.monotonic() + START_SECONDS
        line = b""
        while not line.endswith(b"\n") and time.monotonic() < deadline:
            if sel.select(timeout=0.5):
                chunk = os.read(self.proc.stdout.fileno(), 4096)
                if not chunk:
                    break
                line += chunk
        sel.close()
        text = line.decode("utf-8", "replace").strip().splitlines()
        if text and " at http" in text[0]:
            return text[0].rsplit(" at ", 1)[1]
        self.stop()
        self._log.seek(0)
        why = self._log.read().decode("utf-8", "replace").strip().splitlines()
        reason = why[-1] if why else f"no URL within {START_SECONDS:g} s"
        raise ViewerFailed(reason.removeprefix("aw-view: error: "))

    def stop(self) -> None:
        """Stop the viewer (idempotent)."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        self._log.close()
