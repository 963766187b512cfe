"""Exact nearest neighbours in an assembly of rigid parts, by Delaunay walks in each part's cloud.

Why: a checkpoint's prediction is the union of its parts' clouds, each moved rigidly from its
baked frame. The backward half of ICP (target points into the prediction) needs the union's
nearest neighbours; a KD-tree of the union costs a build per checkpoint and about 1 us per
search far from the cloud, a Delaunay graph of the union a Qhull run per checkpoint. The parts'
own clouds never change within a task, so their graphs are built once (:mod:`aw.kernels.delaunay`)
and a query is walked in each part's graph in that part's baked frame (``c = A_q x + b_q``):

- the union's nearest is the nearest of the per-part nearests; a part whose bounding box (baked
  frame) is farther than the best distance so far is skipped (its box distance is a lower bound);
- the parts' graphs are stored as one disjoint graph (no edge joins two parts), so a walk started
  in a part stays in it; each part keeps the last answer of the previous query as its warm start
  (queries come in a spatially coherent order);
- the certificate for the next query of a moving point (see :mod:`aw.kernels.icp`): the winner
  stays nearest while the query moves less than ``min(its Voronoi margin in its part, (other -
  nearest) / 2)`` (every other part's distance shrinks by at most the motion while the
  winner's grows by at most as much). Queries are certified first, then those that failed are
  searched, in order (:func:`aw.kernels.delaunay.to_search`).

Exact (up to exact distance ties), like the walks it is made of. Distances are compared in
baked units (normalized distance times the divisor; rigid maps keep the order).

Arrays: ``points (N, 3)`` baked coordinates of all parts, each part's rows contiguous and in its
own KD-tree order; ``offsets (P + 1,)``; ``part_of (N,)``; boxes ``(P, 3)``; the disjoint graph in
the CSR layout of :class:`aw.kernels.delaunay.DelaunayGraph` over the rows of ``points``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from aw.kernels.delaunay import DelaunayGraph, to_search, walk
from aw.kernels.kdtree import box_d2

__all__ = ["PartClouds", "build_part_clouds", "no_part_clouds", "part_maps", "parts_pass"]

# Safety margin of the certificates in normalized units, as in :mod:`aw.kernels.icp`.
_SAFETY = 1e-10


class PartClouds(NamedTuple):
    """Every part's baked cloud with its Delaunay graph, built once per task (see the module
    docstring); pass ``tuple(clouds)`` to the kernels."""

    points: np.ndarray  # (N, 3) baked coordinates, per part in its tree order
    offsets: np.ndarray  # (P + 1,) int64: part q owns rows offsets[q]:offsets[q + 1]
    part_of: np.ndarray  # (N,) int64
    rows: np.ndarray  # (N,) int64: row of each point in its part's cloud (the caller's order)
    box_lo: np.ndarray  # (P, 3) bounding boxes of the parts' baked clouds
    box_hi: np.ndarray  # (P, 3)
    graph: tuple  # DelaunayGraph of ``points``: the parts' graphs side by side


def build_part_clouds(baked: list) -> PartClouds | None:
    """Join the parts' ``(KD-tree, Delaunay graph)`` pairs (baked frames, built once per task);
    ``None`` when a part has no graph (Qhull could not triangulate it)."""
    if not baked or any(g is None for _, g in baked):
        return None
    sizes = np.array([len(tree.points) for tree, _ in baked], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    nnz = np.array([len(g.indices) for _, g in baked], dtype=np.int64)
    edge_off = np.concatenate([[0], np.cumsum(nnz)])
    indptr = np.concatenate([[0]] + [g.indptr[1:] + edge_off[q] for q, (_, g) in enumerate(baked)]).astype(np.int64)
    indices = np.concatenate([g.indices + offsets[q] for q, (_, g) in enumerate(baked)]).astype(np.int64)
    graph = DelaunayGraph(
        indptr,
        indices,
        np.ascontiguousarray(np.concatenate([g.coords for _, g in baked], axis=1)),
        np.concatenate([g.half_inv for _, g in baked]),
    )
    points = np.ascontiguousarray(np.concatenate([tree.points for tree, _ in baked]))
    return PartClouds(
        points,
        offsets,
        np.repeat(np.arange(len(baked), dtype=np.int64), sizes),
        np.concatenate([tree.index for tree, _ in baked]).astype(np.int64),
        np.stack([tree.points.min(axis=0) for tree, _ in baked]),
        np.stack([tree.points.max(axis=0) for tree, _ in baked]),
        tuple(graph),
    )


def no_part_clouds() -> PartClouds:
    """The empty set the kernels read as "use the prediction's own tree instead"."""
    z3, zi = np.zeros((0, 3)), np.zeros(0, np.int64)
    return PartClouds(z3, zi, zi, zi, z3, z3, (zi, zi, np.zeros((3, 0)), np.zeros(0)))


def part_maps(poses: np.ndarray, divisor: float, rotations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Maps of normalized prediction coordinates ``x`` into each part's baked frame,
    ``c = A_q x + b_q``: ``A (P, 3, 3) = divisor R_q^T``, ``b (P, 3) = -R_q^T t_q`` for the poses
    ``(P, 7)`` (the prediction is ``(R_q c + t_q) / divisor``) and their rotations ``R_q (P, 3,
    3)`` (from the caller, which owns the poses' convention)."""
    rt = np.swapaxes(rotations, 1, 2)
    return np.ascontiguousarray(divisor * rt), np.ascontiguousarray(-(rt @ poses[:, :3, None])[:, :, 0])


