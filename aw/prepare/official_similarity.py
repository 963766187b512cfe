"""Equivalence groups as the official preparation resolves them (its default ``geometry`` policy,
``assembly_world_agent/similarity.py`` with ``utils/registration.py`` of
AssemblyWorld/assembly-world-agent).

Each part's cloud is put in its mesh's PCA frame and divided by the scale divisor; every pair
``(i, j)``, ``j < i`` in sorted id order, is registered ``i -> j`` by symmetric ICP from the 24
proper PCA axis mappings; an edge joins them when the best squared Chamfer distance is at most
``1e-4``; the groups are the connected components, ordered by their lowest index.

The official ICP is the protocol's iteration (both directions' nearest neighbours, one proper
Kabsch fit of all pairs, at most 100 fits, stop when the objective improves by less than
``1e-9``, keep the best), so it runs here in the evaluator's compiled kernel
(:class:`aw.kernels.icp.ICPProblem`, exact neighbours) from the official starts: the same
numbers up to summation order (tested against a NumPy transcription of the official code).

The groups are found without registering every pair (:func:`aw.pair_search.registration_groups`):
a pair whose proven Chamfer lower bound (:mod:`aw.shape_bounds`, then :mod:`aw.rotation_bound`)
exceeds the threshold cannot be an edge, and a pair already connected cannot change the
components. :func:`geometry_groups_all_pairs`
registers every pair and is kept for the tests.
"""

from __future__ import annotations

from itertools import permutations, product

import numpy as np

from aw.kernels.icp import ICPProblem, build_tree, graph_for
from aw.pair_search import registration_groups
from aw.prepare.official_frame import pca_frame

__all__ = [
    "THRESHOLD",
    "MAX_ITERATIONS",
    "IMPROVEMENT_TOLERANCE",
    "official_starts",
    "register",
    "search_structures",
    "geometry_groups",
    "geometry_groups_all_pairs",
]

THRESHOLD = 1e-4
MAX_ITERATIONS = 100
IMPROVEMENT_TOLERANCE = 1e-9


def official_starts(moving: np.ndarray, fixed: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The 24 starts ``(R (3, 3), t (3,))`` of ``moving (n, 3)`` onto ``fixed (m, 3)``: each proper
    mapping of ``moving``'s PCA axes onto ``fixed``'s (axis permutations, then signs), centre onto
    centre."""
    mc, mb = pca_frame(moving)
    fc, fb = pca_frame(fixed)
    starts = []
    for perm in permutations(range(3)):
        for signs in product((-1, 1), repeat=3):
            axes = np.eye(3)[:, perm] @ np.diag(signs)
            if np.linalg.det(axes) > 0:
                r = fb @ axes @ mb.T
                starts.append((r, fc - r @ mc))
    return starts


def register(moving: np.ndarray, fixed: np.ndarray, enough: float = -np.inf, structures: tuple | None = None) -> float:
    """Smallest squared Chamfer distance of ``moving (n, 3)`` onto ``fixed (n, 3)`` met by ICP from
    the 24 PCA starts. ``enough``: return as soon as a registration reaches it (an edge is then
    decided). ``structures``: ``(tree, graph)`` of ``moving`` and of ``fixed``
    (:func:`search_structures`), built here when not given."""
    (tree_m, graph_m), (tree_f, graph_f) = structures or (search_structures(moving), search_structures(fixed))
    problem = ICPProblem(moving, fixed, tree_t=tree_f, tree_p=tree_m, graph_t=graph_f, graph_p=graph_m)
    stop = None if enough == -np.inf else float(enough)
    best = np.inf
    for r, t in official_starts(moving, fixed):
        best = min(best, problem.run(r, t, MAX_ITERATIONS, IMPROVEMENT_TOLERANCE, stop_at=stop).objective)
        if best <= enough:
            break
    return float(best)


def search_structures(cloud: np.ndarray) -> tuple:
    """``(tree, graph)``: the exact nearest-neighbour structures :func:`register` searches
    ``cloud (n, 3)`` with (a KD-tree and its Delaunay graph)."""
    cloud = np.ascontiguousarray(cloud, dtype=np.float64)
    tree = build_tree(cloud)
    return tree, graph_for(tree)


def _part_clouds(points: np.ndarray, vertices: list[np.ndarray], divisor: float) -> list[np.ndarray]:
    clouds = []
    for cloud, v in zip(points, vertices, strict=True):
        center, basis = pca_frame(v)
        clouds.append((cloud - center) @ basis / divisor)
    return clouds


def geometry_groups(
    part_ids: list[str],
    points: np.ndarray,
    vertices: list[np.ndarray],
    divisor: float,
    threshold: float = THRESHOLD,
    show_progress: bool = False,
    workers: int | None = None,
) -> list[list[str]]:
    """Groups of interchangeable parts: ``part_ids`` sorted, ``points (P, n, 3)`` and ``vertices``
    (each part's mesh, ``(n_i, 3)``) in the same frame, ``divisor`` the scale divisor.
    ``show_progress``: a progress display when many pairs need registering. ``workers``: pairs
    registered at once, in threads (default :func:`aw.pair_search.local_workers`; the groups do
    not depend on it)."""
    clouds = _part_clouds(points, vertices, divisor)
    structures: dict[int, tuple] = {}

    def search(i: int) -> tuple:  # built once per part, only for parts that are registered
        if i not in structures:  # two threads may both build one: the same, and the last kept
            structures[i] = search_structures(clouds[i])
        return structures[i]

    def is_edge(j: int, i: int) -> bool:  # the official order: the later part onto the earlier
        return register(clouds[i], clouds[j], enough=threshold, structures=(search(i), search(j))) <= threshold

    found = registration_groups(
        clouds,
        threshold,
        is_edge,
        what=f"geometry groups of {len(part_ids)} parts",
        show_progress=show_progress,
        workers=workers,
    )
    return [[part_ids[k] for k in g] for g in found]


def geometry_groups_all_pairs(
    part_ids: list[str], points: np.ndarray, vertices: list[np.ndarray], divisor: float, threshold: float = THRESHOLD
) -> list[list[str]]:
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
