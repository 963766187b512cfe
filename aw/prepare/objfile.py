"""Deterministic Wavefront OBJ writing: fixed float format, vertex order kept, no timestamps."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import trimesh

__all__ = ["OBJ_DECIMALS", "obj_bytes", "write_obj"]

OBJ_DECIMALS = 9


def obj_bytes(mesh: trimesh.Trimesh, decimals: int = OBJ_DECIMALS) -> bytes:
    """OBJ text of a triangle mesh: ``v`` lines with ``decimals`` fixed decimals, then ``f`` lines.

    The same mesh always gives the same bytes (``-0`` is written as ``0``).
    """
    v = np.round(np.asarray(mesh.vertices, dtype=np.float64), decimals) + 0.0
    f = np.asarray(mesh.faces, dtype=np.int64) + 1
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise ValueError("obj_bytes needs a triangle mesh")
    if not np.all(np.isfinite(v)):
        raise ValueError("mesh has non-finite vertices")
    fmt = f"v %.{decimals}f %.{decimals}f %.{decimals}f\n"
    text = [
        f"# {len(v)} vertices, {len(f)} faces\n",
        (fmt * len(v)) % tuple(v.ravel()),
        ("f %d %d %d\n" * len(f)) % tuple(f.ravel()),
    ]
    return "".join(text).encode("ascii")


def write_obj(path: str | Path, mesh: trimesh.Trimesh, decimals: int = OBJ_DECIMALS) -> None:
    """Write ``mesh`` to ``path`` atomically (temporary file, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_bytes(obj_bytes(mesh, decimals))
    os.replace(tmp, path)
