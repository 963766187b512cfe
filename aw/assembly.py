"""The assembled object: what every dataset source produces and what ``aw.prepare`` consumes."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trimesh


@dataclass
class SourcePart:
    """One rigid part, its mesh in the assembled object's frame (Z up, source units)."""

    name: str
    mesh: trimesh.Trimesh


@dataclass
class AssembledObject:
    """An object as published by its dataset, before standardized initialization.

    ``source`` is the benchmark block used for aggregation (``partnet``, ``ikea_manual``,
    ``assemblybench``, ``fantastic_breaks`` or a custom name); ``dataset`` is where the geometry
    came from. ``references`` maps a condition (``image`` or ``manual``) to its reference images
    in order (file paths or ``PIL.Image`` objects); a missing condition means the task builder
    renders one when it needs it. ``equivalence`` optionally lists groups of interchangeable
    part names as annotated by the dataset.
    """

    object_id: str
    source: str
    dataset: str
    category: str
    parts: list[SourcePart]
    references: dict[str, list[Any]] = field(default_factory=dict)
    equivalence: list[list[str]] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.parts:
            raise ValueError(f"object {self.object_id}: no parts")
        names = [p.name for p in self.parts]
        if len(set(names)) != len(names):
            raise ValueError(f"object {self.object_id}: part names must be unique")
        for p in self.parts:
            v = np.asarray(p.mesh.vertices)
            if len(v) == 0 or len(p.mesh.faces) == 0:
                raise ValueError(f"object {self.object_id}: part {p.name} has an empty mesh")
            if not np.all(np.isfinite(v)):
                raise ValueError(f"object {self.object_id}: part {p.name} has non-finite vertices")

    @property
    def n_parts(self) -> int:
        return len(self.parts)


def y_up_to_z_up(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Rotate a Y-up mesh to Z-up with (x, y, z) -> (x, -z, y) (a proper rotation)."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    out = np.stack([v[:, 0], -v[:, 2], v[:, 1]], axis=1)
    return trimesh.Trimesh(out, np.asarray(mesh.faces), process=False)
