"""Boolean-free mesh primitives for the procedural benchmark (all closed, deterministic).

Every function returns a new :class:`trimesh.Trimesh` in source units (metres, Z up). Profiles
are 2-D ``(k, 2)`` arrays in counter-clockwise order.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import trimesh

from aw.pose import rotation_about_axis

__all__ = [
    "box",
    "cylinder",
    "tube",
    "revolved",
    "prism",
    "ring_prism",
    "gear_profile",
    "polygon_profile",
    "circle_profile",
    "merge",
    "placed",
]


def placed(mesh: trimesh.Trimesh, at=(0.0, 0.0, 0.0), rot: np.ndarray | None = None) -> trimesh.Trimesh:
    """A copy of ``mesh`` rotated by ``rot (3, 3)`` about the origin, then moved to ``at``."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    if rot is not None:
        v = v @ np.asarray(rot, dtype=np.float64).T
    return trimesh.Trimesh(v + np.asarray(at, dtype=np.float64), np.asarray(mesh.faces), process=False)


def _axis_rot(axis: str) -> np.ndarray | None:
    """Rotation taking +Z onto ``axis`` ('x', 'y' or 'z')."""
    if axis == "z":
        return None
    if axis == "x":
        return rotation_about_axis(1, np.pi / 2)
    if axis == "y":
        return rotation_about_axis(0, -np.pi / 2)
    raise ValueError(f"axis must be x, y or z, got {axis!r}")


def box(size: Sequence[float], at=(0.0, 0.0, 0.0)) -> trimesh.Trimesh:
    """Axis-aligned box of ``size (3,)`` centred at ``at``."""
    return placed(trimesh.creation.box(extents=np.asarray(size, dtype=np.float64)), at)


def cylinder(radius: float, length: float, at=(0.0, 0.0, 0.0), axis: str = "z", sections: int = 24) -> trimesh.Trimesh:
    """Solid cylinder centred at ``at`` along ``axis``."""
    return placed(trimesh.creation.cylinder(radius=radius, height=length, sections=sections), at, _axis_rot(axis))


def tube(
    r_in: float, r_out: float, length: float, at=(0.0, 0.0, 0.0), axis: str = "z", sections: int = 32
) -> trimesh.Trimesh:
    """Hollow cylinder (ring) centred at ``at`` along ``axis``."""
    return ring_prism(circle_profile(r_out, sections), circle_profile(r_in, sections), length, at=at, axis=axis)


def revolved(
    profile: Sequence[Sequence[float]], at=(0.0, 0.0, 0.0), axis: str = "z", sections: int = 32
) -> trimesh.Trimesh:
    """Solid of revolution about ``axis`` of a ``(radius, height)`` polyline from the axis to the axis."""
    prof = np.asarray(profile, dtype=np.float64)
    if prof[0, 0] != 0 or prof[-1, 0] != 0:
        raise ValueError("a revolved profile must start and end on the axis (radius 0)")
    return placed(trimesh.creation.revolve(prof, sections=sections), at, _axis_rot(axis))


def circle_profile(radius: float, k: int = 32, phase: float = 0.0) -> np.ndarray:
    """``(k, 2)`` counter-clockwise polygon approximating a circle."""
    a = phase + 2 * np.pi * np.arange(k) / k
    return radius * np.stack([np.cos(a), np.sin(a)], axis=1)


