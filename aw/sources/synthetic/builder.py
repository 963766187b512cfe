"""Collects the parts of one procedural object: names, identical copies, assembly steps."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import trimesh

from aw.assembly import AssembledObject, SourcePart
from aw.sources.synthetic.prims import placed

__all__ = ["Builder"]


class Builder:
    """Parts of one object in assembled coordinates, with equivalence groups and manual steps.

    Each part belongs to a named step (manual page); steps are ordered by first use.
    """

    def __init__(self, category: str):
        self.category = category
        self.parts: list[SourcePart] = []
        self.groups: list[list[str]] = []
        self._steps: dict[str, list[str]] = {}

    def _name(self, base: str) -> str:
        names = {p.name for p in self.parts}
        if base not in names:
            return base
        k = 2
        while f"{base}_{k}" in names:
            k += 1
        return f"{base}_{k}"

    def add(self, name: str, mesh: trimesh.Trimesh, step: str) -> str:
        name = self._name(name)
        self.parts.append(SourcePart(name, mesh))
        self._steps.setdefault(step, []).append(name)
        return name

    def add_copies(
        self,
        name: str,
        mesh: trimesh.Trimesh,
        placements: Sequence[tuple[Sequence[float], np.ndarray | None]],
        step: str,
    ) -> list[str]:
        """Identical copies of ``mesh`` (made about the origin), one per ``(position, rotation)``."""
        names = [self.add(f"{name}_{k + 1}", placed(mesh, at, rot), step) for k, (at, rot) in enumerate(placements)]
        if len(names) >= 2:
            self.groups.append(names)
        return names

    def transform_all(self, rot: np.ndarray) -> None:
        """Rotate every part about the origin (copies stay identical)."""
        self.parts = [SourcePart(p.name, placed(p.mesh, (0.0, 0.0, 0.0), rot)) for p in self.parts]

    @property
    def n_parts(self) -> int:
        return len(self.parts)

    @property
    def steps(self) -> list[list[str]]:
        return [list(v) for v in self._steps.values()]

    def build(self, object_id: str, source: str, meta: dict | None = None) -> AssembledObject:
        return AssembledObject(
            object_id=object_id,
            source=source,
            dataset="synthetic",
            category=self.category,
            parts=list(self.parts),
            equivalence=[list(g) for g in self.groups] or None,
            meta={"steps": self.steps, **(meta or {})},
        )
