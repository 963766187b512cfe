"""Mesh loading for task directories (trimesh), with errors that name the file; the parts as the
browser 3D views draw them (report.html, aw-view)."""

from __future__ import annotations

from collections.abc import Sequence
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


DISPLAY_MAX_FACES = 1500  # triangles per part in the browser 3D views (vertex clustering above it)


def simplify_for_display(vertices: np.ndarray, faces: np.ndarray, max_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertex clustering: ``vertices (v, 3)`` and ``faces (f, 3)`` snapped to a grid that leaves at
    most ``max_faces`` triangles (unchanged when there are no more than that)."""
    if len(faces) <= max_faces:
        return vertices, faces
    extent = float(np.ptp(vertices, axis=0).max()) or 1.0
    cells = 64
    while True:
        q = np.floor((vertices - vertices.min(axis=0)) / (extent / cells)).astype(np.int64)
        _, first, inverse = np.unique(q, axis=0, return_index=True, return_inverse=True)
        f = inverse.reshape(-1)[faces]
        f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
        f = np.unique(np.sort(f, axis=1), axis=0) if len(f) > max_faces else f
        if len(f) <= max_faces or cells <= 4:
            return vertices[first], f
        cells //= 2


def display_parts(
    part_ids: Sequence[str], meshes: Sequence[trimesh.Trimesh], colors: np.ndarray, max_faces: int = DISPLAY_MAX_FACES
) -> list[dict]:
    """The parts as the browser 3D views draw them: per part ``{id, color: "#rrggbb", v, f}`` with
    ``v`` the decimated vertices (baked frame, flat, 5 decimals) and ``f`` the faces (flat);
    ``colors (P, 3)`` sRGB in [0, 1] (:func:`aw.render.part_colors`, as in the captures)."""
    out = []
    for pid, m, c in zip(part_ids, meshes, colors, strict=True):
        v, f = simplify_for_display(np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64), max_faces)
        out.append(
            {
                "id": pid,
                "color": "#" + "".join(f"{int(round(255 * float(x))):02x}" for x in c),
                "v": np.round(v, 5).reshape(-1).tolist(),
                "f": f.reshape(-1).tolist(),
            }
        )
    return out
