"""Equivalence groups of interchangeable parts (fast path of :func:`aw_eval.reference.equivalence_groups`).

Same protocol as the reference: part clouds in their own PCA frames, ``q_i -> q_j`` registered
with the 24 starts ``(S, 0)``, an edge where the best CD <= ``equiv_cd``, groups = connected
components. Two exact savings: each part's KD-tree and Delaunay graph are built once (not a
tree once per ICP iteration), and a pair whose parts are already connected through other edges is skipped, since
its edge could not change the components. A third saving is a proven size bound: for any
rigid motion, the CD has the lower bound of :func:`cd_lower_bound` (Minkowski's inequality on
projections onto the thin principal subspaces, with Ky Fan's bound on projected variance),
so a pair whose bound already exceeds ``equiv_cd`` cannot be an edge and is not registered. Finally, registration of a pair
stops as soon as any start reaches ``equiv_cd`` (the edge is then decided).
"""

from __future__ import annotations

import numpy as np

from aw.pose import cube_rotations, pca_frame
from aw_eval.kernels import ICPProblem, build_tree, graph_for
from aw_eval.settings import ProtocolSettings

__all__ = ["equivalence_groups", "pair_cd", "cd_lower_bound", "shape_bounds"]


def _frames(clouds: np.ndarray, divisor: float) -> list[np.ndarray]:
    out = []
    for c in clouds:
        mu, a = pca_frame(c)
        out.append(np.ascontiguousarray(((c - mu) @ a) / divisor))
    return out


def pair_cd(q_i: np.ndarray, q_j: np.ndarray, settings: ProtocolSettings, tree_i=None, tree_j=None,
            decide: bool = False, graph_i=None, graph_j=None) -> float:
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


def shape_bounds(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid-invariant summaries of ``q (n, 3)`` (a cloud in its own PCA frame, centred at its mean).

    Returns ``(spread (3,), reach (3,))``: ``spread[k-1]`` is the square root of the sum of the
    ``k`` smallest eigenvalues of the cloud's covariance (mean over points), the least rms
    spread of the cloud projected onto any ``k``-dimensional subspace (Ky Fan); ``reach[k-1]``
    is the largest distance of a point from the centre of its bounding box after projection
    onto the cloud's ``k`` thinnest principal axes (the last ``k`` coordinates).
    """
    ev = np.sort(np.linalg.eigvalsh(q.T @ q / len(q)))  # ascending; q is centred
    spread = np.sqrt(np.maximum(np.cumsum(ev), 0.0))
    reach = np.empty(3)
    for k in (1, 2, 3):
        sub = q[:, 3 - k :]
        centre = 0.5 * (sub.max(axis=0) + sub.min(axis=0))
        reach[k - 1] = float(np.sqrt(np.max(np.sum((sub - centre) ** 2, axis=1))))
    return spread, reach


def cd_lower_bound(bounds_i: tuple[np.ndarray, np.ndarray], bounds_j: tuple[np.ndarray, np.ndarray]) -> float:
    """A lower bound on ``CD(R q_i + t, q_j)`` over every rigid motion ``(R, t)``.

    Forward term: for any fixed subspace ``U`` of ``q_j``'s frame and any centre ``c``, the rms of
    ``P_U(x - c)`` over the moved ``q_i`` is at least the Ky Fan spread of ``q_i``, and at most the
    largest ``|P_U(y - c)|`` over ``q_j`` plus ``sqrt(forward term)`` (Minkowski, pairing each point
    with its nearest neighbour). With ``U`` the ``k`` thinnest axes of ``q_j``:
    ``forward >= max_k (spread_i[k] - reach_j[k])_+^2``; the backward term likewise with the roles
    swapped (``U`` moves with ``q_i``, which changes no distance within it).
    """
    (spread_i, reach_i), (spread_j, reach_j) = bounds_i, bounds_j
    fwd = float(np.max(np.maximum(spread_i - reach_j, 0.0) ** 2))
    bwd = float(np.max(np.maximum(spread_j - reach_i, 0.0) ** 2))
    return fwd + bwd


def equivalence_groups(clouds: np.ndarray, divisor: float, settings: ProtocolSettings | None = None) -> list[list[int]]:
    """Groups (sorted index lists, ordered by first member) of ``clouds (P, n, 3)`` (baked frame)."""
    settings = settings or ProtocolSettings()
    qs = _frames(np.asarray(clouds, dtype=np.float64), float(divisor))
    trees = [build_tree(q) for q in qs]
    graphs = [graph_for(t) for t in trees]
    n = len(qs)
    bounds = [shape_bounds(q) for q in qs]
    parent = list(range(n))

    def find(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    for i in range(n):
        for j in range(i + 1, n):
            ri, rj = find(i), find(j)
            if ri == rj:
                continue
            # the margin keeps rounding in the bound from ever excluding a true edge
            if cd_lower_bound(bounds[i], bounds[j]) > settings.equiv_cd * (1 + 1e-9) + 1e-12:
                continue
            if pair_cd(qs[i], qs[j], settings, trees[i], trees[j], decide=True, graph_i=graphs[i],
                       graph_j=graphs[j]) <= settings.equiv_cd:
                parent[max(ri, rj)] = min(ri, rj)
    comps: dict[int, list[int]] = {}
    for i in range(n):
        comps.setdefault(find(i), []).append(i)
    return sorted((sorted(g) for g in comps.values()), key=lambda g: g[0])
