"""Fixtures for the format tests: small valid instances written to tmp_path."""

from __future__ import annotations

from pathlib import Path

import pytest
import trimesh

from aw.formats import Task, TaskPart


def make_task_dir(root: Path, n_parts: int = 2, condition: str = "none", task_id: str = "demo-0001") -> Path:
    """A valid task directory with ``n_parts`` box meshes (and one reference image if needed)."""
    task_dir = root / task_id
    (task_dir / "parts").mkdir(parents=True)
    parts = []
    for i in range(1, n_parts + 1):
        pid = f"p{i:02d}"
        trimesh.creation.box([0.1 * i, 0.2, 0.3]).export(task_dir / "parts" / f"{pid}.obj")
        parts.append(TaskPart(id=pid, mesh=f"parts/{pid}.obj"))
    refs = []
    if condition != "none":
        (task_dir / "references").mkdir()
        (task_dir / "references" / "01.png").write_bytes(b"\x89PNG\r\n\x1a\n")
        refs = ["references/01.png"]
    task = Task(
        task_id=task_id,
        source="partnet",
        dataset="synthetic",
        category="chair",
        object_id="obj-1",
        condition=condition,
        prompt="Assemble the supplied parts into a coherent object.",
        parts=parts,
        references=refs,
    )
    from aw.formats import write_task

    write_task(task_dir, task)
    return task_dir


@pytest.fixture
def task_dir(tmp_path: Path) -> Path:
    return make_task_dir(tmp_path)


@pytest.fixture
def make_task():
    """The task-directory factory itself: ``make_task(root, n_parts=2, condition="none", task_id=...)``."""
    return make_task_dir
