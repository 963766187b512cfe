"""The suite a task runs on: the one given, or the embedded synthetic suite, built on first use.

The default is ``aw-prepare synthetic``'s own default (20 objects per block, seed 0: 100 tasks in
the benchmark's five cells), built once into ``~/.cache/assemblyworld/suites/`` (or
``$AW_SUITE_CACHE``) and reused from there. Building it takes a few minutes and is said on
stderr before it starts.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from aw.formats import FormatError, read_manifest
from aw.runner.batch import aw_serve_command

__all__ = ["DEFAULT_SUITE_NAME", "suite_cache_dir", "default_suite", "resolve_suite"]

DEFAULT_PER_SOURCE = 20
DEFAULT_SEED = 0
DEFAULT_SUITE_NAME = f"synthetic-{DEFAULT_PER_SOURCE}-seed{DEFAULT_SEED}"  # the name aw-prepare gives it


def suite_cache_dir() -> Path:
    """``$AW_SUITE_CACHE`` if set, else ``~/.cache/assemblyworld/suites``."""
    env = os.environ.get("AW_SUITE_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "assemblyworld" / "suites"


def _aw_prepare() -> list[str]:
    """``aw-prepare`` beside the interpreter (or on PATH, or as a module), as ``aw-serve`` is found."""
    serve = aw_serve_command()
    if len(serve) == 1:
        beside = Path(serve[0]).with_name("aw-prepare")
        if beside.is_file():
            return [str(beside)]
    return [sys.executable, "-c", "import sys; from aw.cli.prepare import main; sys.exit(main())"]


def default_suite(cache: Path | None = None) -> Path:
    """The embedded synthetic suite under ``cache`` (default :func:`suite_cache_dir`), built by
    ``aw-prepare synthetic`` when it is not there yet."""
    out = (cache or suite_cache_dir()) / DEFAULT_SUITE_NAME
    if (out / "manifest.json").is_file():
        return out
    print(
        f"assemblyworld: building the embedded synthetic suite ({DEFAULT_PER_SOURCE} objects per block, seed "
        f"{DEFAULT_SEED}) into {out}, once (a few minutes); pass -T suite=DIR to use another suite",
        file=sys.stderr,
        flush=True,
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    cmd = _aw_prepare() + ["synthetic", "--out", str(out), "--per-source", str(DEFAULT_PER_SOURCE)]
    cmd += ["--seed", str(DEFAULT_SEED), "--no-progress"]
    # aw-prepare's summary goes to stderr: stdout may belong to Inspect (--json)
    done = subprocess.run(cmd, stdout=sys.stderr, stderr=sys.stderr)
    if done.returncode != 0 or not (out / "manifest.json").is_file():
        raise RuntimeError(f"building the embedded synthetic suite into {out} failed (exit status {done.returncode})")
    return out


def resolve_suite(suite: str | None) -> Path:
    """The suite directory of the task argument ``suite`` (None: the embedded synthetic suite);
    a clear error naming the argument when it is not a suite."""
    path = default_suite() if suite is None else Path(suite).expanduser()
    try:
        read_manifest(path)
    except FormatError as exc:
        raise ValueError(f"suite={suite}: {exc}") from None
    if not (path / "tasks").is_dir():
        raise ValueError(
            f"suite={suite}: {path} has no tasks/ folder (a suite converted for scoring only, as aw-prepare "
            "official writes, cannot be played)"
        )
    return path.resolve()
