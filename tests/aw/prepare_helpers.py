"""Small hand-made assembled objects for the aw.prepare tests."""

from __future__ import annotations

import numpy as np
import trimesh

from aw.assembly import AssembledObject, SourcePart
from aw.pose import apply_pose
from aw.prepare.geometry import unique_vertices


def box(size, centre) -> trimesh.Trimesh:
    m = trimesh.creation.box(extents=size)
    return trimesh.Trimesh(np.asarray(m.vertices) + np.asarray(centre, float), m.faces, process=False)


def stool(object_id: str = "stool", source: str = "custom") -> AssembledObject:
    """A seat on three identical legs plus a footrest bar: 5 parts, one equivalence group."""
    seat = box((0.5, 0.4, 0.04), (0.0, 0.0, 0.46))
    leg = trimesh.creation.cylinder(radius=0.02, height=0.44, sections=12)
    legs = []
    for k, a in enumerate(2 * np.pi * np.arange(3) / 3):
        v = np.asarray(leg.vertices) + [0.15 * np.cos(a), 0.15 * np.sin(a), 0.22]
        legs.append(SourcePart(f"leg{k + 1}", trimesh.Trimesh(v, leg.faces, process=False)))
    bar = box((0.3, 0.03, 0.02), (0.0, 0.05, 0.15))
    return AssembledObject(
        object_id=object_id,
        source=source,
        dataset="test",
        category="stool",
        parts=[SourcePart("seat", seat), *legs, SourcePart("bar", bar)],
        equivalence=[["leg1", "leg2", "leg3"]],
        meta={"steps": [["leg1", "leg2", "leg3"], ["bar"], ["seat"]]},
    )


def reassembled(targets, part_ids, meshes) -> dict[str, np.ndarray]:
    """Baked meshes moved by their target poses, keyed by source part name."""
    out = {}
    for pid, mesh in zip(part_ids, meshes, strict=True):
        t = targets.parts[pid]
        out[t.source_name] = apply_pose(np.asarray(t.pose), np.asarray(mesh.vertices))
    return out


def brute_force_scale(obj: AssembledObject) -> float:
    """1 / (2 * largest vertex radius about any part's vertex-mean centroid), computed plainly."""
    radius = 0.0
    for p in obj.parts:
        v = unique_vertices(p.mesh)
        c = v.mean(axis=0)
        radius = max(radius, max(float(np.sqrt(((x - c) ** 2).sum())) for x in v))
    return 1.0 / (2.0 * radius)


def normalized_source(obj: AssembledObject, scale: float) -> dict[str, np.ndarray]:
    """``scale * (v - centre)`` per part, centre = centre of the bounding box of all vertices."""
    allv = np.concatenate([p.mesh.vertices for p in obj.parts])
    centre = 0.5 * (allv.min(axis=0) + allv.max(axis=0))
    return {p.name: (np.asarray(p.mesh.vertices) - centre) * scale for p in obj.parts}
