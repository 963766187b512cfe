"""Fitting one fragment's surface onto another's: ICP restricted to the contact, the symmetric
ICP of two planar faces (the compiled kernel of :mod:`aw.kernels.icp`), and the in-plane turn
that lays one planar face's outline on the other's.

Poses here are ``(R (3, 3), t (3,))`` mapping the moving cloud's frame into the fixed one's.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from aw.kernels.icp import ICPProblem
from aw.refine.classical.contact import OPPOSED
from aw.refine.classical.surface import Cloud

__all__ = ["chamfer_rms", "contact_icp", "facing", "inplane_turns", "partial_placements", "plane_axes", "symmetric_icp"]

ICP_ITERATIONS = 30
POINT_WEIGHT = 0.2  # a weak point-to-point term keeps flat stretches from sliding freely
INPLANE_STEP_DEG = 5.0
VOTERS = 120  # outline points of each face that vote in partial_placements


def rotvec_matrix(w: np.ndarray) -> np.ndarray:
    """The rotation ``(3, 3)`` of the rotation vector ``w (3,)`` (Rodrigues)."""
    angle = float(np.linalg.norm(w))
    if angle < 1e-15:
        return np.eye(3)
    k = w / angle
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * cross + (1.0 - np.cos(angle)) * cross @ cross


def _step(p: np.ndarray, q: np.ndarray, m: np.ndarray) -> np.ndarray:
    """The small motion ``(rotation vector, translation) (6,)`` moving ``p (n, 3)`` onto the
    tangent planes ``(q, m)`` (point-to-plane) and, weighted by ``POINT_WEIGHT``, onto ``q``
    (point-to-point): the 6 x 6 normal equations summed directly."""
    w2 = POINT_WEIGHT**2
    n = len(p)
    pm = np.cross(p, m)
    jac = np.hstack([pm, m])
    r_plane = np.einsum("ij,ij->i", q - p, m)
    r_point = q - p
    hess = jac.T @ jac
    grad = jac.T @ r_plane
    sp = p.sum(0)
    skew = np.array([[0.0, -sp[2], sp[1]], [sp[2], 0.0, -sp[0]], [-sp[1], sp[0], 0.0]])
    hess[:3, :3] += w2 * (np.einsum("ij,ij->", p, p) * np.eye(3) - p.T @ p)
    hess[:3, 3:] += w2 * skew
    hess[3:, :3] -= w2 * skew
    hess[3:, 3:] += w2 * n * np.eye(3)
    grad[:3] += w2 * np.cross(p, r_point).sum(0)
    grad[3:] += w2 * r_point.sum(0)
    try:
        return np.linalg.solve(hess, grad)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(hess, grad, rcond=None)[0]


def contact_icp(
    src: Cloud,
    dst: Cloud,
    rot: np.ndarray,
    shift: np.ndarray,
    radius: float,
    floor: float,
    iterations: int = ICP_ITERATIONS,
) -> tuple[np.ndarray, np.ndarray]:
    """Move ``src`` onto ``dst``: point-to-plane with a weak point-to-point term, pairs only
    between opposed normals within a radius that shrinks from ``radius`` to ``floor``."""
    for _ in range(iterations):
        p = src.points @ rot.T + shift
        n = src.normals @ rot.T
        d, found = dst.tree.query(p, distance_upper_bound=radius)
        j = np.asarray(found)  # (k,) rows; a miss is len(dst.points), where d is inf
        ok = np.isfinite(d)
        ok[ok] &= np.einsum("ij,ij->i", n[ok], dst.normals[j[ok]]) < OPPOSED
        if ok.sum() < 12:
            break
        x = _step(p[ok], dst.points[j[ok]], dst.normals[j[ok]])
        step = rotvec_matrix(x[:3])
        rot, shift = step @ rot, step @ shift + x[3:]
        radius = max(floor, 0.7 * radius)
        if np.linalg.norm(x) < 1e-9:
            break
    return rot, shift


def symmetric_icp(
    src: np.ndarray, dst: np.ndarray, rot: np.ndarray, shift: np.ndarray, size: float, iterations: int = ICP_ITERATIONS
) -> tuple[np.ndarray, np.ndarray]:
    """The symmetric point-to-point ICP (every point of both sets paired with its nearest in the
    other) of ``src (k, 3)`` onto ``dst (m, 3)``: on the outlines of two planar faces of the same
    shape it lays one on the other. Coordinates are divided by ``size`` for the kernel."""
    problem = ICPProblem(src / size, dst / size)
    result = problem.run(rot, shift / size, iterations, 1e-12)
    return result.rotation, result.translation * size


def facing(src_normal: np.ndarray, dst_normal: np.ndarray) -> np.ndarray:
    """A rotation ``(3, 3)`` turning ``src_normal`` against ``dst_normal``."""
    return Rotation.align_vectors([-dst_normal], [src_normal])[0].as_matrix()


def plane_axes(normal: np.ndarray) -> np.ndarray:
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    return np.column_stack([u, np.cross(normal, u)])


def inplane_turns(
    src: np.ndarray,
    dst: np.ndarray,
    src_centre: np.ndarray,
    dst_centre: np.ndarray,
    src_normal: np.ndarray,
    dst_normal: np.ndarray,
    keep: int = 2,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Starts ``(R, t)`` laying the planar outline ``src (k, 3)`` on the planar outline ``dst
    (m, 3)``: normals opposed, centres together, and the ``keep`` turns about the normal (of
    every ``INPLANE_STEP_DEG``) whose outlines agree best (2-D chamfer)."""
    face = facing(src_normal, dst_normal)
    axes = plane_axes(dst_normal)
    flat_dst = (dst - dst_centre) @ axes
    tree = cKDTree(flat_dst)
    flat_src = (src - src_centre) @ face.T @ axes
    found = []
    for angle in np.radians(np.arange(0.0, 360.0, INPLANE_STEP_DEG)):
        c, s = np.cos(angle), np.sin(angle)
        moved = flat_src @ np.array([[c, s], [-s, c]])
        there = tree.query(moved)[0]
        back = cKDTree(moved).query(flat_dst)[0]
        found.append((float(np.mean(there**2) + np.mean(back**2)), angle))
    found.sort()
    starts = []
    for _, angle in found[:keep]:
        rot = Rotation.from_rotvec(angle * dst_normal).as_matrix() @ face
        starts.append((rot, dst_centre - rot @ src_centre))
    return starts


