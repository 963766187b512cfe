"""Mesh loading for task directories (trimesh), with errors that name the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from aw.formats import FormatError, Task


def load_mesh(path: str | Path) -> trimesh.Trimesh:
    """Load one triangle mesh without trimesh's processing (vertex order is kept)."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(path, "mesh file not found")
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for broken files
        raise FormatError(path, f"cannot be read as a mesh ({type(exc).__name__}: {exc})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.vertices) == 0 or len(mesh.faces) == 0:
        raise FormatError(path, "contains no triangles")
    if not np.all(np.isfinite(mesh.vertices)):
        raise FormatError(path, "has non-finite vertex coordinates")
    return mesh


def load_task_meshes(task: Task) -> list[trimesh.Trimesh]:
    """The baked part meshes of a task, in ``task.parts`` order."""
    return [load_mesh(task.root / p.mesh) for p in task.parts]
