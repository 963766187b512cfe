"""Mesh loading for task directories (trimesh), with errors that name the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from aw.formats import FormatError, Task

# Part meshes are in normalized scene units (about 1); beyond this the renderer's camera fit and
# the evaluator's arithmetic overflow, so such a file is refused by name.
MAX_VERTEX_COORDINATE = 1e6


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
    if np.abs(mesh.vertices).max() > MAX_VERTEX_COORDINATE:
        raise FormatError(
            path, f"has vertex coordinates beyond +-{MAX_VERTEX_COORDINATE:g} (scene units are normalized, about 1)"
        )
    return mesh


def load_task_meshes(task: Task) -> list[trimesh.Trimesh]:
    """The baked part meshes of a task, in ``task.parts`` order."""
    return [load_mesh(task.root / p.mesh) for p in task.parts]
