"""What a path given on the command line is, and what to type when it is the wrong kind.

Every ``aw-*`` command that takes a suite (``SUITE``), a runs folder (``RUNS``), a task folder
(``TASK_DIR``) or one run (``RUN_DIR``) checks it with :func:`check_paths` before any work: a
path that is recognisably another of these kinds (or a folder one level above or below the right
one) is refused with one line saying what it is and the command to type instead::

    aw-score: error: runs is a runs folder (systems idle) and suite is a suite (1 task): SUITE and RUNS are
    swapped: aw-score suite runs --out r

:func:`classify` looks only at names of files and folders (a few directory listings, nothing
read), so it costs nothing on a right path; a path it cannot place is left to the command's own
checks.
"""

from __future__ import annotations

import re
import shlex
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from aw.cli.common import UsageError, plural

__all__ = ["Found", "classify", "check_paths", "wrong_kind"]

SUITE, PACKAGE, TASKS, TARGETS, TASK = "suite", "package", "tasks", "targets", "task"
RUNS, SYSTEM, RUN, FILE, MISSING, OTHER = "runs", "system", "run", "file", "missing", "other"
RUN_FILES = ("trajectory.jsonl", "final.json", "run.json")
MAX_LISTED = 200  # entries looked at per folder: enough to tell a layout, cheap on a huge folder
_ATTEMPT = re.compile(r"attempt-[0-9]+")
OUT_RUNS = "out runs"  # a runs folder to write into: may be new, or a folder that holds other things
WATCHED = "watched"  # what aw-view watches: a runs folder, one system's runs or one run
# what each wanted kind is called in messages (the metavar of the argument)
METAVARS = {SUITE: "SUITE", RUNS: "RUNS", OUT_RUNS: "RUNS", WATCHED: "PATH", TASK: "TASK_DIR", RUN: "RUN_DIR"}


def _fits(kind: str, want: str) -> bool:
    """Whether a path of ``kind`` is what an argument wanting ``want`` takes."""
    if want == WATCHED:
        return kind in (RUNS, SYSTEM, RUN)
    return kind == (RUNS if want == OUT_RUNS else want)


@dataclass(frozen=True)
class Found:
    """What :func:`classify` saw: ``kind`` (one of ``suite``, ``package``, ``tasks``,
    ``targets``, ``task``, ``runs``, ``system``, ``run``, ``file``, ``missing``, ``other``), and
    ``inside``: sample subfolders that show it (a suite's tasks, a runs folder's systems, a
    system's runs)."""

    kind: str
    path: Path
    inside: tuple[str, ...] = ()

    def describe(self) -> str:
        """``"a suite (3 tasks)"``, ``"one system's runs folder"``, ...: what the path is."""
        n = len(self.inside)
        return {
            SUITE: f"a suite ({plural(n, 'task')})" if n else "a suite",
            PACKAGE: "an official benchmark package",
            TASKS: "a suite's tasks folder",
            TARGETS: "a suite's targets folder (hidden from agents)",
            TASK: "a task folder",
            RUNS: f"a runs folder (systems {', '.join(self.inside[:3])}{', ...' if n > 3 else ''})"
            if n
            else "a runs folder",
            SYSTEM: "one system's runs folder",
            RUN: f"one run (of task {self.path.name})",
            FILE: "a file",
        }.get(self.kind, "")


def _subdirs(path: Path) -> list[Path]:
    try:
        entries = sorted(path.iterdir())[:MAX_LISTED]
    except OSError:
        return []
    return [p for p in entries if not p.name.startswith(".") and p.is_dir()]


def _is_run(path: Path) -> bool:
    return any((path / f).is_file() for f in RUN_FILES)


def _is_system(path: Path) -> bool:
    """Runs in it (``<task_id>/``), or ``aw-serve --record-under`` attempts (``attempt-N/<task_id>/``)."""
    subs = _subdirs(path)
    return any(_is_run(p) for p in subs) or any(
        _ATTEMPT.fullmatch(p.name) and any(_is_run(q) for q in _subdirs(p)) for p in subs
    )


def _is_suite(path: Path) -> bool:
    return (path / "manifest.json").is_file()


def classify(path: str | Path) -> Found:
    """What ``path`` is, from the names of the files and folders in it (see :class:`Found`)."""
    p = Path(path)
    if not p.exists():
        return Found(MISSING, p)
    if not p.is_dir():
        return Found(FILE, p)
    if (p / "benchmark.json").is_file():
        return Found(PACKAGE, p)
    if _is_suite(p):
        return Found(SUITE, p, tuple(t.name for t in _subdirs(p / "tasks")))
    if (p / "task.json").is_file():
        return Found(TASK, p)
    if _is_run(p):
        return Found(RUN, p)
    parent_is_suite = _is_suite(p.resolve().parent)
    if p.resolve().name == "targets" and parent_is_suite:
        return Found(TARGETS, p)
    subs = _subdirs(p)
    tasks = [s.name for s in subs if (s / "task.json").is_file()]
    if tasks and (parent_is_suite or p.resolve().name == "tasks"):
        return Found(TASKS, p, tuple(tasks))
    if _is_system(p):
        return Found(SYSTEM, p, tuple(s.name for s in subs if _is_run(s)))
    systems = [s.name for s in subs if _is_system(s)]
    if systems or (p / "refinement_study.json").is_file():
        return Found(RUNS, p, tuple(systems))
    return Found(OTHER, p, tuple(s.name for s in subs))


def _parent(p: Path, levels: int = 1) -> Path:
    """``p``'s folder ``levels`` up, as the user would type it (``.`` resolved only when needed)."""
    for _ in range(levels):
        p = p.parent if p.name not in ("", ".", "..") else p.resolve().parent
    return p


