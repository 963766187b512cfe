"""Sanity checks of procedural objects: parts that look alike without being meant to."""

from __future__ import annotations

import numpy as np

from aw.assembly import AssembledObject
from aw.prepare.geometry import pca_box, unique_vertices

__all__ = ["shape_signature", "accidental_twins"]


def shape_signature(mesh) -> np.ndarray:
    """Pose-invariant size signature ``(4,)``: PCA box extents (descending) and surface area."""
    _, _, (lo, hi) = pca_box(unique_vertices(mesh))
    return np.concatenate([np.sort(hi - lo)[::-1], [float(mesh.area)]])


def accidental_twins(obj: AssembledObject, rel_tol: float = 0.03) -> list[tuple[str, str]]:
    """Pairs of parts in different equivalence groups whose signatures agree within ``rel_tol``.

    Equal signatures are necessary (not sufficient) for two parts to be congruent, so an empty
    result means no two unrelated parts are near-identical.
    """
    group_of = {}
    for g, members in enumerate(obj.equivalence or []):
        for name in members:
            group_of[name] = g
    sigs = [shape_signature(p.mesh) for p in obj.parts]
    out = []
    for i in range(obj.n_parts):
        for j in range(i + 1, obj.n_parts):
            a, b = obj.parts[i].name, obj.parts[j].name
            if a in group_of and group_of.get(a) == group_of.get(b):
                continue
            rel = np.abs(sigs[i] - sigs[j]) / np.maximum(np.maximum(np.abs(sigs[i]), np.abs(sigs[j])), 1e-12)
            if np.all(rel <= rel_tol):
                out.append((a, b))
    return out