def chamfer_rms(src: np.ndarray, dst: np.ndarray) -> float:
    """Root mean square of the nearest-neighbour distances both ways between two point sets."""
    there = cKDTree(dst).query(src)[0]
    back = cKDTree(src).query(dst)[0]
    return float(np.sqrt(0.5 * (np.mean(there**2) + np.mean(back**2))))


def _rot2(angle: float) -> np.ndarray:
    """The 2-D rotation by ``angle`` acting on row vectors (``x @ _rot2(a)``)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, s], [-s, c]])


def _icp_2d(src: np.ndarray, dst: np.ndarray, angle: float, shift: np.ndarray, radius: float, floor: float):
    """Trimmed 2-D ICP of the points ``src (k, 2)`` onto ``dst (m, 2)``: only pairs within a
    radius shrinking from ``radius`` to ``floor``; returns the refined ``(angle, shift (2,))``."""
    tree = cKDTree(dst)
    for _ in range(ICP_ITERATIONS):
        moved = src @ _rot2(angle) + shift
        d, found = tree.query(moved, distance_upper_bound=radius)
        j = np.asarray(found)
        ok = np.isfinite(d)
        if ok.sum() < 6:
            break
        p, q = moved[ok], dst[j[ok]]
        pc, qc = p.mean(0), q.mean(0)
        a, b = p - pc, q - qc
        turn = np.arctan2(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]), np.sum(a * b))
        angle += turn
        shift = (shift - pc) @ _rot2(turn) + qc
        radius = max(floor, 0.7 * radius)
        if abs(turn) < 1e-9:
            break
    return angle, shift


def partial_placements(
    small: np.ndarray,
    big: np.ndarray,
    small_centre: np.ndarray,
    big_centre: np.ndarray,
    small_normal: np.ndarray,
    big_normal: np.ndarray,
    cell: float,
    keep: int = 2,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Placements ``(R, t)`` of a planar face (outline ``small (k, 3)``) on part of a larger
    coplanar face (outline ``big (m, 3)``), normals opposed: where a break of one fragment meets
    the breaks of two others, each holds only part of it, and only part of the smaller outline
    lies on the larger. For every turn of ``INPLANE_STEP_DEG``, each pair of outline points votes
    for the shift that would lay one on the other (bins of ``cell``); the ``keep`` turns with the
    most votes are refined by a trimmed 2-D ICP of the outlines."""
    face = facing(small_normal, big_normal)
    axes = plane_axes(big_normal)
    step = max(1, len(small) // VOTERS), max(1, len(big) // VOTERS)
    flat_small = (small @ face.T @ axes)[:: step[0]]
    flat_big = (big @ axes)[:: step[1]]
    votes = []
    for angle in np.radians(np.arange(0.0, 360.0, INPLANE_STEP_DEG)):
        diff = (flat_big[None, :, :] - (flat_small @ _rot2(angle))[:, None, :]).reshape(-1, 2)
        bins = np.floor(diff / cell).astype(np.int64)
        low = bins.min(0)
        # one integer per bin, in the bins' lexicographic order: a 1-D unique is far cheaper than a 2-D one
        keys = (bins[:, 0] - low[0]) * (bins[:, 1].max() - low[1] + 1) + (bins[:, 1] - low[1])
        found, counts = np.unique(keys, return_counts=True)
        top = int(np.argmax(counts))
        votes.append((int(counts[top]), angle, diff[keys == found[top]].mean(0)))
    votes.sort(key=lambda v: -v[0])
    out = []
    for _, angle, shift in votes[:keep]:
        angle, shift = _icp_2d(flat_small, flat_big, angle, shift, 2 * cell, 0.5 * cell)
        rot = rotvec_matrix(angle * big_normal) @ face
        height = (big_centre - rot @ small_centre) @ big_normal
        out.append((rot, axes @ shift + height * big_normal))
    return out
