"""Broken solids for the refiners' benchmark families: planar cuts, noisy and eroded surfaces,
objects of several pieces.

A solid (:func:`solid`: a deformed blob, a vase, a chamfered brick, a tapered rod, a flat lens)
is cut by a cutter, a large closed body whose top is a plane or a rough height field, with
manifold3d's exact booleans (``Manifold.split``): the two sides share the cut surface vertex for
vertex. Several cuts, each through the largest piece so far, make several pieces. The variants
work on the pieces afterwards, each piece on its own, so that the two sides of a break no longer
match exactly:

- ``noisy``: every surface subdivided to about 1.5 % of the object's size, then each vertex moved
  along its normal by Gaussian noise of 0.25 % of the size (a scan's noise);
- ``eroded``: small chips (spheres of 4-7 % of the size centred on the rim of a cut) taken out of
  one side only, then the rims rounded (the vertices within 3 % of the size of a rim smoothed).

Sizes are in metres, like the other blocks.
"""

from __future__ import annotations

from dataclasses import dataclass

import manifold3d as m3
import numpy as np
import trimesh
from scipy.spatial import cKDTree

__all__ = ["CUT_SHAPES", "Piece", "cut_pieces", "erode", "make_noisy", "rotation_to", "shared_faces", "solid"]

CUT_SHAPES = ("blob", "vase", "brick", "rod", "lens")
MIN_SHARE = 0.12  # of the solid's volume: the smallest piece a cut may leave
EDGE = 0.04  # of the size: the longest edge after subdividing (noisy and eroded variants)
NOISE = 0.0025  # of the size: the scan noise's standard deviation


def rotation_to(normal: np.ndarray) -> np.ndarray:
    """A rotation ``(3, 3)`` taking +Z onto the unit vector ``normal``."""
    z = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def _blob(rng: np.random.Generator, subdivisions: int, scales: np.ndarray) -> trimesh.Trimesh:
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    v = np.asarray(sphere.vertices)
    r = np.ones(len(v))
    for _ in range(4):  # low-frequency bumps: a pebble, not a ball
        d = rng.normal(size=3)
        r += rng.uniform(0.04, 0.12) * np.cos(
            rng.uniform(1.5, 3.0) * (v @ (d / np.linalg.norm(d))) + rng.uniform(0, 6.3)
        )
    return trimesh.Trimesh(v * r[:, None] * scales, sphere.faces, process=False)


def solid(shape: str, rng: np.random.Generator, dense: bool) -> trimesh.Trimesh:
    """A closed ``shape`` solid about the origin, 8-16 cm across; ``dense``: thousands of faces
    (each face under about 1.5 % of the size across), else tens to hundreds."""
    size = rng.uniform(0.08, 0.16)
    if shape == "blob":
        mesh = _blob(
            rng, 4 if dense else 1, 0.5 * size * np.array([1.0, rng.uniform(0.65, 0.9), rng.uniform(0.5, 0.8)])
        )
    elif shape == "lens":  # flat: a cut through its thickness leaves cut faces as large as the rest
        mesh = _blob(
            rng, 4 if dense else 2, 0.5 * size * np.array([1.0, rng.uniform(0.7, 0.9), rng.uniform(0.16, 0.24)])
        )
    elif shape == "vase":
        n = 24 if dense else 5
        z = np.linspace(0.0, size, n)
        radius = 0.25 * size * (1 + 0.35 * np.sin(rng.uniform(1.0, 2.5) * np.pi * z / size + rng.uniform(0, 6.3)))
        profile = np.vstack([[0.0, 0.0], np.column_stack([radius, z]), [0.0, size]])
        mesh = trimesh.creation.revolve(profile, sections=64 if dense else 9)
    elif shape == "brick":  # a box with some corners chamfered off (so that no two faces are alike)
        ext = size * np.array([1.0, rng.uniform(0.45, 0.75), rng.uniform(0.3, 0.55)])
        corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
        points = []
        for c in corners:
            if rng.uniform() < 0.5:
                cut = rng.uniform(0.15, 0.35, size=3)
                points += [c * ext / 2 - np.eye(3)[k] * c[k] * cut[k] * ext[k] for k in range(3)]
            else:
                points.append(c * ext / 2)
        mesh = trimesh.Trimesh(np.array(points)).convex_hull
    elif shape == "rod":  # long and tapered: a cut across it leaves a small cut face
        sides = int(rng.integers(5, 8))
        angles = np.sort(rng.uniform(0, 2 * np.pi, sides))
        radii = 0.09 * size * rng.uniform(0.8, 1.2, sides)
        ring = np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])
        rings = 12 if dense else 2
        z = np.linspace(-size / 2, size / 2, rings)
        taper = np.linspace(1.0, rng.uniform(0.5, 0.7), rings)
        mesh = trimesh.Trimesh(
            np.vstack([np.column_stack([ring * s, np.full(sides, h)]) for s, h in zip(taper, z, strict=True)])
        )
        mesh = mesh.convex_hull
    else:
        raise ValueError(f"unknown solid {shape!r}; choose from {', '.join(CUT_SHAPES)}")
    mesh = trimesh.Trimesh(mesh.vertices - mesh.center_mass, mesh.faces, process=True)
    if dense and len(mesh.faces) < 2000:  # flat-sided solids: split their faces finely
        man = _manifold(mesh).refine_to_length(0.03 * size)
        mesh = _trimesh(man.to_mesh())
    return mesh


