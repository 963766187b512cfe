"""The public task directory: ``task.json``, ``parts/<id>.<ext>``, ``references/*``.

This is the only thing ``aw-serve`` is given.
"""

from __future__ import annotations

from pathlib import Path
from typing import Final, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from aw.formats.common import MAX_CATEGORY_CHARS, PART_ID_PATTERN, Condition
from aw.formats.errors import FormatError
from aw.formats.io import read_model, write_json_atomic

# Longest execution budget (about 69 days): a longer one overflows the server's expiry timer.
MAX_BUDGET_MINUTES = 100_000.0

TASK_FORMAT: Final = "assemblyworld.task"
TASK_FORMAT_VERSION: Final = 1
MESH_SUFFIXES = (".obj", ".ply", ".glb", ".stl", ".off")

CONVENTIONS: dict[str, str] = {
    "units": "normalized scene units",
    "up": "+Z",
    "handedness": "right-handed",
    "quaternion": "(w, x, y, z)",
    "pose": "[x, y, z, qw, qx, qy, qz]",
    "angles": "degrees",
    "rotation_order": "X, then Y, then Z",
    "camera_axes": "right, up, forward",
}


class TaskPart(BaseModel):
    model_config = ConfigDict(extra="forbid")
    id: str = Field(pattern=PART_ID_PATTERN)
    mesh: str = Field(description="path relative to the task directory, under parts/")


class Task(BaseModel):
    """``task.json``. ``source`` is the benchmark block used for aggregation."""

    model_config = ConfigDict(extra="forbid")
    format: Literal["assemblyworld.task"] = TASK_FORMAT
    format_version: Literal[1] = TASK_FORMAT_VERSION
    task_id: str = Field(pattern=r"^[A-Za-z0-9_.-]{1,128}$")
    source: str = Field(min_length=1, description="partnet | ikea_manual | assemblybench | fantastic_breaks | custom")
    dataset: str = Field(min_length=1, description="where the geometry came from, e.g. synthetic, partnet, folder")
    category: str = Field(default="", max_length=MAX_CATEGORY_CHARS)
    object_id: str = Field(min_length=1, description="paired conditions share an object_id")
    condition: Condition = "none"
    prompt: str = Field(min_length=1)
    parts: list[TaskPart] = Field(min_length=1)
    references: list[str] = Field(default_factory=list, description="image paths relative to the task dir, in order")
    conventions: dict[str, str] = Field(default_factory=lambda: dict(CONVENTIONS))
    budget_minutes: float = Field(default=60.0, gt=0, le=MAX_BUDGET_MINUTES)

    # Set by read_task; not serialized.
    _root: Path | None = None

    @model_validator(mode="after")
    def _check(self) -> Task:
        ids = [p.id for p in self.parts]
        if len(set(ids)) != len(ids):
            raise ValueError("part ids must be unique")
        for p in self.parts:
            _check_relative(p.mesh, "parts/")
            if not p.mesh.lower().endswith(MESH_SUFFIXES):
                raise ValueError(f"part {p.id}: mesh must be one of {MESH_SUFFIXES}")
        for r in self.references:
            _check_relative(r, "references/")
        if self.condition == "none" and self.references:
            raise ValueError("a task with condition 'none' must have no references")
        if self.condition != "none" and not self.references:
            raise ValueError(f"a task with condition '{self.condition}' needs at least one reference image")
        return self

    @property
    def part_ids(self) -> list[str]:
        return [p.id for p in self.parts]

    @property
    def root(self) -> Path:
        if self._root is None:
            raise RuntimeError("task was not read from a directory")
        return self._root

    def mesh_path(self, part_id: str) -> Path:
        for p in self.parts:
            if p.id == part_id:
                return self.root / p.mesh
        raise KeyError(part_id)

    def reference_paths(self) -> list[Path]:
        return [self.root / r for r in self.references]


def _check_relative(rel: str, prefix: str) -> None:
    p = Path(rel)
    if p.is_absolute() or ".." in p.parts or not rel.startswith(prefix):
        raise ValueError(f"{rel!r} must be a relative path under {prefix}")


def read_task(task_dir: str | Path, check_files: bool = True) -> Task:
    """Read and validate ``task_dir/task.json`` (and that its mesh and reference files exist)."""
    task_dir = Path(task_dir)
    path = task_dir / "task.json"
    if not task_dir.is_dir():
        raise FormatError(task_dir, "task directory not found")
    task = read_model(Task, path)
    task._root = task_dir
    if check_files:
        root = task_dir.resolve()
        for rel in [p.mesh for p in task.parts] + list(task.references):
            target = task_dir / rel
            if not target.is_file():
                raise FormatError(path, f"listed file {rel} is missing from the task directory")
            # A symlink must not lead out of the task directory (the server serves only this dir).
            if not target.resolve().is_relative_to(root):
                raise FormatError(path, f"listed file {rel} resolves outside the task directory")
    return task


def write_task(task_dir: str | Path, task: Task) -> Path:
    task_dir = Path(task_dir)
    write_json_atomic(task_dir / "task.json", task)
    task._root = task_dir
    return task_dir / "task.json"
