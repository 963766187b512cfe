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


# Parts saved each at its own origin: a frequent export mistake that turns the target into a pile.
STACKED_SHARE = 0.5  # a pair is stacked when each axis overlaps by at least this share of the smaller box
PILE_SHARE = 0.75  # with 3 parts or more, a pile when more than this share of the pairs is stacked
CENTRED_SHARE = 0.05  # with 2 parts, a pile when the box centres are this close (share of the smaller box)


@dataclass(frozen=True)
class Pile:
    """Why an object's parts look piled on one point rather than assembled: ``stacked`` of
    ``pairs`` part pairs share most of a box (3 parts or more), or the 2 parts' boxes are centred
    on one point; ``parts`` names the parts of the stacked pairs."""

    stacked: int
    pairs: int
    parts: list[str]

    def reason(self) -> str:
        if self.pairs == 1:
            return "the bounding boxes of its 2 parts are centred on one point"
        return (
            f"the bounding boxes of its parts mostly overlap ({self.stacked} of {self.pairs} part pairs share most "
            "of the smaller part's box)"
        )


def piled_parts(obj: AssembledObject) -> Pile | None:
    """A :class:`Pile` when ``obj``'s parts look saved each at its own origin, else None.

    The parts of an assembly touch; they do not share a volume. A pair is *stacked* when its
    axis-aligned boxes overlap, on every axis, by at least ``STACKED_SHARE`` of the smaller box's
    extent there. With 3 parts or more, more than ``PILE_SHARE`` of the pairs stacked is a pile
    (parts centred on their bounding boxes, centroids or base pivots alike); a few nested pairs,
    such as a bolt in a nut, are not. Two parts may overlap in their boxes (the halves of a slanted
    break), so a pair is a pile only when the centres of its boxes coincide within
    ``CENTRED_SHARE`` of the smaller extent on every axis. Tested on every embedded synthetic
    object (none piled) and on their parts re-centred at the origin (all piled):
    ``tests/aw/test_assembly_pile.py``.
    """
    lo = np.array([np.asarray(p.mesh.vertices).min(axis=0) for p in obj.parts])  # (P, 3)
    hi = np.array([np.asarray(p.mesh.vertices).max(axis=0) for p in obj.parts])  # (P, 3)
    if len(lo) < 2:
        return None
    floor = 1e-3 * float(np.ptp(np.vstack([lo, hi]), axis=0).max())  # flat parts still have an extent
    extent = np.maximum(hi - lo, floor)
    i, j = np.triu_indices(len(lo), k=1)
    smaller = np.minimum(extent[i], extent[j])  # (pairs, 3)
    if len(lo) == 2:
        offset = np.abs((lo[0] + hi[0]) - (lo[1] + hi[1])) / 2
        if np.all(offset <= CENTRED_SHARE * smaller[0]):
            return Pile(1, 1, [p.name for p in obj.parts])
        return None
    overlap = np.minimum(hi[i], hi[j]) - np.maximum(lo[i], lo[j])
    stacked = np.all(overlap >= STACKED_SHARE * smaller, axis=1)
    if stacked.mean() <= PILE_SHARE:
        return None
    names = sorted({obj.parts[k].name for k in np.concatenate([i[stacked], j[stacked]])})
    return Pile(int(stacked.sum()), len(stacked), names)