def _manifold(mesh: trimesh.Trimesh) -> m3.Manifold:
    """``mesh`` as a manifold whose triangles remember their index in ``mesh`` (``face_id``)."""
    out = m3.Manifold(
        m3.Mesh(
            vert_properties=np.asarray(mesh.vertices, dtype=np.float32),
            tri_verts=np.asarray(mesh.faces, dtype=np.uint32),
            face_id=np.arange(len(mesh.faces), dtype=np.uint32),
        )
    ).as_original()
    if out.status() != m3.Error.NoError:
        raise ValueError(f"not a closed manifold solid ({out.status()})")
    return out


def _trimesh(mesh: m3.Mesh) -> trimesh.Trimesh:
    return trimesh.Trimesh(
        np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3], np.asarray(mesh.tri_verts), process=False
    )


def _origins(mesh: m3.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Per triangle of a boolean's result: ``(original manifold id (f,), index of the triangle it
    came from in that original (f,))``."""
    runs = np.asarray(mesh.run_index) // 3
    ids = np.repeat(np.asarray(mesh.run_original_id), np.diff(runs))
    return ids, np.asarray(mesh.face_id)


def _cutter(rng: np.random.Generator, size: float, rough: bool) -> trimesh.Trimesh:
    """A closed body under ``z = h(x, y)`` (``h`` zero, or rough: sinusoids like the rough
    breaks' of :mod:`aw.sources.synthetic.fracture`), spanning 4 sizes each way and 2 deep."""
    n = 48 if rough else 2
    half = 2.0 * size
    xs = np.linspace(-half, half, n)
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    z = np.zeros(len(xy))
    if rough:
        amp = 0.05 * size
        for _ in range(6):
            freq = rng.normal(size=2) * rng.uniform(3.0, 8.0) / size
            z += amp * rng.uniform(0.3, 1.0) * np.sin(xy @ freq + rng.uniform(0, 2 * np.pi))
            amp *= 0.7
    top = np.column_stack([xy, z])
    bottom = np.column_stack([xy, np.full(len(xy), -2.0 * size)])
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = [np.column_stack([a, b, c]), np.column_stack([a, c, d])]  # top, counter-clockwise from +Z
    faces += [np.column_stack([a, c, b]) + n * n, np.column_stack([a, d, c]) + n * n]  # bottom, reversed
    rim = np.concatenate([idx[:, 0], idx[-1, 1:], idx[-2::-1, -1], idx[0, -2:0:-1]])  # a loop round the edge
    r0, r1 = rim, np.roll(rim, -1)
    faces += [np.column_stack([r0, r1 + n * n, r1]), np.column_stack([r0, r0 + n * n, r1 + n * n])]
    body = trimesh.Trimesh(np.vstack([top, bottom]), np.vstack(faces), process=False)
    if body.volume < 0:
        body.invert()
    return body


@dataclass
class Piece:
    """A solid and which of its faces lie on a break: ``broken (f,)``."""

    mesh: trimesh.Trimesh
    broken: np.ndarray


def _cut(piece: Piece, rng: np.random.Generator, size: float, rough: bool, normal: np.ndarray, share: float):
    """``piece`` cut in two near its centre of mass (moved by ``share`` of the size along
    ``normal``); ``None`` when a side is not one solid."""
    cutter = _cutter(rng, size, rough)
    rot = rotation_to(normal)
    at = piece.mesh.center_mass + share * size * rot[:, 2]
    cutter = _manifold(trimesh.Trimesh(cutter.vertices @ rot.T + at, cutter.faces, process=False))
    solid_ = _manifold(piece.mesh)
    sides = []
    for man in solid_.split(cutter):
        if len(man.decompose()) != 1:
            return None
        mesh = man.to_mesh()
        ids, faces = _origins(mesh)
        from_cutter = ids == cutter.original_id()
        broken = from_cutter | (~from_cutter & piece.broken[np.where(from_cutter, 0, faces)])
        sides.append(Piece(_trimesh(mesh), broken))
    return sides


def cut_pieces(
    whole: trimesh.Trimesh,
    rng: np.random.Generator,
    n_pieces: int,
    rough: bool | list[bool],
    tilt_deg: float = 90.0,
    axis: np.ndarray | None = None,
    offset: float = 0.15,
) -> list[Piece]:
    """``whole`` cut into ``n_pieces`` solids, each cut through the largest piece so far.
    ``rough``: per cut (or for all) whether the cutter is rough; a cut's normal lies within
    ``tilt_deg`` of ``axis`` (default: any direction), its plane within ``offset`` of the size of
    the piece's centre of mass. Raises ``ValueError`` when no draw cuts well (20 tries a cut)."""
    size = float(np.ptp(whole.vertices, axis=0).max())
    volume = whole.volume
    pieces = [Piece(whole, np.zeros(len(whole.faces), dtype=bool))]
    roughs = [rough] * (n_pieces - 1) if isinstance(rough, bool) else list(rough)
    for k in range(n_pieces - 1):
        target = max(range(len(pieces)), key=lambda i: pieces[i].mesh.volume)
        for _ in range(20):
            if axis is None:
                normal = rng.normal(size=3)
            else:  # within tilt_deg of axis, turned about it at random
                tilt = np.radians(rng.uniform(0, tilt_deg))
                normal = _about(axis, rng.uniform(0, 2 * np.pi)) @ rotation_to(axis) @ [np.sin(tilt), 0.0, np.cos(tilt)]
            normal /= np.linalg.norm(normal)
            sides = _cut(pieces[target], rng, size, roughs[k], normal, rng.uniform(-offset, offset))
            if sides is not None and min(s.mesh.volume for s in sides) >= MIN_SHARE * volume:
                pieces[target : target + 1] = sides
                break
        else:
            raise ValueError(f"no cut of piece {target} left two solids of at least {MIN_SHARE:.0%} of the volume")
    return pieces


def _about(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation ``(3, 3)`` by ``angle`` about the unit vector ``axis``."""
    a = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def shared_faces(meshes: list[trimesh.Trimesh]) -> list[Piece]:
    """Pieces whose breaks share their vertices exactly (the rough breaks of
    :mod:`aw.sources.synthetic.fracture`): a face is on a break when each of its corners is a
    vertex of another piece too."""
    size = float(np.ptp(np.vstack([m.vertices for m in meshes]), axis=0).max())
    out = []
    for i, mesh in enumerate(meshes):
        others = np.vstack([m.vertices for j, m in enumerate(meshes) if j != i])
        shared = np.asarray(cKDTree(others).query(mesh.vertices)[0]) < 1e-9 * size
        out.append(Piece(mesh, shared[np.asarray(mesh.faces)].all(axis=1)))
    return out


def make_noisy(piece: Piece, rng: np.random.Generator, size: float, sigma: float = NOISE) -> trimesh.Trimesh:
    """``piece`` subdivided to edges under ``EDGE`` of ``size``, each vertex moved along its
    normal by Gaussian noise of ``sigma * size``."""
    mesh = _subdivided(piece.mesh, size)
    moved = mesh.vertices + mesh.vertex_normals * rng.normal(0.0, sigma * size, size=(len(mesh.vertices), 1))
    return trimesh.Trimesh(moved, mesh.faces, process=False)


def _subdivided(mesh: trimesh.Trimesh, size: float) -> trimesh.Trimesh:
    v, f = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=EDGE * size, max_iter=12)
    return trimesh.Trimesh(v, f, process=True)


def _rim(piece: Piece) -> np.ndarray:
    """Vertices ``(k, 3)`` on the edges between a piece's broken and unbroken faces."""
    adj = piece.mesh.face_adjacency
    across = piece.broken[adj[:, 0]] != piece.broken[adj[:, 1]]
    return piece.mesh.vertices[np.unique(piece.mesh.face_adjacency_edges[across])]


def erode(pieces: list[Piece], rng: np.random.Generator, size: float, chips: int = 3) -> list[trimesh.Trimesh]:
    """``pieces`` with ``chips`` spheres (radius 4-7 % of ``size``, centred on rims) taken out of
    one piece each, then every piece subdivided and its rims rounded (the vertices within 3 % of
    ``size`` of a rim smoothed)."""
    rims = [_rim(p) for p in pieces]
    out = [p.mesh for p in pieces]
    for _ in range(chips):
        k = int(rng.integers(len(out)))
        if not len(rims[k]):
            continue
        ball = trimesh.creation.icosphere(subdivisions=2, radius=rng.uniform(0.04, 0.07) * size)
        ball.vertices += rims[k][rng.integers(len(rims[k]))]
        parts = (_manifold(out[k]) - _manifold(ball)).decompose()
        if parts:  # a chip can cut off a sliver: keep the piece's body
            out[k] = _trimesh(max(parts, key=lambda m: m.volume()).to_mesh())
    rounded = []
    for mesh, rim in zip(out, rims, strict=True):
        mesh = _subdivided(mesh, size)
        if len(rim):
            near = np.asarray(cKDTree(rim).query(mesh.vertices)[0]) < 0.03 * size
            smooth = mesh.copy()
            trimesh.smoothing.filter_taubin(smooth, iterations=10)
            mesh = trimesh.Trimesh(np.where(near[:, None], smooth.vertices, mesh.vertices), mesh.faces, process=False)
        rounded.append(mesh)
    return rounded