def wrong_kind(found: Found, want: str) -> tuple[str, Path | str | None] | None:
    """Why ``found`` is not the ``want`` kind (``suite``, ``runs``, ``out runs``, ``watched``,
    ``task`` or ``run``) and what to type instead: ``(reason, right path, a pattern, or None)``; None when it
    is that kind, or when it cannot be placed (the command's own checks then speak)."""
    p, kind, meta = found.path, found.kind, METAVARS[want]
    if _fits(kind, want) or kind == MISSING:
        return None
    if want in (OUT_RUNS, WATCHED):
        if kind == OTHER:  # an output folder may hold anything; aw-view watches any folder
            return None
        if want == WATCHED:
            return f"{found.path} is {found.describe()}, not runs; {meta} is a runs folder or one run", None
        want = RUNS
    what = f"{p} is {found.describe()}"
    if kind == FILE:
        wanted_file = {SUITE: "manifest.json", TASK: "task.json", RUN: None, RUNS: None}[want]
        if p.name == wanted_file or (want == RUN and p.name in RUN_FILES):
            return f"{what}; {meta} is the folder that holds it", _parent(p)
        return None
    if kind == OTHER:  # one level above the right folder?
        below = [Path(p, name) for name in found.inside if classify(Path(p, name)).kind == want]
        if len(below) == 1:
            return f"{p} holds {classify(below[0]).describe()} in {below[0].name}/; {meta} is that folder", below[0]
        if below:
            names = ", ".join(b.name for b in below[:3])
            return f"{p} holds {len(below)} folders of that kind ({names}{', ...' if len(below) > 3 else ''})", None
        return None
    if want == SUITE:
        if kind in (TASKS, TARGETS):
            return f"{what}; {meta} is the suite itself", _parent(p)
        if kind == TASK and _is_suite(p.resolve().parent.parent):
            return f"{p} is one task of a suite; {meta} is the suite, two folders up", _parent(p, 2)
        if kind == TASK:
            return f"{what}, not a suite; aw-serve serves one task", None
        if kind == PACKAGE:
            return f"{what}; convert it into a suite first (aw-prepare official {p} --out SUITE)", None
        return f"{what}, not a suite; {meta} is the suite the tasks come from (manifest.json, tasks/, targets/)", None
    if want == RUNS:
        if kind == SYSTEM:
            return f"{what}; {meta} is the folder above it, which holds every system", _parent(p)
        if kind == RUN:
            return f"{what}; {meta} is the folder two levels above it, which holds every system", _parent(p, 2)
        return (
            f"{what}, not a runs folder; {meta} holds <system>/<task_id>/ runs (aw-run SUITE ... --out RUNS writes them)",
            None,
        )
    if want == TASK:
        if kind == SUITE and found.inside:
            return f"{what}; {meta} is one task's folder", Path(p, "tasks", found.inside[0])
        if kind == TASKS:
            return f"{what}; {meta} is one of the task folders in it", Path(p, found.inside[0])
        if kind == RUN:
            return f"{what}, not a task; {meta} is the task's folder in its suite", f"SUITE/tasks/{p.name}"
        return f"{what}, not a task; {meta} is one task's folder (SUITE/tasks/<task_id>, with task.json)", None
    # want == RUN
    if kind == SYSTEM and found.inside:
        return f"{what}; {meta} is one of the runs in it", Path(p, found.inside[0])
    return f"{what}, not one run; {meta} holds trajectory.jsonl and final.json (RUNS/<system>/<task_id>)", None


def _retyped(prog: str, argv: Sequence[str], swaps: dict[tuple[Path, int], str]) -> str:
    """The command line ``argv`` with arguments replaced: ``swaps`` maps ``(path, k)`` (the
    ``k``-th argument naming ``path``, counting from 0) to what to type there."""
    seen: dict[Path, int] = {}
    words = []
    for a in argv:
        if a.startswith("-"):
            words.append(a)
            continue
        k = seen.get(Path(a), 0)
        seen[Path(a)] = k + 1
        words.append(swaps.get((Path(a), k), a))
    return shlex.join([prog, *words])


def check_paths(prog: str, argv: Sequence[str], wanted: Sequence[tuple[str | Path | None, str]]) -> None:
    """Refuse (:class:`UsageError`, one line) the first path of ``wanted`` (``(path, kind)``
    pairs in the order they are typed, a kind as in :func:`wrong_kind`; None paths skipped) that
    is recognisably another kind, saying what it is and what to type: ``argv`` (the command's
    arguments as typed) with that path replaced, or with two paths in each other's place
    exchanged."""
    given: list[tuple[tuple[Path, int], str, Found]] = []
    for path, want in wanted:
        if path is not None:
            key = (Path(path), sum(1 for (q, _), _w, _f in given if q == Path(path)))
            given.append((key, want, classify(path)))
    for i, (key, want, found) in enumerate(given):  # two paths given in each other's place
        for key_q, want_q, found_q in given[i + 1 :]:
            if _fits(found.kind, want_q) and _fits(found_q.kind, want):
                swapped = _retyped(prog, argv, {key: str(key_q[0]), key_q: str(key[0])})
                raise UsageError(
                    f"{key[0]} is {found.describe()} and {key_q[0]} is {found_q.describe()}: {METAVARS[want]} and "
                    f"{METAVARS[want_q]} are swapped: {swapped}"
                )
    for key, want, found in given:
        problem = wrong_kind(found, want)
        if problem is None:
            continue
        reason, right = problem
        typed = _retyped(prog, argv, {key: METAVARS[want] if right is None else str(right)})
        raise UsageError(f"{reason}: {typed}")
