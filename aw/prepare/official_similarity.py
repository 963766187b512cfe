"""Equivalence groups as the official preparation resolves them (its default ``geometry`` policy,
``assembly_world_agent/similarity.py`` with ``utils/registration.py`` of
AssemblyWorld/assembly-world-agent).

Each part's cloud is put in its mesh's PCA frame and divided by the scale divisor; every pair
``(i, j)``, ``j < i`` in sorted id order, is registered ``i -> j`` by symmetric ICP from the 24
proper PCA axis mappings; an edge joins them when the best squared Chamfer distance is at most
``1e-4``; the groups are the connected components, ordered by their lowest index.

The groups are found without registering every pair (:func:`aw.pair_search.registration_groups`):
a pair whose proven Chamfer lower bound (:mod:`aw.shape_bounds`, then :mod:`aw.rotation_bound`)
exceeds the threshold cannot be an edge, and a pair already connected cannot change the
components. :func:`geometry_groups_all_pairs`
registers every pair and is kept for the tests.
"""

from __future__ import annotations

from itertools import permutations, product

import numpy as np
from scipy.spatial import cKDTree

from aw.pair_search import registration_groups
from aw.prepare.official_frame import pca_frame

__all__ = ["THRESHOLD", "MAX_ITERATIONS", "IMPROVEMENT_TOLERANCE", "register", "geometry_groups", "geometry_groups_all_pairs"]

THRESHOLD = 1e-4
MAX_ITERATIONS = 100
IMPROVEMENT_TOLERANCE = 1e-9


def _kabsch(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a, b = source.mean(0), target.mean(0)
    u, _, vt = np.linalg.svd((source - a).T @ (target - b))
    flip = np.eye(3)
    flip[-1, -1] = np.linalg.det(vt.T @ u.T)
    rotation = vt.T @ flip @ u.T
    return rotation, b - rotation @ a


def register(moving: np.ndarray, fixed: np.ndarray, enough: float = -np.inf) -> float:
    """Smallest squared Chamfer distance of ``moving (n, 3)`` onto ``fixed (n, 3)`` met by ICP from
    the 24 PCA starts. ``enough``: return as soon as a start reaches it (an edge is then decided)."""
    mc, mb = pca_frame(moving)
    fc, fb = pca_frame(fixed)
    starts = []
    for perm in permutations(range(3)):
        for signs in product((-1, 1), repeat=3):
            axes = np.eye(3)[:, perm] @ np.diag(signs)
            if np.linalg.det(axes) > 0:
                r = fb @ axes @ mb.T
                starts.append((r, fc - r @ mc))
    fixed_tree, moving_tree = cKDTree(fixed), cKDTree(moving)

    def cost(r, t):
        ahead, fwd = fixed_tree.query(moving @ r.T + t)
        back, bwd = moving_tree.query((fixed - t) @ r)
        return float(np.mean(ahead * ahead) + np.mean(back * back)), fwd, bwd

    best = np.inf
    for r, t in starts:
        value, fwd, bwd = cost(r, t)
        lowest = value
        for _ in range(MAX_ITERATIONS):
            r, t = _kabsch(np.concatenate((moving, moving[bwd])), np.concatenate((fixed[fwd], fixed)))
            updated, fwd, bwd = cost(r, t)
            lowest = min(lowest, updated)
            gain, value = value - updated, updated
            if gain < IMPROVEMENT_TOLERANCE:
                break
        best = min(best, lowest)
        if best <= enough:
            break
    return best


def _part_clouds(points: np.ndarray, vertices: list[np.ndarray], divisor: float) -> list[np.ndarray]:
    clouds = []
    for cloud, v in zip(points, vertices):
        center, basis = pca_frame(v)
        clouds.append((cloud - center) @ basis / divisor)
    return clouds


def geometry_groups(part_ids: list[str], points: np.ndarray, vertices: list[np.ndarray], divisor: float,
                    threshold: float = THRESHOLD, show_progress: bool = False,
                    workers: int | None = None) -> list[list[str]]:
    """Groups of interchangeable parts: ``part_ids`` sorted, ``points (P, n, 3)`` and ``vertices``
    (each part's mesh, ``(n_i, 3)``) in the same frame, ``divisor`` the scale divisor.
    ``show_progress``: a progress display when many pairs need registering. ``workers``: pairs
    registered at once, in threads (default :func:`aw.pair_search.local_workers`; the groups do
    not depend on it)."""
    clouds = _part_clouds(points, vertices, divisor)

    def is_edge(j: int, i: int) -> bool:  # the official order: the later part onto the earlier
        return register(clouds[i], clouds[j], enough=threshold) <= threshold

    found = registration_groups(clouds, threshold, is_edge, what=f"geometry groups of {len(part_ids)} parts",
                                show_progress=show_progress, workers=workers)
    return [[part_ids[k] for k in g] for g in found]


def geometry_groups_all_pairs(part_ids: list[str], points: np.ndarray, vertices: list[np.ndarray], divisor: float,
                              threshold: float = THRESHOLD) -> list[list[str]]:
    """:func:`geometry_groups` by registering every pair ``(i, j)``, ``j < i``, in full."""
    clouds = _part_clouds(points, vertices, divisor)
    parent = list(range(len(part_ids)))

    def root(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    for i in range(len(part_ids)):
        for j in range(i):
            if register(clouds[i], clouds[j]) <= threshold:
                a, b = root(i), root(j)
                parent[max(a, b)] = min(a, b)
    members: dict[int, list[str]] = {}
    for i, pid in enumerate(part_ids):
        members.setdefault(root(i), []).append(pid)
    return list(members.values())
