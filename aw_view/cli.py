"""aw-view: watch recorded episodes live in a browser, one run or whole batches.

    aw-view PATH [--port P] [--host H] [--suite SUITE] [--tasks DIR] [--cache DIR]

PATH is one run directory, a runs folder (every system and task under it, aw-serve
--record-under attempts included) or the --out folder of a running aw-run. The page updates
as the recordings grow; it reads only what is on disk (recordings and the tasks' public files),
never writes into a run directory and never takes a run's lock. See docs/harnesses.md,
"Watching episodes".
"""

from __future__ import annotations

import argparse
import secrets
import signal
import socket
import sys
from pathlib import Path

from aw.cli.common import UsageError, check_in_dir, new_parser, positive_float, run_main

DEFAULT_PORT = 8770


def build_parser() -> argparse.ArgumentParser:
    p = new_parser(
        "aw-view",
        "Watch recorded episodes live in a browser: a page of every run, and each episode's scene, calls and captures.",
        epilog=__doc__.partition("\n\n")[2],
    )
    p.add_argument("path", type=Path, metavar="PATH", help="a run directory, a runs folder, or aw-run's --out folder")
    p.add_argument(
        "--port",
        type=int,
        default=DEFAULT_PORT,
        metavar="P",
        help=f"port to serve on (default {DEFAULT_PORT}; 0: any free port)",
    )
    p.add_argument(
        "--host",
        default="127.0.0.1",
        metavar="H",
        help="address to bind (default 127.0.0.1); any other needs the token printed in the URL",
    )
    p.add_argument(
        "--suite",
        type=Path,
        metavar="SUITE",
        help="also read the suite's hidden targets: the target as a ghost and each state's PA/SR/SCD "
        "(fast for states, exact for the final one)",
    )
    p.add_argument(
        "--tasks",
        type=Path,
        action="append",
        default=[],
        metavar="DIR",
        help="a folder of public task directories (SUITE/tasks) for the scene and reference images "
        "(repeatable; aw-run batches name theirs)",
    )
    p.add_argument(
        "--cache",
        type=Path,
        metavar="DIR",
        help="with --suite: where scores are kept (default ~/.cache/assemblyworld/view; an aw-score "
        "REPORT/cache folder reuses its scores)",
    )
    p.add_argument(
        "--stuck-minutes",
        type=positive_float("--stuck-minutes"),
        default=2.0,
        metavar="M",
        help="a running episode without a call for this long is marked stuck (default 2)",
    )
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return run_main("aw-view", lambda: _serve(args))


def _inside(path: Path, root: Path) -> bool:
    path, root = path.resolve(), root.resolve()
    return path == root or root in path.parents


def default_cache() -> Path:
    return Path.home() / ".cache" / "assemblyworld" / "view"


def _serve(args: argparse.Namespace) -> int:
    from aw_view.public import PublicFiles, TaskFiles
    from aw_view.server import LOOPBACK_HOSTS, ViewerServer
    from aw_view.watch import Watch

    root = check_in_dir(args.path, "PATH").resolve()
    if not 0 <= args.port <= 65535:
        raise UsageError(f"--port must be in 0..65535, got {args.port}")
    folders = [check_in_dir(d, "--tasks").resolve() for d in args.tasks]
    scorer = None
    if args.suite is not None:
        suite = check_in_dir(args.suite, "--suite").resolve()
        folders.append(suite / "tasks")
        cache = (args.cache or default_cache()).resolve()
        if _inside(cache, root):
            raise UsageError(f"--cache {cache}: inside the watched folder; the viewer never writes there")
        from aw.formats import FormatError
        from aw_view.scores import Scorer

        try:
            scorer = Scorer(suite, cache)
        except FormatError as exc:
            raise UsageError(f"--suite {args.suite}: {exc}") from None
    elif args.cache is not None:
        raise UsageError("--cache applies with --suite (scores are what it keeps)")
    token = None
    if args.host not in LOOPBACK_HOSTS:
        token = secrets.token_urlsafe(18)
        print(
            f"aw-view: warning: serving on {args.host}, not this machine alone: anyone who can reach it and has "
            "the URL below (it carries a token) sees the recordings",
            file=sys.stderr,
        )
    public = PublicFiles([root])
    watch = Watch(root, public, TaskFiles(public, folders), 60.0 * args.stuck_minutes, scorer)
    try:
        server = ViewerServer((args.host, args.port), watch, token)
    except OSError as exc:
        hint = "; pass another --port (0: any free port)" if exc.errno == 98 else ""
        raise UsageError(f"cannot serve on {args.host}:{args.port} ({exc.strerror or exc}){hint}") from None
    shown = args.host if args.host not in ("0.0.0.0", "::", "") else socket.gethostname()
    if ":" in shown:
        shown = f"[{shown}]"
    url = f"http://{shown}:{server.port}/" + (f"?token={token}" if token else "")
    print(f"aw-view: watching {root} at {url}", flush=True)
    if scorer is not None:
        print(f"aw-view: scores of {args.suite} computed here and kept in {scorer.cache.root}", flush=True)

    def stop(signum: int, frame: object) -> None:
        raise SystemExit(0)

    signal.signal(signal.SIGTERM, stop)
    try:
        server.serve_forever(poll_interval=0.2)
    finally:
        server.server_close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
