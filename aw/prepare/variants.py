"""Robustness variants of Appendix E: alternative layouts, one part removed, one distractor added.

Geometry, normalization and the assembled targets never change. Inventory changes keep every
unaffected part's baked mesh (its initial pose) as it was; ids are re-anonymized with the
variant's seed so that a gap in the numbering cannot reveal a removed part and the added part
is not recognizable by its id.
"""

from __future__ import annotations

import numpy as np
import trimesh

from aw.assembly import AssembledObject
from aw.pose import IDENTITY_POSE, pca_frame
from aw.prepare.geometry import unique_vertices
from aw.prepare.layout import free_spot
from aw.prepare.standardize import (
    PartFrame,
    PreparedObject,
    PreparedPart,
    clean_object,
    footprint,
    normalization_divisor,
    part_ids,
    standardize,
    yawed_local,
)

__all__ = ["layout_variant", "remove_part", "add_distractor"]


def layout_variant(obj: AssembledObject, layout_seed: int) -> PreparedObject:
    """The same object initialized with another seed (new yaws, scatter and ids)."""
    prep = standardize(obj, layout_seed)
    prep.variant = {"kind": "layout", "layout_seed": int(layout_seed)}
    return prep


def _reanonymize(
    prep: PreparedObject, parts: list[PreparedPart], rng: np.random.Generator, **changes
) -> PreparedObject:
    new_ids = part_ids(len(parts), rng.permutation(len(parts)))
    renamed = {p.part_id: nid for p, nid in zip(parts, new_ids, strict=True)}
    out = [PreparedPart(renamed[p.part_id], p.source_name, p.mesh, p.target, p.distractor) for p in parts]
    hint = None
    if prep.equivalence_hint:
        groups = [sorted(renamed[i] for i in g if i in renamed) for g in prep.equivalence_hint]
        hint = sorted(g for g in groups if len(g) >= 2) or None
    return prep.with_parts(out, equivalence_hint=hint, **changes)


def remove_part(prep: PreparedObject, seed: int) -> PreparedObject:
    """Drop one seeded part. Retained parts keep their meshes, targets and the original divisor."""
    n = len(prep.parts)
    if n < 3:
        raise ValueError(f"object {prep.obj.object_id}: removing a part needs at least 3 parts, it has {n}")
    if any(p.distractor for p in prep.parts):
        raise ValueError("remove_part applies to an original task, not to one with a distractor")
    rng = np.random.default_rng(seed)
    k = int(rng.integers(n))
    removed = prep.parts[k]
    kept = [p for i, p in enumerate(prep.parts) if i != k]
    return _reanonymize(
        prep,
        kept,
        rng,
        eval_divisor=prep.divisor(),
        variant={"kind": "missing", "removed_source_names": [removed.source_name], "layout_seed": prep.seed},
    )


def add_distractor(prep: PreparedObject, donor: AssembledObject, seed: int) -> PreparedObject:
    """Add one seeded part of ``donor`` (another object of the same source) in a free spot.

    The part is normalized as in its own task (the donor's shared scale), lies in its PCA frame
    with a seeded yaw, rests on ``z = 0`` beside the existing layout, and is flagged as a
    distractor with an identity dummy target. Existing parts keep their meshes and targets.
    """
    if donor.object_id == prep.obj.object_id:
        raise ValueError("the distractor must come from a different object")
    if any(p.distractor for p in prep.parts):
        raise ValueError("the task already has a distractor")
    donor = clean_object(donor)
    rng = np.random.default_rng(seed)
    src = donor.parts[int(rng.integers(donor.n_parts))]
    yaw = float(rng.uniform(-np.pi, np.pi))
    scale = 1.0 / normalization_divisor(donor)
    frame = PartFrame(*pca_frame(unique_vertices(src.mesh)))
    local = yawed_local(src.mesh, frame, scale, yaw)
    lo, hi = footprint(local)
    boxes = [footprint(np.asarray(p.mesh.vertices)) for p in prep.parts]
    corner = free_spot([b[0][:2] for b in boxes], [b[1][:2] for b in boxes], (hi - lo)[:2], rng)
    offset = np.array([corner[0] - lo[0], corner[1] - lo[1], -lo[2]])
    mesh = trimesh.Trimesh(local + offset, np.asarray(src.mesh.faces), process=False)
    extra = PreparedPart("distractor", f"{donor.object_id}/{src.name}", mesh, IDENTITY_POSE.copy(), distractor=True)
    return _reanonymize(
        prep,
        list(prep.parts) + [extra],
        rng,
        eval_divisor=prep.divisor(),
        variant={"kind": "distractor", "distractor_from": donor.object_id, "layout_seed": prep.seed},
    )
