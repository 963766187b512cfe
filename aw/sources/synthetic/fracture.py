"""Two-fragment fractures: a prism solid broken along a rough, tilted, capped surface.

The solid is the extrusion along Z of a star-shaped cross-section ``r(theta)``, meshed on a
polar grid (a centre vertex and ``rings`` rings of ``sectors`` vertices). The fracture surface
is a height field ``z = h(x, y)`` over the same grid: a tilted plane plus a sum of random
sinusoids (the roughness), kept inside the solid. The lower fragment is the bottom cap, the
side wall up to the surface and the surface; the upper fragment is the surface (reversed), the
side wall above it and the top cap. Both are closed, consistently oriented meshes, and they
share the fracture surface vertex for vertex: their complementary geometry is exact.
"""

from __future__ import annotations

import numpy as np
import trimesh

from aw.pose import rotation_about_axis
from aw.sources.synthetic.builder import Builder
from aw.sources.synthetic.prims import placed

__all__ = ["CATEGORIES", "fracture", "polar_grid_faces"]

CATEGORIES = ("cylinder", "bar", "hex_prism", "stone", "tile")


def _radius_fn(category: str, rng: np.random.Generator):
    """Cross-section radius as a function of angle, and the extrusion height (metres)."""
    if category == "cylinder":
        r = rng.uniform(0.03, 0.06)
        return (lambda a: np.full_like(a, r)), rng.uniform(0.08, 0.16)
    if category == "bar":
        hx, hy = rng.uniform(0.015, 0.03), rng.uniform(0.03, 0.05)
        return (
            lambda a: np.minimum(hx / np.maximum(np.abs(np.cos(a)), 1e-9), hy / np.maximum(np.abs(np.sin(a)), 1e-9))
        ), rng.uniform(0.12, 0.2)
    if category == "hex_prism":
        r = rng.uniform(0.03, 0.05)
        sector = np.pi / 3
        return (lambda a: r * np.cos(sector / 2) / np.cos((a % sector) - sector / 2)), rng.uniform(0.06, 0.12)
    if category == "stone":
        r = rng.uniform(0.03, 0.05)
        amps = rng.uniform(0.04, 0.12, size=3)
        phases = rng.uniform(0, 2 * np.pi, size=3)
        return (
            lambda a: (
                r
                * (
                    1
                    + sum(amp * np.cos((k + 2) * a + ph) for k, (amp, ph) in enumerate(zip(amps, phases, strict=True)))
                )
            )
        ), rng.uniform(0.05, 0.1)
    if category == "tile":
        hx, hy = rng.uniform(0.04, 0.07), rng.uniform(0.006, 0.01)
        return (
            lambda a: np.minimum(hx / np.maximum(np.abs(np.cos(a)), 1e-9), hy / np.maximum(np.abs(np.sin(a)), 1e-9))
        ), rng.uniform(0.08, 0.14)
    raise ValueError(f"unknown fracture category {category!r}")


def polar_grid_faces(rings: int, sectors: int, up: bool) -> np.ndarray:
    """Triangles of a polar grid: vertex 0 is the centre, ring ``j`` (1-based) vertex ``k`` is
    ``1 + (j - 1) * sectors + k``. ``up``: counter-clockwise seen from +Z."""
    k = np.arange(sectors)
    k1 = (k + 1) % sectors
    faces = [np.stack([np.zeros(sectors, dtype=np.int64), 1 + k, 1 + k1], axis=1)]
    for j in range(1, rings):
        a = 1 + (j - 1) * sectors
        b = 1 + j * sectors
        faces.append(np.stack([a + k, b + k, b + k1], axis=1))
        faces.append(np.stack([a + k, b + k1, a + k1], axis=1))
    f = np.concatenate(faces)
    return f if up else f[:, ::-1]


def _wall(lo_ring: np.ndarray, hi_ring: np.ndarray, sectors: int) -> np.ndarray:
    """Outward side wall between two rings of vertex indices (counter-clockwise order)."""
    k = np.arange(sectors)
    k1 = (k + 1) % sectors
    return np.concatenate(
        [
            np.stack([lo_ring[k], lo_ring[k1], hi_ring[k1]], axis=1),
            np.stack([lo_ring[k], hi_ring[k1], hi_ring[k]], axis=1),
        ]
    )


def fracture(b: Builder, category: str, rng: np.random.Generator, rings: int = 10, sectors: int = 48) -> None:
    """Two fragments of a ``category`` solid, added to ``b`` as ``fragment_a`` (lower) and ``fragment_b``."""
    radius, height = _radius_fn(category, rng)
    ang = 2 * np.pi * np.arange(sectors) / sectors
    r_out = radius(ang)
    rho = np.arange(1, rings + 1) / rings
    xy = np.concatenate(
        [
            np.zeros((1, 2)),
            np.concatenate([np.stack([p * r_out * np.cos(ang), p * r_out * np.sin(ang)], axis=1) for p in rho]),
        ]
    )

    # fracture height field: tilted plane + rough sinusoids, clipped inside the solid
    scale = float(r_out.max())
    tilt = rng.normal(size=2) * 0.25 * height / scale
    z = height * rng.uniform(0.35, 0.65) + xy @ tilt
    amp = 0.06 * height
    for _ in range(6):
        freq = rng.normal(size=2) * rng.uniform(1.5, 4.0) / scale
        z = z + amp * rng.uniform(0.3, 1.0) * np.sin(xy @ freq + rng.uniform(0, 2 * np.pi))
        amp *= 0.7
    z = np.clip(z, 0.12 * height, 0.88 * height)

    nv = len(xy)
    outer = 1 + (rings - 1) * sectors + np.arange(sectors)
    # lower fragment: bottom grid (0..nv-1), fracture grid (nv..2nv-1)
    v_a = np.concatenate([np.column_stack([xy, np.zeros(nv)]), np.column_stack([xy, z])])
    f_a = np.concatenate(
        [
            polar_grid_faces(rings, sectors, up=False),
            polar_grid_faces(rings, sectors, up=True) + nv,
            _wall(outer, outer + nv, sectors),
        ]
    )
    # upper fragment: fracture grid (0..nv-1), top grid (nv..2nv-1)
    v_b = np.concatenate([np.column_stack([xy, z]), np.column_stack([xy, np.full(nv, height)])])
    f_b = np.concatenate(
        [
            polar_grid_faces(rings, sectors, up=False),
            polar_grid_faces(rings, sectors, up=True) + nv,
            _wall(outer, outer + nv, sectors),
        ]
    )

    rot = rotation_about_axis(2, rng.uniform(-np.pi, np.pi))
    if category in ("bar", "tile") and rng.uniform() < 0.5:
        rot = rotation_about_axis(0, np.pi / 2) @ rot  # lying down
    a = placed(trimesh.Trimesh(v_a, f_a, process=False), (0, 0, 0), rot)
    c = placed(trimesh.Trimesh(v_b, f_b, process=False), (0, 0, 0), rot)
    b.add("fragment_a", a, step="fragments")
    b.add("fragment_b", c, step="fragments")
