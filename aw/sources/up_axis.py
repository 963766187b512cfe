"""Which source axis points up in an assembled object whose files do not say: Z (kept as given)
or Y (turned Z-up with :func:`aw.assembly.y_up_to_z_up`).

The rule (:func:`guess_up_axis`), for furniture-like objects whose upright members (legs, posts,
side panels) are longer than they are wide:

1. A part *stands along* an axis when its axis-aligned extent along it is at least
   :data:`ELONGATION` times each of its other two extents (a leg, a post; not a square top).
2. Y is chosen when at least two parts stand along Y, more than stand along Z, two of them side
   by side (their footprints across Y apart, as legs are; not end to end, as the pieces of a
   broken bar are), and the object rests stably with Y up: the area-weighted centroid of all
   part surfaces projects inside the convex hull of the vertices within :data:`BASE_BAND` of
   the object's height above its lowest point (its base), by at least :data:`STABLE_MARGIN` of
   its width.
3. Otherwise Z, the convention of most mesh formats, is kept.

Limits: objects without elongated parts (plates, boxes, most fragments) or with as many lying
as standing members keep Z whatever their true orientation; a lying object whose long parts lie
side by side along Y (a raft of planks) is stood up; an object whose upright members are
along Y but that does not rest on them (a hanging lamp) keeps Z. X-up and upside-down files are
not detected. The decision is said per object; ``up_axis`` in ``meta.json`` or
``aw-prepare folder --up-axis`` overrides it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import ConvexHull, QhullError

__all__ = [
    "ELONGATION",
    "BASE_BAND",
    "STABLE_MARGIN",
    "UpAxisGuess",
    "guess_up_axis",
    "standing_counts",
    "standing_along",
    "side_by_side",
    "stable_on_base",
]

ELONGATION = 1.5
"""A part stands along an axis when its extent there is at least this many times its others."""

BASE_BAND = 0.02
"""The base: vertices within this fraction of the object's height above its lowest point."""

STABLE_MARGIN = 0.02
"""Stable: the centroid lies this fraction of the object's width inside the base's hull."""

_AXES = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True)
class UpAxisGuess:
    """The axis chosen (``"y"`` or ``"z"``) and why, in words for the user."""

    axis: str
    reason: str


def standing_along(mesh: trimesh.Trimesh) -> str | None:
    """The source axis (``"x"``, ``"y"``, ``"z"``) a part stands along, or None."""
    ext = np.ptp(np.asarray(mesh.vertices, dtype=np.float64), axis=0)
    k = int(np.argmax(ext))
    return "xyz"[k] if np.all(ext[k] >= ELONGATION * np.delete(ext, k)) else None


def standing_counts(meshes: Sequence[trimesh.Trimesh]) -> dict[str, int]:
    """How many parts stand along each source axis (``{"x": n, "y": n, "z": n}``)."""
    counts = {a: 0 for a in _AXES}
    for m in meshes:
        axis = standing_along(m)
        if axis is not None:
            counts[axis] += 1
    return counts


def side_by_side(meshes: Sequence[trimesh.Trimesh], up: str) -> bool:
    """Whether two of the parts standing along ``up`` have footprints across it that do not
    overlap (legs apart), rather than all stacked end to end."""
    ground = [k for k in range(3) if k != _AXES[up]]
    boxes = [
        (m.vertices[:, ground].min(axis=0), m.vertices[:, ground].max(axis=0))
        for m in meshes
        if standing_along(m) == up
    ]
    return any(
        np.any(hi_a < lo_b) or np.any(hi_b < lo_a)
        for i, (lo_a, hi_a) in enumerate(boxes)
        for lo_b, hi_b in boxes[i + 1 :]
    )


def stable_on_base(meshes: Sequence[trimesh.Trimesh], up: str) -> bool:
    """Whether the object rests stably on its lowest points with source axis ``up`` pointing up."""
    u = _AXES[up]
    ground = [k for k in range(3) if k != u]
    v = np.concatenate([np.asarray(m.vertices, dtype=np.float64) for m in meshes])
    tri = np.concatenate([np.asarray(m.triangles, dtype=np.float64) for m in meshes])
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    if not area.sum() > 0:
        return False
    centroid = (tri.mean(axis=1) * area[:, None]).sum(axis=0) / area.sum()
    low, height = v[:, u].min(), np.ptp(v[:, u])
    base = v[v[:, u] <= low + BASE_BAND * height][:, ground]
    width = float(np.ptp(v[:, ground], axis=0).max())
    try:
        hull = ConvexHull(base)
    except (QhullError, ValueError):  # fewer than 3 points or all on a line: no area to rest on
        return False
    # hull.equations: rows (a, b, c) with a*x + b*y + c <= 0 inside; (a, b) unit normals
    inside = -(hull.equations[:, :2] @ centroid[ground] + hull.equations[:, 2]).max()
    return bool(inside >= STABLE_MARGIN * width)


def guess_up_axis(meshes: Sequence[trimesh.Trimesh]) -> UpAxisGuess:
    """The up axis of an assembled object's parts ``meshes`` (source frame) by the module's rule."""
    counts = standing_counts(meshes)
    tally = f"{counts['y']} part{'' if counts['y'] == 1 else 's'} stand{'s' if counts['y'] == 1 else ''} along Y, {counts['z']} along Z"
    if counts["y"] >= 2 and counts["y"] > counts["z"]:
        if not side_by_side(meshes, "y"):
            return UpAxisGuess("z", f"{tally}, but end to end, not side by side; kept Z")
        if stable_on_base(meshes, "y"):
            return UpAxisGuess("y", f"{tally}, and it rests stably on its base with Y up")
        return UpAxisGuess("z", f"{tally}, but it would not rest stably with Y up; kept Z")
    return UpAxisGuess("z", f"{tally}; kept Z")
