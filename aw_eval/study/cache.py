"""The resumable per-task cache under ``OUT_DIR/cache``.

A run's entry is keyed by a hash of everything that determines its scores: the task's geometry
files (task.json, part meshes, targets), the run's trajectory and final.json bytes, the score
settings, the evaluator's version and this cache's format version. Entries live at
``cache/runs/<system>/<task_id>/<key>.npz``; writing a new entry removes the stale ones of the
same run. Task facts live at ``cache/tasks/<task_id>/<geometry key>.npz``.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from aw.formats.io import pid_alive
from aw_eval.study.model import RunScore, TaskFacts, load_npz, save_npz

__all__ = ["CACHE_VERSION", "file_digest", "geometry_key", "run_key", "Cache"]

CACHE_VERSION = "1"
_KEY_LEN = 24


def file_digest(path: Path) -> str:
    """sha256 of a file's bytes, or ``absent``."""
    if not path.is_file():
        return "absent"
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def geometry_key(task_dir: Path, targets_path: Path) -> str:
    """Hash of task.json, every file under ``parts/`` and the targets file; for an official
    (converted) task without a task directory, its evaluation points and the targets file."""
    h = hashlib.sha256()
    official = targets_path.parent.parent / "eval_points" / f"{targets_path.stem}.npz"
    if official.is_file():
        files = [official, targets_path]
    else:
        files = [task_dir / "task.json", *sorted((task_dir / "parts").glob("*")), targets_path]
    for f in files:
        h.update(f.name.encode())
        h.update(file_digest(f).encode())
    return h.hexdigest()[:_KEY_LEN]


def run_key(geom_key: str, run_dir: Path, settings_key: str, evaluator_version: str) -> str:
    h = hashlib.sha256()
    for part in (
        CACHE_VERSION,
        evaluator_version,
        settings_key,
        geom_key,
        file_digest(run_dir / "trajectory.jsonl"),
        file_digest(run_dir / "final.json"),
    ):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()[:_KEY_LEN]


def _drop_others(keep: Path) -> None:
    """Remove stale entries next to ``keep`` (same run, older keys)."""
    for old in keep.parent.glob("*.npz"):
        if old != keep:
            old.unlink(missing_ok=True)


class Cache:
    def __init__(self, root: Path):
        self.root = Path(root)

    def remove_stale(self) -> int:
        """Delete the temporary files (``*.npz.tmp<pid>``) that a killed run left, those of live
        processes excepted; returns how many."""
        removed = 0
        for sub in ("runs", "tasks"):
            for tmp in (self.root / sub).rglob("*.npz.tmp*"):
                pid = tmp.name.rpartition(".tmp")[2]
                if pid.isdigit() and pid_alive(int(pid)) and int(pid) != os.getpid():
                    continue
                tmp.unlink(missing_ok=True)
                removed += 1
        return removed

    def _run_path(self, system: str, task_id: str, key: str) -> Path:
        return self.root / "runs" / system / task_id / f"{key}.npz"

    def _facts_path(self, task_id: str, key: str) -> Path:
        return self.root / "tasks" / task_id / f"{key}.npz"

    @property
    def geometry_dir(self) -> Path:
        return self.root / "geometry"

    def get_run(self, system: str, task_id: str, key: str) -> RunScore | None:
        p = self._run_path(system, task_id, key)
        if not p.is_file():
            return None
        try:
            obj = load_npz(p)
        except ValueError:
            p.unlink(missing_ok=True)  # damaged: recompute
            return None
        return obj if isinstance(obj, RunScore) else None

    def put_run(self, score: RunScore, key: str) -> None:
        p = self._run_path(score.system, score.task_id, key)
        save_npz(p, score)
        _drop_others(p)

    def get_facts(self, task_id: str, key: str) -> TaskFacts | None:
        p = self._facts_path(task_id, key)
        if not p.is_file():
            return None
        try:
            obj = load_npz(p)
        except ValueError:
            p.unlink(missing_ok=True)
            return None
        return obj if isinstance(obj, TaskFacts) else None

    def put_facts(self, facts: TaskFacts, key: str) -> None:
        p = self._facts_path(facts.task_id, key)
        save_npz(p, facts)
        _drop_others(p)
