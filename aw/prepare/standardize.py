"""Standardized initialization (Appendix A.1): PCA frames, shared scale, yaw, scatter, baking.

For an :class:`~aw.assembly.AssembledObject` with parts ``i`` (source units, assembled frame):

* ``V_i``: the part's unique vertices (first occurrence, mesh order).
* Centroid ``c_i``: the mean of ``V_i`` (the vertex mean, which is also the origin of the
  part's vertex-PCA frame). PCA frame ``A_i`` (3x3, columns = principal axes in descending
  variance, right-handed): :func:`aw.pose.pca_frame` of ``V_i``.
* Shared normalization divisor ``D = 2 * max_i max_{v in V_i} |v - c_i|`` (twice the largest
  vertex radius about any part's centroid); ``scale = 1 / D`` multiplies source coordinates.
  It depends only on the individual parts, never on the assembled poses.
* Yaw ``theta_i`` uniform in ``[-pi, pi)`` from ``numpy.random.default_rng(seed)``.
* Baked vertex ``b = Rz(theta_i) A_i^T scale (v - c_i) + t_i``: the part in its PCA frame
  (smallest axis along world Z), yawed, and moved by ``t_i`` so it rests on ``z = 0`` at its
  place in the XY scatter (:mod:`aw.prepare.layout`). Every initial body pose is the identity.
* The assembled target is ``scale * (v - centre)`` with ``centre`` the centre of the axis-aligned
  bounding box of all parts' vertices, so the normalized assembled object is centred on the
  origin. Part ``i``'s target pose maps its baked mesh onto it:
  ``R_i = A_i Rz(theta_i)^T``, ``p_i = -R_i t_i + scale (c_i - centre)``.
* Part ids ``p01, p02, ...`` are assigned in a seeded random order (ids do not reveal the
  source order).

Random draws, in this order, from ``default_rng(seed)``: the yaws (n values), the id
permutation, the packing order. Nothing else is random.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import trimesh

from aw.assembly import AssembledObject, SourcePart
from aw.pose import apply_pose, matrix_to_quat, pca_frame, rotation_about_axis
from aw.prepare.geometry import eval_divisor, unique_vertices
from aw.prepare.layout import shelf_pack

__all__ = [
    "PreparedPart",
    "PreparedObject",
    "PartFrame",
    "clean_object",
    "assembled_at_start",
    "ASSEMBLED_TOLERANCE",
    "part_frames",
    "normalization_divisor",
    "standardize",
    "part_ids",
]


@dataclass(frozen=True)
class PartFrame:
    """A source part's PCA placement: ``centroid (3,)`` and ``axes (3, 3)`` (columns)."""

    centroid: np.ndarray
    axes: np.ndarray


@dataclass
class PreparedPart:
    """One part of a task: anonymized id, baked mesh (normalized units) and hidden target pose."""

    part_id: str
    source_name: str
    mesh: trimesh.Trimesh
    target: np.ndarray  # (7,) wire pose mapping the baked mesh onto the normalized assembly
    distractor: bool = False


@dataclass
class PreparedObject:
    """A standardized object: what a task directory and its targets file are written from.

    ``parts`` are in id order. ``scale`` multiplies source coordinates (``1 / D``);
    ``centre (3,)`` is the source-frame point that maps to the origin. ``eval_divisor`` is set
    only when scoring must not recompute it from the task's own parts (inventory variants).
    """

    obj: AssembledObject
    seed: int
    scale: float
    centre: np.ndarray
    parts: list[PreparedPart]
    equivalence_hint: list[list[str]] | None = None
    eval_divisor: float | None = None
    variant: dict = field(default_factory=lambda: {"kind": "original"})

    def part(self, part_id: str) -> PreparedPart:
        for p in self.parts:
            if p.part_id == part_id:
                return p
        raise KeyError(part_id)

    @property
    def part_ids(self) -> list[str]:
        return [p.part_id for p in self.parts]

    @property
    def scored_parts(self) -> list[PreparedPart]:
        return [p for p in self.parts if not p.distractor]

    def divisor(self) -> float:
        """Evaluation divisor in baked units: the stored one, else computed from scored parts."""
        if self.eval_divisor is not None:
            return self.eval_divisor
        return eval_divisor([p.mesh for p in self.scored_parts])

    def with_parts(self, parts: list[PreparedPart], **changes) -> PreparedObject:
        return replace(self, parts=sorted(parts, key=lambda p: p.part_id), **changes)


