"""Equivalence groups of interchangeable parts (fast path of :func:`aw_eval.reference.equivalence_groups`).

Same protocol as the reference: part clouds in their own PCA frames, ``q_i -> q_j`` (``i < j``)
registered with the 24 starts ``(S, 0)``, an edge where the best CD <= ``equiv_cd``, groups =
connected components. The search (:func:`aw.pair_search.registration_groups`) registers only
the pairs that the proven lower bounds of :mod:`aw.shape_bounds` and :mod:`aw.rotation_bound` do
not rule out, likely edges first, and skips a pair already connected through other edges; the components are those of registering
every pair (:func:`equivalence_groups_all_pairs`, kept for the tests). Each part's KD-tree and
Delaunay graph are built once, for the parts that take part in a registration (the Qhull run
shared with the task's index, :func:`aw.kernels.delaunay.cloud_neighbours`), candidates are
registered in threads (:func:`aw.pair_search.local_workers`), and a registration stops as soon
as any start reaches ``equiv_cd`` (the edge is then decided).
"""

from __future__ import annotations

import numpy as np

from aw.kernels.delaunay import DelaunayGraph
from aw.kernels.kdtree import KDTree
from aw.pair_search import registration_groups
from aw.pose import cube_rotations, pca_frame
from aw_eval.kernels import ICPProblem, build_tree, graph_for
from aw_eval.settings import ProtocolSettings

__all__ = ["equivalence_groups", "equivalence_groups_all_pairs", "pair_cd", "part_frames"]


def part_frames(clouds: np.ndarray, divisor: float) -> list[np.ndarray]:
    """Each part's cloud ``(n, 3)`` of ``clouds (P, n, 3)`` in its own PCA frame, over ``divisor``."""
    out = []
    for c in np.asarray(clouds, dtype=np.float64):
        mu, a = pca_frame(c)
        out.append(np.ascontiguousarray(((c - mu) @ a) / divisor))
    return out


def pair_cd(
    q_i: np.ndarray,
    q_j: np.ndarray,
    settings: ProtocolSettings,
    tree_i: KDTree | None = None,
    tree_j: KDTree | None = None,
    decide: bool = False,
    graph_i: DelaunayGraph | None = None,
    graph_j: DelaunayGraph | None = None,
) -> float:
    """Best CD of ``q_i -> q_j`` (both in their PCA frames) over the 24 starts ``(S, 0)``.

    ``decide=True`` answers only "is it <= equiv_cd?": it returns the first objective at or
    below ``equiv_cd`` as soon as any start reaches one (the answer cannot change afterwards).
    ``graph_i, graph_j``: Delaunay graphs of the trees' points (:func:`aw_eval.kernels.graph_for`),
    which speed the neighbour search up without changing it.
    """
    prob = ICPProblem(q_i, q_j, tree_t=tree_j, tree_p=tree_i, graph_t=graph_j, graph_p=graph_i)
    zero = np.zeros(3)
    best = np.inf
    stop = settings.equiv_cd if decide else None
    for s in cube_rotations():
        res = prob.run(s, zero, settings.max_iters, settings.tol, stop_at=stop)
        best = min(best, res.objective)
        if decide and best <= settings.equiv_cd:
            break
    return float(best)


def equivalence_groups(
    clouds: np.ndarray,
    divisor: float,
    settings: ProtocolSettings | None = None,
    *,
    show_progress: bool = True,
    workers: int | None = None,
) -> list[list[int]]:
    """Groups (sorted index lists, ordered by first member) of ``clouds (P, n, 3)`` (baked frame).

    ``show_progress``: a progress display when many pairs need registering (and, either way, a
    :class:`aw.pair_search.LongWorkWarning` when they would take long). ``workers``: pairs
    registered at once, in threads (the compiled ICP releases the GIL); default
    :func:`aw.pair_search.local_workers`. The groups do not depend on it."""
    settings = settings or ProtocolSettings()
    qs = part_frames(clouds, float(divisor))
    structures: dict[int, tuple[KDTree, DelaunayGraph | None]] = {}

    def search(
        i: int,
    ) -> tuple[KDTree, DelaunayGraph | None]:  # built once per part, only for parts that are registered
        if i not in structures:  # two threads may both build one: the same, and the last kept
            tree = build_tree(qs[i])
            structures[i] = (tree, graph_for(tree, clouds[i]))  # Qhull run shared with the task's index
        return structures[i]

    def is_edge(i: int, j: int) -> bool:
        (tree_i, graph_i), (tree_j, graph_j) = search(i), search(j)
        return (
            pair_cd(qs[i], qs[j], settings, tree_i, tree_j, decide=True, graph_i=graph_i, graph_j=graph_j)
            <= settings.equiv_cd
        )

    return registration_groups(
        qs,
        settings.equiv_cd,
        is_edge,
        what=f"equivalence groups of {len(qs)} parts",
        show_progress=show_progress,
        workers=workers,
    )


def equivalence_groups_all_pairs(
    clouds: np.ndarray, divisor: float, settings: ProtocolSettings | None = None
) -> list[list[int]]:
    """The groups by registering every pair ``i < j`` in full (no bound, no skipped pair): the
    plain statement :func:`equivalence_groups` is tested against, with the same kernels."""
    settings = settings or ProtocolSettings()
    qs = part_frames(clouds, float(divisor))
    parent = list(range(len(qs)))

    def root(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    for i in range(len(qs)):
        for j in range(i + 1, len(qs)):
            if pair_cd(qs[i], qs[j], settings) <= settings.equiv_cd:
                a, b = root(i), root(j)
                parent[max(a, b)] = min(a, b)
    groups: dict[int, list[int]] = {}
    for i in range(len(qs)):
        groups.setdefault(root(i), []).append(i)
    return sorted(groups.values(), key=lambda g: g[0])
