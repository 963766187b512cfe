"""The only way the viewer opens a file.

:class:`PublicFiles` lets a path through only when it lies, links resolved, under an allowed
root (the watched folder, the public task directories found for its episodes) and outside every
suite's hidden folders (``targets/``, ``eval_points/``, ``official/`` beside a ``manifest.json``),
even when the watched folder holds a suite. Without ``--suite`` nothing else opens files, so no
byte of a target is read (``aw_view.scores`` reads targets, and only with ``--suite``).

:class:`TaskFiles` finds an episode's public task directory (``--tasks DIR``, ``--suite
SUITE``'s ``tasks/``, or the suite an ``aw-run`` batch names in its ``.aw-batch.json``) and
keeps what the pages need of it: the part meshes as the 3D views draw them, coloured as in the
captures, the reference images and the budget.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aw.formats import FormatError, Task, read_task

__all__ = ["NotPublic", "PublicFiles", "TaskFiles", "TaskView", "HIDDEN_SUITE_FOLDERS"]

HIDDEN_SUITE_FOLDERS = ("targets", "eval_points", "official")


class NotPublic(Exception):
    """A path the viewer may not open."""


class PublicFiles:
    """The gate: ``check(path)`` returns the resolved path or raises :class:`NotPublic`."""

    def __init__(self, roots: list[Path]):
        self._roots = [Path(os.path.realpath(r)) for r in roots]
        self._lock = threading.Lock()
        self._suite_dirs: dict[Path, bool] = {}

    def allow(self, root: Path) -> Path:
        """Add ``root`` (a public task directory) to the allowed roots; returns it resolved."""
        real = Path(os.path.realpath(root))
        self._refuse_hidden(real, root)
        with self._lock:
            if real not in self._roots:
                self._roots.append(real)
        return real

    def _is_suite(self, folder: Path) -> bool:
        with self._lock:
            known = self._suite_dirs.get(folder)
        if known is None:
            known = (folder / "manifest.json").is_file()
            with self._lock:
                self._suite_dirs[folder] = known
        return known

    def _refuse_hidden(self, real: Path, shown: Path) -> None:
        for parent in real.parents:
            if self._is_suite(parent):
                first = real.relative_to(parent).parts[:1]
                if first and first[0] in HIDDEN_SUITE_FOLDERS:
                    raise NotPublic(f"{shown}: a suite's hidden {first[0]}/ folder is never read")

    def check(self, path: Path) -> Path:
        real = Path(os.path.realpath(path))
        with self._lock:
            roots = list(self._roots)
        if not any(real == r or r in real.parents for r in roots):
            raise NotPublic(f"{path}: outside the watched folder and the tasks' public files")
        self._refuse_hidden(real, path)
        return real

    def read_bytes(self, path: Path, limit: int = 64 << 20) -> bytes:
        """The bytes of an allowed file of at most ``limit`` bytes (``OSError``, :class:`NotPublic`)."""
        real = self.check(path)
        with open(real, "rb") as fh:
            data = fh.read(limit + 1)
        if len(data) > limit:
            raise NotPublic(f"{path}: larger than {limit} bytes")
        return data


@dataclass
class TaskView:
    """What the pages show of one public task: the parts as the 3D view draws them, in the
    recording's part order, coloured by their place in ``task.json`` (as the captures are)."""

    task_dir: Path
    task: Task
    parts: list[dict]
    budget_seconds: float

    def reference(self, k: int) -> Path:
        return self.task.root / self.task.references[k]


class TaskFiles:
    """Finds and reads the public task directory of each task id, once per ``task.json`` version.
    ``folders``: directories that hold ``<task_id>/task.json`` (``--tasks``, ``SUITE/tasks``)."""

    def __init__(self, public: PublicFiles, folders: list[Path]):
        self.public = public
        self.folders = [Path(f) for f in folders]
        self._lock = threading.Lock()
        self._views: dict[tuple[Path, int], TaskView] = {}
        self._tasks: dict[tuple[Path, int], Task] = {}

    def find(self, task_id: str, suites: list[Path]) -> Path | None:
        """The task directory of ``task_id``: in the given folders, else in the ``tasks/`` of
        ``suites`` (the suites that ``aw-run`` batches name)."""
        if not task_id or "/" in task_id or task_id in (".", ".."):
            return None
        for folder in [*self.folders, *(Path(s) / "tasks" for s in suites)]:
            candidate = folder / task_id
            if (candidate / "task.json").is_file():
                return candidate
        return None

    def task(self, task_dir: Path) -> Task:
        """The task's ``task.json`` (read again when it changes; ``FormatError``, :class:`NotPublic`)."""
        real = self.public.allow(task_dir)
        stamp = (real / "task.json").stat().st_mtime_ns
        with self._lock:
            cached = self._tasks.get((real, stamp))
        if cached is None:
            cached = read_task(real)
            with self._lock:
                self._tasks[(real, stamp)] = cached
        return cached

    def view(self, task_dir: Path, part_ids: list[str]) -> TaskView:
        """The task's :class:`TaskView` for a recording with ``part_ids`` (``FormatError`` when the
        task cannot be read or its parts differ from the recording's, :class:`NotPublic`)."""
        real = self.public.allow(task_dir)
        stamp = (real / "task.json").stat().st_mtime_ns
        with self._lock:
            cached = self._views.get((real, stamp))
        if cached is not None and [p["id"] for p in cached.parts] == list(part_ids):
            return cached
        from aw.meshes import display_parts, load_task_meshes
        from aw.render import part_colors

        task = self.task(real)
        if set(task.part_ids) != set(part_ids):
            raise FormatError(real / "task.json", f"its parts {task.part_ids} are not the recording's {part_ids}")
        for p in task.parts:
            self.public.check(real / p.mesh)
        meshes = dict(zip(task.part_ids, load_task_meshes(task), strict=True))
        colors = dict(zip(task.part_ids, part_colors(len(task.part_ids)), strict=True))
        parts = display_parts(part_ids, [meshes[p] for p in part_ids], np.array([colors[p] for p in part_ids]))
        view = TaskView(real, task, parts, 60.0 * task.budget_minutes)
        with self._lock:
            self._views[(real, stamp)] = view
        return view