ASSEMBLED_TOLERANCE = 1e-3
"""Two parts keep their assembled placement when one rigid motion takes both onto their targets
to within this many normalized units (the object is about 1 across)."""


def assembled_at_start(prep: PreparedObject, tol: float = ASSEMBLED_TOLERANCE) -> list[str]:
    """Scored parts already assembled among themselves in the initial layout: the largest group
    (two or more) whose target poses are one rigid motion, so that the whole-assembly
    registration can put them on their targets with no move at all; a one-part object's part;
    else ``[]``. An object where this is every part cannot be assessed (an agent that never
    moves scores PA 100%)."""
    parts = prep.scored_parts
    if len(parts) == 1:
        return [parts[0].part_id]
    # A necessary condition for every pair at once (hundreds of parts): both target poses take
    # one vertex of part a's mesh to within tol of each other (slack far above the rounding of
    # the two ways of computing it); only the pairs that pass are checked on every vertex.
    targets = np.array([q.target for q in parts], dtype=np.float64)  # (P, 7)
    firsts = np.array([np.asarray(q.mesh.vertices[0], dtype=np.float64) for q in parts])  # (P, 3)
    moved = apply_pose(targets[None], firsts[:, None, None, :])[:, :, 0]  # (a, b, 3): pose b on a vertex of a
    near = (
        np.abs(moved - moved[np.arange(len(parts)), np.arange(len(parts))][:, None]).max(axis=-1)
        <= tol * (1 + 1e-6) + 1e-12
    )
    best: list[str] = []
    for ia, a in enumerate(parts):
        group = [
            parts[ib].part_id
            for ib in np.flatnonzero(near[ia])
            if all(
                float(np.abs(apply_pose(a.target, m.vertices) - apply_pose(parts[ib].target, m.vertices)).max()) <= tol
                for m in (a.mesh, parts[ib].mesh)
            )
        ]
        if len(group) > len(best):
            best = group
        if len(best) == len(parts):
            break
    return best if len(best) >= 2 else []


