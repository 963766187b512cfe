"""Leaf boxes of fixed clouds: the jax backend's exact per-query neighbour certificates.

A cloud is split by a balanced k-d partition (median along the widest axis, recursively) into
``B`` leaves of at most ``S`` points; a leaf keeps its axis-aligned box and its points'
original indices, padded to ``S`` by repeating one of its own points (same index, same
distance: a first minimum never changes). A query reads the squared distance ``lb2`` to every
leaf box, gathers the points of the ``C`` nearest boxes, computes their squared distances from
coordinates as the protocol does, and takes ``d*`` = their minimum and the lowest index among
the candidates at ``d*`` (brute force's first minimum on exact ties). The ``(C+1)``-th smallest
box distance is the certificate: every point outside the ``C`` leaves is at least that far, so
where ``lb2 (1 - REL) - ABS > d*`` no such point can be nearer or tied, and the answer is the
brute-force first minimum. Elsewhere the query is flagged for the brute-force path.

Rounding cannot break this: a point's computed squared distance differs from its exact one by a
relative ~1e-15 (a few float64 operations, plus the rigid map between a part's frame and the
reference frame where the boxes and the distances are taken in different frames), far inside
``REL = 1e-9``; the box distance, an exact lower bound of every point in the box, is computed
with the same few operations. So a point outside the chosen leaves computes strictly farther
than ``d*``, and the candidates' own distances are the very numbers brute force compares.

Unlike a cell grid, whose lists must serve every location of a cell and grow with the distance
to the cloud, the bound is per query: far from a flat face, only the leaves around the foot of
the perpendicular come near ``d*``. Built on the host in NumPy (milliseconds per cloud).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = [
    "LeafBoxes",
    "DEFAULT_LEAF",
    "DEFAULT_CANDIDATES",
    "REL",
    "ABS",
    "build_leaf_boxes",
    "build_part_leaves",
    "brute_first_min",
    "leaf_lookup",
]

DEFAULT_LEAF = 32  # S: points a leaf at most
DEFAULT_CANDIDATES = 8  # C: leaves a query reads (8 x 32: under 5 % fallback in benchmarks/grid_coverage.py)
# Slack of the certificate: the (C+1)-th box distance must exceed d* by this relative margin
# and an absolute one far above the rounding of O(1) squared distances.
REL, ABS = 1e-9, 1e-15


class LeafBoxes(NamedTuple):
    """Leaves of ``P`` clouds of ``n`` points each, stacked for XLA: boxes ``lo, hi (P, B, 3)``
    and ``index (P, B, S)`` int32, indices into the joined clouds ``(P n, 3)`` (part ``q``'s
    point ``j`` is ``q n + j``), each leaf padded with one of its own points."""

    lo: np.ndarray
    hi: np.ndarray
    index: np.ndarray  # type: ignore[assignment]  # shadows tuple.index, which is never called on the boxes


def _leaves(pts: np.ndarray, leaf: int) -> list[np.ndarray]:
    """Index sets of the balanced k-d partition of ``pts (n, 3)`` into ``2^d`` leaves of at most
    ``leaf`` points (``d`` the fewest levels that fit)."""
    n = len(pts)
    depth = max(0, int(np.ceil(np.log2(max(n, 1) / leaf))))
    sets = [np.arange(n)]
    for _ in range(depth):
        nxt = []
        for s in sets:
            p = pts[s]
            axis = int(np.argmax(p.max(axis=0) - p.min(axis=0)))
            half = len(s) // 2
            # stable order along the axis: equal coordinates keep index order (deterministic)
            order = s[np.argsort(p[:, axis], kind="stable")]
            nxt += [order[:half], order[half:]]
        sets = nxt
    return sets


def build_leaf_boxes(points: np.ndarray, leaf: int = DEFAULT_LEAF, offset: int = 0) -> LeafBoxes:
    """:class:`LeafBoxes` of one cloud ``points (n, 3)`` (``P = 1``), indices shifted by ``offset``."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        raise ValueError("leaf boxes need at least one point")
    sets = _leaves(pts, int(leaf))
    size = max(len(s) for s in sets)
    index = np.empty((len(sets), size), np.int32)
    lo, hi = np.empty((len(sets), 3)), np.empty((len(sets), 3))
    for b, s in enumerate(sets):
        index[b] = np.concatenate([s, np.full(size - len(s), s[0])]) + offset
        lo[b], hi[b] = pts[s].min(axis=0), pts[s].max(axis=0)
    return LeafBoxes(lo[None], hi[None], index[None])


def build_part_leaves(parts: np.ndarray, leaf: int = DEFAULT_LEAF) -> LeafBoxes:
    """:func:`build_leaf_boxes` of every cloud of ``parts (P, n, 3)``, stacked."""
    parts = np.asarray(parts, dtype=np.float64)
    n = parts.shape[1]
    each = [build_leaf_boxes(c, leaf, q * n) for q, c in enumerate(parts)]
    return LeafBoxes(*(np.concatenate(z) for z in zip(*each, strict=True)))


def brute_first_min(x: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Brute-force nearest rows of ``ref (m, 3)`` for ``x (k, 3)``: first minimum of the squared
    distances summed as the protocol sums them (a reference for tests)."""
    d = ((x[:, None, 0] - ref[None, :, 0]) ** 2 + (x[:, None, 1] - ref[None, :, 1]) ** 2) + (
        x[:, None, 2] - ref[None, :, 2]
    ) ** 2
    return np.argmin(d, axis=1)


def box_d2(lo: np.ndarray, hi: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``(k, B)`` squared distances of ``y (k, 3)`` to the boxes ``lo, hi (B, 3)``."""
    g = np.maximum(np.maximum(lo[None] - y[:, None], y[:, None] - hi[None]), 0.0)
    return (g[..., 0] * g[..., 0] + g[..., 1] * g[..., 1]) + g[..., 2] * g[..., 2]


def leaf_lookup(
    leaves: LeafBoxes, y: np.ndarray, x: np.ndarray, ref: np.ndarray, candidates: int = DEFAULT_CANDIDATES
) -> tuple[np.ndarray, np.ndarray]:
    """Host version of the XLA lookup (the same rule; boxes picked in float64 here, in float32
    there): ``(index (k,), answered (k,))`` for queries ``y (P, k, 3)``
    in every cloud's frame and ``x (k, 3)`` the same queries in ``ref``'s frame (``ref (P n, 3)``
    the joined clouds there); ``index`` is the first minimum over the ``candidates`` nearest
    leaves, certified where ``answered`` (elsewhere the caller's brute-force path)."""
    p, b, s = leaves.index.shape
    lb = np.concatenate([box_d2(leaves.lo[q], leaves.hi[q], y[q]) for q in range(p)], axis=1)  # (k, P B)
    c = min(candidates, p * b)
    order = np.argsort(lb, axis=1, kind="stable")
    cand = leaves.index.reshape(p * b, s)[order[:, :c]].reshape(len(x), c * s)
    yc = ref[cand]
    d = ((x[:, None, 0] - yc[..., 0]) ** 2 + (x[:, None, 1] - yc[..., 1]) ** 2) + (x[:, None, 2] - yc[..., 2]) ** 2
    dmin = d.min(axis=1)
    idx = np.where(d == dmin[:, None], cand, np.iinfo(np.int32).max).min(axis=1)
    if c == p * b:
        return idx, np.ones(len(x), bool)
    nxt = np.take_along_axis(lb, order[:, c : c + 1], 1)[:, 0]
    return idx, nxt * (1 - REL) - ABS > dmin
