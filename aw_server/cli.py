"""aw-serve: serve one task's environment over MCP and record the episode.

    aw-serve TASK_DIR --record RUN_DIR [--system LABEL] [--budget-minutes 60]
             [--transport stdio|http] [--host 127.0.0.1] [--port 8765] [--overwrite]
             [--surface default|official] [--initial-poses FILE]
    aw-serve TASK_DIR --record-under DIR [...]   one config, many sessions: DIR/attempt-N/<task_id>/
    aw-serve TASK_DIR --print-prompt             the task text, then exit
    aw-serve TASK_DIR --print-references         absolute paths of the reference images, in order

The server is given the public task directory only. final.json and the closing trajectory
line are written however the session ends: stdin closed by the client (disconnect),
SIGINT/SIGTERM/SIGHUP (interrupted), a server crash (error); timeout wins if the
execution budget ran out first.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import select
import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from aw.cli.common import EXIT_USAGE, add_overwrite, new_parser

if TYPE_CHECKING:  # the server's imports wait until the arguments are checked
    from aw.formats import EndReason

REFUSAL_WAIT_S = 3.0  # how long a refused stdio start waits for the client's initialize request


def _positive_minutes(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    from aw.formats.task import MAX_BUDGET_MINUTES

    if not (math.isfinite(v) and 0 < v <= MAX_BUDGET_MINUTES):
        raise argparse.ArgumentTypeError(
            f"must be a positive number of minutes, at most {MAX_BUDGET_MINUTES:g}, got {text!r}"
        )
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
    p = new_parser(
        "aw-serve",
        "Serve an AssemblyWorld task over MCP (stdio by default) and record the episode.",
        epilog="One MCP config for many sessions: --record-under DIR records session k of a task in "
        "DIR/attempt-k/<task_id>/ (the first attempt number free for that task), a layout aw-score "
        "reads with one system per attempt. See docs/harnesses.md.",
    )
    p.add_argument(
        "task_dir", type=Path, metavar="TASK_DIR", help="public task directory (task.json, parts/, references/)"
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--record", type=Path, metavar="RUN_DIR", help="run directory for trajectory.jsonl, final.json and captures/"
    )
    where.add_argument(
        "--record-under",
        type=Path,
        metavar="DIR",
        help="record in a new DIR/attempt-N/<task_id>/ (N: the first free for this task), so that "
        "one MCP config serves many sessions",
    )
    p.add_argument("--system", default="", metavar="LABEL", help="system label stored in the trajectory header")
    p.add_argument(
        "--budget-minutes",
        type=_positive_minutes,
        default=None,
        metavar="M",
        help="execution budget from start_episode, in minutes (default: the task's, normally 60)",
    )
    p.add_argument(
        "--transport",
        choices=("stdio", "http"),
        default="stdio",
        help="stdio (default; the harness launches the server) or streamable HTTP at /mcp",
    )
    p.add_argument(
        "--host", default="127.0.0.1", metavar="ADDR", help="HTTP bind address (default 127.0.0.1, loopback only)"
    )
    p.add_argument("--port", type=_port, default=8765, help="HTTP port (default 8765)")
    add_overwrite(p, "an earlier recording in RUN_DIR")
    p.add_argument(
        "--initial-poses",
        type=Path,
        metavar="FILE",
        help="start from these poses instead of the task's layout: an assemblyworld.poses file or a "
        "run's final.json (recorded in the trajectory header as initial_poses_from)",
    )
    p.add_argument(
        "--surface",
        choices=("default", "official"),
        default="default",
        help="tools the agent sees: the project's scene tools (default), or the official benchmark's "
        "list_pages / list_webmcp_tools / execute_webmcp_tool / read_manual_page",
    )
    p.add_argument("--print-prompt", action="store_true", help="print the task text and exit")
    p.add_argument(
        "--print-references",
        action="store_true",
        help="print the reference image paths (absolute, in order, one per line) and exit",
    )
    p.add_argument(
        "--log-level",
        default="WARNING",
        choices=("DEBUG", "INFO", "WARNING", "ERROR"),
        help="server log level on stderr (default WARNING)",
    )
    return p


def _fail(msg: str, *, tell_client: bool = False) -> int:
    """Say why the server does not start (stderr, exit 2); with ``tell_client``, also answer the
    MCP client's initialize request with that line, so the client shows it instead of only
    "Connection closed"."""
    line = f"aw-serve: error: {msg}"
    print(line, file=sys.stderr, flush=True)
    if tell_client:
        _refuse_initialize(line)
    return EXIT_USAGE


def _refuse_initialize(message: str, wait_s: float = REFUSAL_WAIT_S) -> None:
    """Answer a stdio client's requests (initialize, or a newer client's discovery probe first)
    with an error carrying ``message`` until it closes stdin; nothing when stdin is a terminal.
    Gives up ``wait_s`` seconds after the last request (or after starting, if none comes)."""
    import json

    from aw.formats.strict_json import parse_json

    try:
        if sys.stdin is None or sys.stdin.isatty():
            return
        while select.select([sys.stdin], [], [], wait_s)[0]:
            line = sys.stdin.readline(1 << 20)  # a request is small: a longer line is not one
            if not line:
                return  # the client closed our stdin: it has read the replies
            try:
                request = parse_json(line)
            except ValueError:
                return
            if isinstance(request, dict) and "id" in request and "method" in request:
                reply = {"jsonrpc": "2.0", "id": request["id"], "error": {"code": -32603, "message": message}}
                sys.stdout.write(json.dumps(reply) + "\n")
                sys.stdout.flush()
    except (OSError, ValueError):
        return


def _remove_empty(run_dir: Path) -> None:
    try:
        run_dir.rmdir()
    except OSError:
        pass


def next_attempt_dir(parent: Path, task_id: str) -> Path:
    """Create and return ``parent/attempt-N/task_id`` for the smallest N whose directory does not
    exist yet (mkdir is atomic: two sessions starting together get different N)."""
    n = 1
    while True:
        run_dir = parent / f"attempt-{n}" / task_id
        run_dir.parent.mkdir(parents=True, exist_ok=True)
        try:
            run_dir.mkdir()
            return run_dir
        except FileExistsError:
            n += 1


def main(argv: list[str] | None = None) -> int:
    typed = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(typed)
    from aw.cli.common import UsageError
    from aw.cli.paths import check_paths
    from aw.formats import FormatError, read_task

    serving = not (args.print_prompt or args.print_references)
    stdio = serving and args.transport == "stdio"
    try:
        check_paths("aw-serve", typed, [(args.task_dir, "task")])
        task = read_task(args.task_dir)
    except (FormatError, UsageError) as exc:
        return _fail(str(exc), tell_client=stdio)
    if args.print_prompt or args.print_references:
        try:
            if args.print_prompt:
                print(task.prompt)
            if args.print_references:
                for path in task.reference_paths():
                    print(path.resolve())
            sys.stdout.flush()
        except BrokenPipeError:  # the reader stopped early (| head): not an error
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    if args.record is None and args.record_under is None:
        return _fail(
            "--record RUN_DIR or --record-under DIR is required to serve (or use --print-prompt / --print-references)",
            tell_client=stdio,
        )
    run_dir = args.record
    if args.record_under is not None:
        try:
            run_dir = next_attempt_dir(args.record_under, task.task_id)
        except OSError as exc:
            return _fail(f"--record-under {args.record_under}: {exc.strerror or exc}", tell_client=stdio)
        print(f"aw-serve: recording in {run_dir}", file=sys.stderr, flush=True)

    logging.basicConfig(level=args.log_level, stream=sys.stderr, format="aw-serve %(levelname)s %(name)s: %(message)s")
    from aw.episode import Episode, RunDirError
    from aw.meshes import load_task_meshes

    try:
        initial = None
        if args.initial_poses is not None:
            from aw.formats.poses import read_initial_poses

            initial = read_initial_poses(args.initial_poses, task.task_id, task.part_ids)
        meshes = load_task_meshes(task)
        episode = Episode(
            task,
            meshes,
            run_dir,
            system=args.system,
            budget_minutes=args.budget_minutes,
            overwrite=args.overwrite,
            initial_poses=initial,
            initial_poses_from=str(args.initial_poses.resolve()) if initial is not None else None,
        )
    except (FormatError, RunDirError, ValueError) as exc:
        if args.record_under is not None:
            _remove_empty(run_dir)
        return _fail(str(exc), tell_client=stdio)

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

    reason: EndReason = "disconnect"
    message = ""
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
    return isinstance(
        exc, (BrokenPipeError, ConnectionResetError, anyio.BrokenResourceError, anyio.ClosedResourceError)
    )


def run() -> None:
    """The ``aw-serve`` entry point: :func:`main`, then exit without the interpreter's teardown.

    When ``main`` returns, the recording is closed and on disk (every trajectory line written
    and synced, ``final.json`` renamed into place) and the run directory's lock is released by
    the kernel at exit. Collecting the heap of modules and GL objects would only keep the client
    waiting for the process to end: 0.5 s of CPU or more, and over 2 s on a loaded machine, where
    the MCP client gives up waiting and kills the server. An exception still unwinds normally."""
    code = main()
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: nothing more can reach it
            pass
    os._exit(code)


if __name__ == "__main__":
    run()
