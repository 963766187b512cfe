"""Finding and running refiners.

A refiner is either a Python function ``refine(request: RefineRequest) -> poses (P, 7)`` (built
in, or a plug-in registered under the ``assemblyworld.refiners`` entry-point group), or an
external command that reads a request file and writes a result file (:mod:`aw.refine.exchange`).
Both run in a child process, so that a refiner that hangs is killed at its time limit and one
that crashes takes nothing else down.
"""

from __future__ import annotations

import os
import shlex
import sys
from collections.abc import Callable
from dataclasses import dataclass
from importlib import import_module
from importlib.metadata import entry_points
from pathlib import Path

import numpy as np

from aw.formats.io import last_line
from aw.processes import new_marker, run_supervised
from aw.refine.base import RefineRequest, RefinerError, check_poses
from aw.refine.exchange import read_result, write_request

__all__ = [
    "BUILTIN",
    "ENTRY_POINT_GROUP",
    "RefinerSpec",
    "available",
    "command_label",
    "load_refiner",
    "resolve",
    "run_refiner",
]

ENTRY_POINT_GROUP = "assemblyworld.refiners"
LEFTOVER_GRACE_S = 1.0  # processes a refiner left running after it exited: ended after this long
BUILTIN = {"classical": "aw.refine.classical:refine"}


def _entry_points() -> dict:
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def available() -> list[str]:
    """Names of the built-in and installed refiners."""
    return sorted(set(BUILTIN) | set(_entry_points()))


def load_refiner(name: str) -> Callable[[RefineRequest], object]:
    """The Python refiner called ``name``: built in, else an installed entry point."""
    if name in BUILTIN:
        module, _, attr = BUILTIN[name].partition(":")
        return getattr(import_module(module), attr)
    eps = _entry_points()
    if name not in eps:
        raise RefinerError(
            f"unknown refiner {name!r}; available: {', '.join(available())} (or an external command, --refiner-command)"
        )
    try:
        fn = eps[name].load()
    except Exception as exc:  # a broken plug-in: say which
        raise RefinerError(
            f"refiner {name}: its entry point {eps[name].value} cannot be loaded ({type(exc).__name__}: {exc})"
        ) from None
    return getattr(fn, "refine", fn)


@dataclass(frozen=True)
class RefinerSpec:
    """A refiner to run: ``name`` labels it in messages and run.json; ``command`` is the external
    command (``{request}`` and ``{result}`` stand for the two files, appended when absent), or
    None for a Python refiner run through ``python -m aw.refine.worker``."""

    name: str
    command: tuple[str, ...] | None = None

    def argv(self, request_path: Path, result_path: Path) -> list[str]:
        if self.command is None:
            return [sys.executable, "-m", "aw.refine.worker", self.name, str(request_path), str(result_path)]
        words = [w.replace("{request}", str(request_path)).replace("{result}", str(result_path)) for w in self.command]
        if not any("{request}" in w or "{result}" in w for w in self.command):
            words += [str(request_path), str(result_path)]
        return words


# extensions of scripts and programs that a label leaves out (refine.py is labelled refine)
SCRIPT_SUFFIXES = (".py", ".sh", ".bash", ".js", ".mjs", ".rb", ".pl", ".r", ".jl", ".exe", ".bat", ".cmd")


def command_label(program: str) -> str:
    """The label of an external refiner's program: its file name without a script extension
    (``python refine.py`` and ``./refine.py`` are both ``refine``)."""
    path = Path(program)
    return path.stem if path.suffix.lower() in SCRIPT_SUFFIXES and path.stem else path.name


def resolve(name: str | None, command: str | None = None) -> RefinerSpec:
    """Check a refiner choice before anything runs: a known Python refiner, or a command line
    (named ``name``, else its program's file name, the script's for ``python SCRIPT``)."""
    if command is not None:
        try:
            words = shlex.split(command)
        except ValueError as exc:
            raise RefinerError(f"--refiner-command: {exc}") from None
        if not words:
            raise RefinerError("--refiner-command is empty")
        program = words[1] if Path(words[0]).name.startswith("python") and len(words) > 1 else words[0]
        return RefinerSpec(name or command_label(program), tuple(words))
    if not name:
        raise RefinerError("name a refiner (--refiner) or give --refiner-command")
    load_refiner(name)
    return RefinerSpec(name)


def run_refiner(spec: RefinerSpec, request: RefineRequest, work_dir: Path, timeout_s: float) -> np.ndarray:
    """Run ``spec`` on ``request`` in a child process (its own session); after ``timeout_s`` it is
    killed with every process it started, those in sessions of their own (``setsid()``) and
    orphans included (:mod:`aw.processes`), and nothing it started outlives a normal exit either.
    Returns the checked ``(P, 7)`` poses, or raises :class:`RefinerError`. The request, result
    and the refiner's output stay in ``work_dir`` (``refiner.log``)."""
    work_dir.mkdir(parents=True, exist_ok=True)
    req, res = work_dir / "refine-request.json", work_dir / "refine-result.json"
    res.unlink(missing_ok=True)
    write_request(req, request)
    log = work_dir / "refiner.log"
    try:
        sup = run_supervised(
            spec.argv(req, res),
            env=dict(os.environ),
            marker=new_marker(),
            limit_seconds=timeout_s,
            stdout_path=log,
            stderr_path=log,
            leftover_grace=LEFTOVER_GRACE_S,
        )
    except OSError as exc:
        raise RefinerError(
            f"refiner {spec.name}: cannot start {spec.argv(req, res)[0]} ({exc.strerror or exc})"
        ) from None
    if sup.timed_out:
        raise RefinerError(f"refiner {spec.name}: timed out after {timeout_s:g} s (killed)")
    code = sup.returncode
    if code != 0:
        tail = last_line(log)
        if tail.startswith(f"refiner {spec.name}: "):  # the worker's own verdict on the answer
            raise RefinerError(tail)
        raise RefinerError(f"refiner {spec.name}: exited with code {code}" + (f": {tail}" if tail else ""))
    return check_poses(spec.name, request, read_result(spec.name, res, request.part_ids))
