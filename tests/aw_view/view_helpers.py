"""Helpers for the aw-view tests: a viewer served in-process, an agent that drives a real
aw-serve over MCP one call at a time, JSON requests. (A uniquely named module, so that tests
and benchmarks can import it.)"""

from __future__ import annotations

import json
import os
import queue
import sys
import threading
import urllib.error
import urllib.request
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from aw_view.public import PublicFiles, TaskFiles
from aw_view.server import ViewerServer, serve_in_thread
from aw_view.watch import Watch

ONE_TASK = (("partnet", ("image",)),)  # box_suite blocks: one task, with a reference image


@contextmanager
def viewer(root: Path, tasks: list[Path] | None = None, scorer=None, token: str | None = None, stuck: float = 120.0):
    """``aw-view ROOT`` served in this process on a free port; yields its base URL."""
    public = PublicFiles([root])
    watch = Watch(root, public, TaskFiles(public, tasks or []), stuck, scorer)
    server = ViewerServer(("127.0.0.1", 0), watch, token)
    serve_in_thread(server)
    try:
        yield f"http://127.0.0.1:{server.port}/"
    finally:
        server.shutdown()
        server.server_close()


def fetch(url: str, headers: dict[str, str] | None = None) -> tuple[int, bytes, dict[str, str]]:
    """``(status, body, headers)`` of a GET, errors included."""
    req = urllib.request.Request(url, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            return r.status, r.read(), dict(r.headers)
    except urllib.error.HTTPError as e:
        return e.code, e.read(), dict(e.headers)


def get_json(url: str) -> Any:
    status, body, _ = fetch(url)
    assert status == 200, (url, status, body[:300])
    return json.loads(body)


class ScriptedAgent:
    """A real ``aw-serve TASK_DIR --record RUN_DIR`` driven by the MCP SDK client in a thread of
    its own; :meth:`call` makes one tool call and returns when its reply (so its recorded line)
    is back; :meth:`close` disconnects (the episode ends with reason ``disconnect``)."""

    def __init__(self, task_dir: Path, run_dir: Path, system: str = "scripted"):
        self._todo: queue.Queue = queue.Queue()
        self._done: queue.Queue = queue.Queue()
        cmd = [sys.executable, "-m", "aw_server.cli", str(task_dir), "--record", str(run_dir), "--system", system]
        self._cmd = cmd
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        self._wait()  # connected: the header line is on disk

    def _run(self) -> None:
        import anyio
        from mcp import Client, StdioServerParameters

        async def main() -> None:
            params = StdioServerParameters(command=self._cmd[0], args=self._cmd[1:], env=dict(os.environ))
            async with Client(params) as client:
                self._done.put(("ready", None))
                while True:
                    item = await anyio.to_thread.run_sync(self._todo.get)
                    if item is None:
                        break
                    try:
                        self._done.put(("ok", await client.call_tool(*item)))
                    except Exception as exc:  # noqa: BLE001 - handed to the test thread
                        self._done.put(("error", exc))
            self._done.put(("closed", None))

        try:
            anyio.run(main)
        except Exception as exc:  # noqa: BLE001
            self._done.put(("error", exc))

    def _wait(self) -> Any:
        kind, value = self._done.get(timeout=180)
        if kind == "error":
            raise value
        return value

    def call(self, tool: str, args: dict | None = None) -> Any:
        self._todo.put((tool, args or {}))
        return self._wait()

    def close(self) -> None:
        self._todo.put(None)
        self._wait()
        self._thread.join(timeout=60)