@njit(cache=True, inline="always")
def _to_part(a, b, q, x0, x1, x2):
    """The point ``x`` in part ``q``'s baked frame: ``A_q x + b_q``."""
    return (
        a[q, 0, 0] * x0 + a[q, 0, 1] * x1 + a[q, 0, 2] * x2 + b[q, 0],
        a[q, 1, 0] * x0 + a[q, 1, 1] * x1 + a[q, 1, 2] * x2 + b[q, 1],
        a[q, 2, 0] * x0 + a[q, 2, 1] * x1 + a[q, 2, 2] * x2 + b[q, 2],
    )


@njit(cache=True)
def parts_pass(
    clouds,
    a: np.ndarray,
    b: np.ndarray,
    divisor: float,
    x: np.ndarray,
    cand: np.ndarray,
    xref: np.ndarray,
    slack: np.ndarray,
    fresh: bool,
    warm: np.ndarray,
    stats: np.ndarray,
) -> int:
    """Update ``cand (k,)`` (rows of ``clouds.points``) to the exact nearest neighbours of the
    queries ``x (k, 3)`` (normalized prediction frame) in the posed assembly; returns the number
    of queries searched. ``a (P, 3, 3)``, ``b (P, 3)``: :func:`part_maps` for ``divisor``.
    Certificate state as in :func:`aw.kernels.icp._certified_pass`, in baked units: ``xref (k, 3)``
    (normalized) where each query was last searched, ``slack (k, 2)``: column 1 the squared
    union margin less a safety margin (-1 where none is left; column 0 is not used here).
    ``warm (P,)``: scratch for each part's last answer. ``stats (2,)`` int64 adds
    the queries searched and the part walks they took (more than one walk per search where the
    query is within reach of several parts: parts in contact)."""
    pts, offsets, part_of, _, lo, hi, graph = clouds
    n_parts = offsets.shape[0] - 1
    scale = divisor * divisor  # normalized -> baked squared distances
    safety = _SAFETY * divisor
    for q in range(n_parts):
        warm[q] = offsets[q]
    todo = np.empty(x.shape[0], np.int64)
    searched = to_search(x, xref, slack[:, 1], scale, fresh, todo)
    walks = 0
    for k in range(searched):
        i = todo[k]
        x0, x1, x2 = x[i, 0], x[i, 1], x[i, 2]
        hint = -1 if fresh else cand[i]
        first = part_of[hint] if hint >= 0 else (part_of[cand[i - 1]] if i > 0 else 0)
        best, best_j, best_margin, other = np.inf, -1, np.inf, np.inf
        for step in range(n_parts):
            q = first + step
            if q >= n_parts:
                q -= n_parts
            c0, c1, c2 = _to_part(a, b, q, x0, x1, x2)
            lb = box_d2(c0, c1, c2, lo, hi, q)
            if lb >= best:  # every point of this part is at least that far
                other = min(other, lb)
                continue
            j = warm[q]
            if hint >= 0 and part_of[hint] == q and hint != j:  # the nearer of the two starts
                u, v, w = c0 - pts[j, 0], c1 - pts[j, 1], c2 - pts[j, 2]
                e, f, g = c0 - pts[hint, 0], c1 - pts[hint, 1], c2 - pts[hint, 2]
                if e * e + f * f + g * g < u * u + v * v + w * w:
                    j = hint
            j, d1, _, margin = walk(pts, graph, c0, c1, c2, j)
            walks += 1
            warm[q] = j
            if d1 < best:
                other = min(other, best)
                best, best_j, best_margin = d1, j, margin
            else:
                other = min(other, d1)
        cand[i] = best_j
        margin = min(best_margin, 0.5 * (np.sqrt(other) - np.sqrt(best))) - safety
        slack[i, 1] = margin * margin if margin > 0.0 else -1.0
        xref[i, 0], xref[i, 1], xref[i, 2] = x0, x1, x2
    stats[0] += searched
    stats[1] += walks
    return searched
