"""How well two fragments meet: the share of their surfaces in contact, and how far one sinks
into the other. Every cloud here is already in one frame (the anchor's).

Two samples are in contact when they face each other (normals opposed: cosine below
``OPPOSED``), lie within ``eps`` of each other, and one lies within ``plane_tol`` of the other's
tangent plane; the tight plane distance tells an exact fit of rough surfaces from a near miss.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aw.refine.classical.surface import Cloud, Fragment

__all__ = [
    "IDENTITY",
    "OPPOSED",
    "Pose",
    "Tolerance",
    "contact_share",
    "coverage",
    "inverse",
    "objective",
    "relative",
    "sunk_share",
    "tolerance",
]

OPPOSED = -0.5
PLANE_FLOOR = 3e-3  # of the size: how far off a partner's tangent plane a sample may lie (noise-free)
SINK_DEPTH = 0.5  # in eps: how deep behind the other's surface a sample must be to count as sunk
SINK_NEIGHBOURS = 6


@dataclass(frozen=True)
class Tolerance:
    """Contact distance ``eps`` and tangent-plane distance ``plane`` (mesh units)."""

    eps: float
    plane: float


def tolerance(a: Fragment, b: Fragment) -> Tolerance:
    """The contact tolerance of two fragments: ``eps`` twice the sample spacing, at least 0.5 % of
    the object's size and four times the two surfaces' noise; ``plane`` 0.3 % of the size or
    three times the noise."""
    noise = float(np.hypot(a.noise, b.noise))
    size = max(a.size, b.size)
    eps = max(2.0 * max(a.spacing, b.spacing), 5e-3 * size, 4.0 * noise)
    return Tolerance(eps, max(PLANE_FLOOR * size, 3.0 * noise))


Pose = tuple[np.ndarray, np.ndarray]  # (R (3, 3), t (3,)): x -> R x + t
IDENTITY: Pose = (np.eye(3), np.zeros(3))


def inverse(move: Pose) -> Pose:
    return move[0].T, -move[0].T @ move[1]


def relative(to: Pose, frm: Pose) -> Pose:
    """The move from the frame placed by ``frm`` into the frame placed by ``to`` (both map a
    local frame into one common frame)."""
    r = to[0].T @ frm[0]
    return r, to[0].T @ (frm[1] - to[1])


def _touching(src: Cloud, dst: Cloud, tol: Tolerance, move: Pose) -> np.ndarray:
    """Mask ``(n,)`` of ``src``'s samples (moved into ``dst``'s frame by ``move``) in contact with ``dst``."""
    points, normals = src.points @ move[0].T + move[1], src.normals @ move[0].T
    d, found = dst.tree.query(points, distance_upper_bound=tol.eps)
    j = np.asarray(found)  # (n,) rows; a miss is len(dst.points), where d is inf
    hit = np.isfinite(d)
    k = j[hit]
    near = dst.points[k]
    hit[hit] = (np.einsum("ij,ij->i", normals[hit], dst.normals[k]) < OPPOSED) & (
        np.abs(np.einsum("ij,ij->i", points[hit] - near, dst.normals[k])) < tol.plane
    )
    return hit


def contact_share(src: Cloud, dst: Cloud, tol: Tolerance, move: Pose = IDENTITY) -> float:
    """Share of ``src``'s samples (moved into ``dst``'s frame by ``move``) in contact with ``dst``."""
    return float(_touching(src, dst, tol, move).mean())


def coverage(a: Cloud, b: Cloud, tol: Tolerance, move: Pose = IDENTITY) -> float:
    """The smaller of the two shares in contact (``b`` moved into ``a``'s frame by ``move``):
    high only when both surfaces meet all over."""
    return min(contact_share(a, b, tol, inverse(move)), contact_share(b, a, tol, move))


def sunk_share(src: Cloud, dst: Cloud, tol: Tolerance, move: Pose = IDENTITY) -> float:
    """Share of ``src``'s samples (moved into ``dst``'s frame by ``move``) inside ``dst``:
    behind the tangent plane of each of their ``SINK_NEIGHBOURS`` nearest samples of ``dst`` by
    more than ``SINK_DEPTH * eps`` (one nearest sample is not enough: beside an edge a point
    outside is behind one of the faces)."""
    points = src.points @ move[0].T + move[1]
    _, j = dst.tree.query(points, k=SINK_NEIGHBOURS)
    depth = np.einsum("nkj,nkj->nk", points[:, None, :] - dst.points[j], dst.normals[j])
    return float(np.mean(np.all(depth < -SINK_DEPTH * tol.eps, axis=1)))


def objective(fragments: list[Fragment], poses: list[Pose], tols: dict[tuple[int, int], Tolerance]) -> float:
    """The assembly's fracture objective: over every pair of fragments, the smaller of the two
    areas in contact less twice the areas sunk into each other, over half the total area.
    ``poses``: each fragment's mesh frame into one common frame."""
    total = 0.0
    for i in range(len(fragments)):
        for j in range(i + 1, len(fragments)):
            tol = tols[(i, j)]
            bi, bj = fragments[i].body, fragments[j].body
            i_to_j, j_to_i = relative(poses[j], poses[i]), relative(poses[i], poses[j])
            ai, aj = fragments[i].mesh.area, fragments[j].mesh.area
            touching = min(contact_share(bi, bj, tol, i_to_j) * ai, contact_share(bj, bi, tol, j_to_i) * aj)
            sunk = sunk_share(bi, bj, tol, i_to_j) * ai + sunk_share(bj, bi, tol, j_to_i) * aj
            total += touching - 2.0 * sunk
    return total / (0.5 * sum(f.mesh.area for f in fragments))