def polygon_profile(radius: float, sides: int, k: int | None = None, phase: float = 0.0) -> np.ndarray:
    """Regular polygon (circumradius ``radius``) resampled at ``k`` equally spaced angles.

    Sampling at the same angles as :func:`circle_profile` lets it pair with a circular hole.
    """
    k = k or sides
    a = phase + 2 * np.pi * np.arange(k) / k
    sector = 2 * np.pi / sides
    local = (a - phase) % sector - sector / 2
    r = radius * np.cos(sector / 2) / np.cos(local)
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def gear_profile(r_root: float, r_tip: float, teeth: int, per_tooth: int = 8) -> np.ndarray:
    """Toothed outline ``(teeth * per_tooth, 2)``: trapezoidal teeth between root and tip radii."""
    k = teeth * per_tooth
    a = 2 * np.pi * np.arange(k) / k
    phase = (np.arange(k) % per_tooth) / per_tooth  # position inside one tooth period
    # flank up over [0.125, 0.25), tip over [0.25, 0.5), flank down over [0.5, 0.625), root otherwise
    r = np.full(k, r_root)
    r[(phase >= 0.25) & (phase < 0.5)] = r_tip
    r[phase == 0.125] = 0.5 * (r_root + r_tip)
    r[phase == 0.5] = 0.5 * (r_root + r_tip)
    r[phase == 0.625] = r_root
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def prism(profile: np.ndarray, length: float, at=(0.0, 0.0, 0.0), axis: str = "z", centre=None) -> trimesh.Trimesh:
    """Extrusion along ``axis`` of a polygon star-shaped about ``centre``, centred on ``at``.

    Caps are fans around ``centre`` (default: the vertex mean, right for convex outlines; pass a
    point of the kernel for other star-shaped ones, e.g. the corner of an L).
    """
    prof = np.asarray(profile, dtype=np.float64)
    k = len(prof)
    centre = prof.mean(axis=0) if centre is None else np.asarray(centre, dtype=np.float64)
    h = 0.5 * length
    verts = np.concatenate(
        [
            np.column_stack([prof, np.full(k, -h)]),
            np.column_stack([prof, np.full(k, h)]),
            [[centre[0], centre[1], -h], [centre[0], centre[1], h]],
        ]
    )
    i = np.arange(k)
    j = (i + 1) % k
    cb, ct = 2 * k, 2 * k + 1
    faces = np.concatenate(
        [
            np.stack([i, j, j + k], axis=1),
            np.stack([i, j + k, i + k], axis=1),
            np.stack([np.full(k, cb), j, i], axis=1),
            np.stack([np.full(k, ct), i + k, j + k], axis=1),
        ]
    )
    return _oriented(placed(trimesh.Trimesh(verts, faces, process=False), at, _axis_rot(axis)))


def ring_prism(
    outer: np.ndarray, inner: np.ndarray, length: float, at=(0.0, 0.0, 0.0), axis: str = "z"
) -> trimesh.Trimesh:
    """Extrusion of the region between two loops sampled at the same angles (a ring with a bore)."""
    outer = np.asarray(outer, dtype=np.float64)
    inner = np.asarray(inner, dtype=np.float64)
    if outer.shape != inner.shape:
        raise ValueError("outer and inner loops need the same number of vertices")
    k = len(outer)
    h = 0.5 * length
    # vertex blocks: outer bottom, outer top, inner bottom, inner top
    verts = np.concatenate(
        [
            np.column_stack([outer, np.full(k, -h)]),
            np.column_stack([outer, np.full(k, h)]),
            np.column_stack([inner, np.full(k, -h)]),
            np.column_stack([inner, np.full(k, h)]),
        ]
    )
    i = np.arange(k)
    j = (i + 1) % k
    ob, ot, ib, it = 0, k, 2 * k, 3 * k
    faces = np.concatenate(
        [
            np.stack([ob + i, ob + j, ot + j], axis=1),  # outer wall
            np.stack([ob + i, ot + j, ot + i], axis=1),
            np.stack([ib + i, it + j, ib + j], axis=1),  # inner wall
            np.stack([ib + i, it + i, it + j], axis=1),
            np.stack([ot + i, ot + j, it + j], axis=1),  # top annulus
            np.stack([ot + i, it + j, it + i], axis=1),
            np.stack([ob + i, ib + j, ob + j], axis=1),  # bottom annulus
            np.stack([ob + i, ib + i, ib + j], axis=1),
        ]
    )
    return _oriented(placed(trimesh.Trimesh(verts, faces, process=False), at, _axis_rot(axis)))


def _oriented(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Flip all faces if the mesh is inside out (negative volume)."""
    if mesh.volume < 0:
        mesh = trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)[:, ::-1], process=False)
    return mesh


def merge(meshes: Sequence[trimesh.Trimesh]) -> trimesh.Trimesh:
    """One part made of several closed pieces (concatenated, not fused)."""
    verts, faces, offset = [], [], 0
    for m in meshes:
        verts.append(np.asarray(m.vertices, dtype=np.float64))
        faces.append(np.asarray(m.faces, dtype=np.int64) + offset)
        offset += len(m.vertices)
    return trimesh.Trimesh(np.concatenate(verts), np.concatenate(faces), process=False)
