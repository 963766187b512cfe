"""``aw-serve``: serve one task's environment over MCP and record the episode.

    aw-serve TASK_DIR --record RUN_DIR [--system LABEL] [--budget-minutes 60]
             [--transport stdio|http] [--host 127.0.0.1] [--port 8765] [--overwrite]
             [--surface default|official]
    aw-serve TASK_DIR --print-prompt        # the task text, then exit
    aw-serve TASK_DIR --print-references    # absolute paths of the reference images, in order

The server is given the public task directory only. ``final.json`` and the closing trajectory
line are written however the session ends: stdin closed by the client (``disconnect``),
SIGINT/SIGTERM/SIGHUP (``interrupted``), a server crash (``error``); ``timeout`` wins if the
execution budget ran out first.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import signal
import sys
from pathlib import Path

EXIT_USAGE = 2


def _positive_minutes(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    from aw.formats.task import MAX_BUDGET_MINUTES

    if not (math.isfinite(v) and 0 < v <= MAX_BUDGET_MINUTES):
        raise argparse.ArgumentTypeError(f"must be a positive number of minutes, at most {MAX_BUDGET_MINUTES:g}, "
                                         f"got {text!r}")
    return v


def _port(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if not 0 < v < 65536:
        raise argparse.ArgumentTypeError(f"port must be in 1..65535, got {v}")
    return v


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="aw-serve",
        description="Serve an AssemblyWorld task over MCP (stdio by default) and record the episode.",
    )
    p.add_argument("task_dir", type=Path, help="public task directory (task.json, parts/, references/)")
    p.add_argument("--record", type=Path, metavar="RUN_DIR",
                   help="run directory for trajectory.jsonl, final.json and captures/ (required to serve)")
    p.add_argument("--system", default="", help="system label stored in the trajectory header")
    p.add_argument("--budget-minutes", type=_positive_minutes, default=None,
                   help="execution budget from start_episode, in minutes (default: the task's, normally 60)")
    p.add_argument("--transport", choices=("stdio", "http"), default="stdio",
                   help="stdio (default; the harness launches the server) or streamable HTTP at /mcp")
    p.add_argument("--host", default="127.0.0.1", help="HTTP bind address (default 127.0.0.1, loopback only)")
    p.add_argument("--port", type=_port, default=8765, help="HTTP port (default 8765)")
    p.add_argument("--overwrite", action="store_true", help="replace an earlier recording in RUN_DIR")
    p.add_argument("--surface", choices=("default", "official"), default="default",
                   help="tools the agent sees: the project's scene tools (default), or the official benchmark's "
                        "list_pages / list_webmcp_tools / execute_webmcp_tool / read_manual_page")
    p.add_argument("--print-prompt", action="store_true", help="print the task text and exit")
    p.add_argument("--print-references", action="store_true",
                   help="print the reference image paths (absolute, in order, one per line) and exit")
    p.add_argument("--log-level", default="WARNING", choices=("DEBUG", "INFO", "WARNING", "ERROR"),
                   help="server log level on stderr (default WARNING)")
    return p


def _fail(msg: str) -> int:
    print(f"aw-serve: error: {msg}", file=sys.stderr)
    return EXIT_USAGE


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from aw.formats import FormatError, read_task

    try:
        task = read_task(args.task_dir)
    except FormatError as exc:
        return _fail(str(exc))
    if args.print_prompt or args.print_references:
        if args.print_prompt:
            print(task.prompt)
        if args.print_references:
            for path in task.reference_paths():
                print(path.resolve())
        return 0
    if args.record is None:
        return _fail("--record RUN_DIR is required to serve (or use --print-prompt / --print-references)")

    logging.basicConfig(level=args.log_level, stream=sys.stderr, format="aw-serve %(levelname)s %(name)s: %(message)s")
    from aw.episode import Episode, RunDirError
    from aw.meshes import load_task_meshes

    try:
        meshes = load_task_meshes(task)
        episode = Episode(task, meshes, args.record, system=args.system, budget_minutes=args.budget_minutes,
                          overwrite=args.overwrite)
    except (FormatError, RunDirError, ValueError) as exc:
        return _fail(str(exc))

    def on_signal(signum, _frame):
        # Runs in the main thread between bytecodes; tool calls run in worker threads, so the
        # episode lock is free or soon released. Exit at once: the event loop may be mid-read.
        try:
            episode.close("interrupted", f"signal {signal.Signals(signum).name}")
        finally:
            os._exit(128 + signum)

    for name in ("SIGTERM", "SIGINT", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), on_signal)

    if args.surface == "official":
        from aw_server.official_surface import build_official_server as build_server
    else:
        from aw_server.app import build_server

    reason, message = "disconnect", ""
    try:
        server = build_server(episode, log_level=args.log_level)
        if args.transport == "stdio":
            from aw_server.stdio import serve_stdio

            serve_stdio(server)  # answers malformed lines with JSON-RPC errors
        else:
            print(f"aw-serve: MCP endpoint http://{args.host}:{args.port}/mcp", file=sys.stderr, flush=True)
            server.run("streamable-http", host=args.host, port=args.port)
            reason = "interrupted"
    except KeyboardInterrupt:
        reason = "interrupted"
    except BaseException as exc:
        if _is_disconnect(exc):
            reason = "disconnect"  # the client went away while a reply was being written
        else:
            reason, message = "error", f"{type(exc).__name__}: {exc}"
            raise
    finally:
        episode.close(reason, message)
    return 0


def _is_disconnect(exc: BaseException) -> bool:
    """Whether ``exc`` (or every exception in a group) is a closed pipe or stream."""
    import anyio

    if isinstance(exc, BaseExceptionGroup):
        return all(_is_disconnect(e) for e in exc.exceptions)
    return isinstance(exc, (BrokenPipeError, ConnectionResetError, anyio.BrokenResourceError, anyio.ClosedResourceError))


if __name__ == "__main__":
    sys.exit(main())