def referenced_only(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The mesh without vertices that no face uses (OBJ readers drop them), order kept."""
    faces = np.asarray(mesh.faces, dtype=np.int64)
    used = np.zeros(len(mesh.vertices), dtype=bool)
    used[faces.ravel()] = True
    if used.all():
        return mesh
    new_index = np.cumsum(used) - 1
    return trimesh.Trimesh(np.asarray(mesh.vertices)[used], new_index[faces], process=False)


def part_frames(obj: AssembledObject) -> list[PartFrame]:
    """Vertex-PCA frame of every part's unique vertices, in part order."""
    out = []
    for p in obj.parts:
        origin, axes = pca_frame(unique_vertices(p.mesh))
        out.append(PartFrame(origin, axes))
    return out


def normalization_divisor(obj: AssembledObject, frames: list[PartFrame] | None = None) -> float:
    """``D``: twice the largest vertex radius about any part's centroid (source units)."""
    frames = frames if frames is not None else part_frames(obj)
    radius = max(
        float(np.linalg.norm(unique_vertices(p.mesh) - f.centroid, axis=1).max())
        for p, f in zip(obj.parts, frames, strict=True)
    )
    if not radius > 0:
        raise ValueError(f"object {obj.object_id}: every part is a single point; nothing to normalize")
    return 2.0 * radius


def part_ids(n: int, permutation) -> list[str]:
    """Anonymized ids: part ``k`` gets ``p{permutation[k] + 1}``, zero-padded to two digits or more."""
    width = max(2, len(str(n)))
    return [f"p{int(permutation[k]) + 1:0{width}d}" for k in range(n)]


def yawed_local(mesh: trimesh.Trimesh, frame: PartFrame, scale: float, yaw: float) -> np.ndarray:
    """Vertices ``(n, 3)`` of a part in its scaled PCA frame, rotated by ``yaw`` about Z."""
    rz = rotation_about_axis(2, yaw)
    local = (np.asarray(mesh.vertices, dtype=np.float64) - frame.centroid) @ frame.axes * scale
    return local @ rz.T


def target_pose(frame: PartFrame, scale: float, yaw: float, offset: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Wire pose ``(7,)`` mapping the baked part (``offset`` = its translation) onto the assembly."""
    rot = frame.axes @ rotation_about_axis(2, yaw).T
    pos = -rot @ offset + scale * (frame.centroid - centre)
    return np.concatenate([pos, matrix_to_quat(rot)])


def footprint(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounds ``(lo (3,), hi (3,))`` of ``vertices: (n, 3)``."""
    return vertices.min(axis=0), vertices.max(axis=0)


def clean_object(obj: AssembledObject) -> AssembledObject:
    """``obj`` with unreferenced vertices removed from every part (the same object if none)."""
    cleaned = [referenced_only(p.mesh) for p in obj.parts]
    if all(c is p.mesh for c, p in zip(cleaned, obj.parts, strict=True)):
        return obj
    return replace(obj, parts=[SourcePart(p.name, c) for p, c in zip(obj.parts, cleaned, strict=True)])


def standardize(obj: AssembledObject, seed: int = 0) -> PreparedObject:
    """Apply the standardized initialization of Appendix A.1 to ``obj`` with ``seed``.

    Vertices that no face references are dropped first (they would not survive an OBJ round
    trip and must not influence frames or scale).
    """
    obj = clean_object(obj)
    frames = part_frames(obj)
    scale = 1.0 / normalization_divisor(obj, frames)
    all_v = np.concatenate([np.asarray(p.mesh.vertices, dtype=np.float64) for p in obj.parts])
    centre = 0.5 * (all_v.min(axis=0) + all_v.max(axis=0))

    n = obj.n_parts
    rng = np.random.default_rng(seed)
    yaws = rng.uniform(-np.pi, np.pi, size=n)
    ids = part_ids(n, rng.permutation(n))
    order = rng.permutation(n)

    local = [yawed_local(p.mesh, f, scale, y) for p, f, y in zip(obj.parts, frames, yaws, strict=True)]
    bounds = [footprint(v) for v in local]
    sizes = np.array([(hi - lo)[:2] for lo, hi in bounds])
    corners = shelf_pack(sizes, order)

    parts = []
    for k, (src, frame, yaw, v, (lo, _hi)) in enumerate(zip(obj.parts, frames, yaws, local, bounds, strict=True)):
        offset = np.array([corners[k, 0] - lo[0], corners[k, 1] - lo[1], -lo[2]])
        mesh = trimesh.Trimesh(v + offset, np.asarray(src.mesh.faces), process=False)
        parts.append(PreparedPart(ids[k], src.name, mesh, target_pose(frame, scale, yaw, offset, centre)))

    name_to_id = {p.source_name: p.part_id for p in parts}
    hint: list[list[str]] | None = None
    if obj.equivalence:
        groups: list[list[str]] = []
        for group in obj.equivalence:
            unknown = [g for g in group if g not in name_to_id]
            if unknown:
                raise ValueError(f"object {obj.object_id}: equivalence names unknown parts {unknown}")
            ids_g = sorted(name_to_id[g] for g in group)
            if len(ids_g) >= 2:
                groups.append(ids_g)
        hint = sorted(groups) or None
    return PreparedObject(obj, seed, scale, centre, sorted(parts, key=lambda p: p.part_id), hint)
