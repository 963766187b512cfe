"""A compiled KD-tree (numba) for exact nearest neighbours of moving query sets.

The evaluator's neighbour searches all have the same shape: a reference cloud that never changes
(a target per task, a prediction per checkpoint, in its own frame) and query clouds that move a
little between calls (ICP iterations). This tree is built once per cloud and answers

- ``nearest2``: the nearest and second-nearest squared distances of one query, with a *warm*
  start: the search begins at the leaf of the previous neighbour and climbs only until the
  second-nearest ball lies inside the current node's cell, so a query that barely moved visits
  a leaf or two;
- the *certificate* used by :mod:`aw.kernels.icp`: a query last searched at ``x_ref`` with second
  nearest distance ``d2`` keeps its neighbour ``j`` at a new position ``x`` without any search
  while ``|x - y_j| + |x - x_ref| < d2`` (every other point is at least ``d2 - |x - x_ref|``
  away, by the triangle inequality). Exact, not approximate (up to exact distance ties).

Layout (all arrays C-contiguous): ``points (n, 3)`` float64 permuted into tree order; ``index
(n,)`` maps tree order to the caller's order; per node ``lo, hi (N, 3)`` bounding boxes,
``left, right (N,)`` children (``-1`` for a leaf), ``start, end (N,)`` its point range, the split
``dim, split``, ``parent`` and the cell ``cell_lo, cell_hi``; ``leaf_of (n,)`` per point.
Searches work in tree order; callers convert with ``index`` once.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

__all__ = ["KDTree", "box_d2", "build_tree", "nearest2", "nn_indices"]

LEAF_SIZE = 8
STACK = 128  # pending subtrees: at most one per level of a median-split tree


class KDTree(NamedTuple):
    """Arrays of a compiled KD-tree (see the module docstring); pass ``tree`` to the kernels."""

    points: np.ndarray  # (n, 3) tree order
    index: np.ndarray  # type: ignore[assignment]  # (n,) tree position -> caller's row; shadows tuple.index, never called
    lo: np.ndarray  # (N, 3)
    hi: np.ndarray  # (N, 3)
    left: np.ndarray  # (N,)
    right: np.ndarray  # (N,)
    start: np.ndarray  # (N,)
    end: np.ndarray  # (N,)
    dim: np.ndarray  # (N,) split axis of an inner node
    split: np.ndarray  # (N,) split value: left child <= split <= right child
    parent: np.ndarray  # (N,) parent node (-1 for the root)
    leaf_of: np.ndarray  # (n,) leaf node holding each tree position
    cell_lo: np.ndarray  # (N, 3) region of space of a node (split planes on its path; the
    cell_hi: np.ndarray  # (N, 3) root's is unbounded), unlike ``lo, hi`` which bound its points

    def __len__(self) -> int:
        return len(self.points)

    def query(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact nearest neighbours of ``x (k, 3)``: ``(squared distance (k,), caller row (k,))``."""
        x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3)
        d, j = nn_indices(self, x)
        return d, self.index[j]


@njit(cache=True)
def _select(pts: np.ndarray, order: np.ndarray, dim: int, s: int, e: int, k: int) -> None:
    """Reorder rows ``s:e`` of ``pts (n, 3)`` (and ``order`` with them) so that row ``k`` holds
    the point of rank ``k - s`` along ``dim``, none after it smaller and none before it larger
    (Hoare quickselect, median-of-three pivots): O(n) per level where a sort is O(n log n)."""
    lo, hi = s, e - 1
    while hi > lo:
        a, b, c = pts[lo, dim], pts[(lo + hi) // 2, dim], pts[hi, dim]
        pivot = max(min(a, b), min(max(a, b), c))
        i, j = lo, hi
        while i <= j:
            while pts[i, dim] < pivot:
                i += 1
            while pts[j, dim] > pivot:
                j -= 1
            if i <= j:
                for d in range(3):
                    pts[i, d], pts[j, d] = pts[j, d], pts[i, d]
                order[i], order[j] = order[j], order[i]
                i += 1
                j -= 1
        # now rows lo..j <= pivot <= rows i..hi, and any row between j and i holds the pivot
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            return


@njit(cache=True)
def _build(points: np.ndarray, leaf: int):
    n = points.shape[0]
    cap = 2 * (n // leaf + 1) * 2 + 1
    lo = np.empty((cap, 3))
    hi = np.empty((cap, 3))
    dims = np.zeros(cap, np.int64)
    split = np.zeros(cap)
    left = np.full(cap, -1, np.int64)
    right = np.full(cap, -1, np.int64)
    start = np.zeros(cap, np.int64)
    end = np.zeros(cap, np.int64)
    pts = points.copy()  # permuted in place into tree order, with ``order``
    order = np.arange(n)
    stack = np.empty(STACK, np.int64)
    n_nodes = 1
    start[0], end[0] = 0, n
    sp = 1
    stack[0] = 0
    while sp > 0:
        sp -= 1
        node = stack[sp]
        s, e = start[node], end[node]
        for d in range(3):
            lo[node, d] = np.inf
            hi[node, d] = -np.inf
        for k in range(s, e):
            for d in range(3):
                v = pts[k, d]
                if v < lo[node, d]:
                    lo[node, d] = v
                if v > hi[node, d]:
                    hi[node, d] = v
        if e - s <= leaf:
            continue
        dim = 0
        for d in range(1, 3):
            if hi[node, d] - lo[node, d] > hi[node, dim] - lo[node, dim]:
                dim = d
        mid = s + (e - s) // 2
        _select(pts, order, dim, s, e, mid)
        dims[node] = dim
        split[node] = pts[mid, dim]
        a, b = n_nodes, n_nodes + 1
        n_nodes += 2
        left[node], right[node] = a, b
        start[a], end[a], start[b], end[b] = s, mid, mid, e
        stack[sp] = a
        stack[sp + 1] = b
        sp += 2
    parent = np.full(n_nodes, -1, np.int64)
    leaf_of = np.zeros(n, np.int64)
    cell_lo = np.full((n_nodes, 3), -np.inf)
    cell_hi = np.full((n_nodes, 3), np.inf)
    for node in range(n_nodes):  # children always come after their parent
        if left[node] >= 0:
            a, b = left[node], right[node]
            parent[a] = node
            parent[b] = node
            cell_lo[a], cell_hi[a] = cell_lo[node], cell_hi[node]
            cell_lo[b], cell_hi[b] = cell_lo[node], cell_hi[node]
            cell_hi[a, dims[node]] = split[node]
            cell_lo[b, dims[node]] = split[node]
        else:
            for k in range(start[node], end[node]):
                leaf_of[k] = node
    return (
        pts,
        order,
        lo[:n_nodes].copy(),
        hi[:n_nodes].copy(),
        left[:n_nodes].copy(),
        right[:n_nodes].copy(),
        start[:n_nodes].copy(),
        end[:n_nodes].copy(),
        dims[:n_nodes].copy(),
        split[:n_nodes].copy(),
        parent,
        leaf_of,
        cell_lo,
        cell_hi,
    )


def build_tree(points: np.ndarray) -> KDTree:
    """Compiled KD-tree of ``points (n, 3)`` (n >= 1), median splits on the widest axis."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        raise ValueError("a KD-tree needs at least one point")
    return KDTree(*_build(pts, LEAF_SIZE))


@njit(cache=True, inline="always")
def box_d2(x0, x1, x2, lo, hi, node):
    """Squared distance from the point to the box ``lo[node], hi[node]`` (0 inside)."""
    d = 0.0
    for k, v in enumerate((x0, x1, x2)):
        g = max(lo[node, k] - v, v - hi[node, k], 0.0)
        d += g * g
    return d


@njit(cache=True, inline="always")
def _subtree(tree, x0, x1, x2, root, j1, d1, d2, stack, bounds):
    """Update the two nearest ``(j1, d1, d2)`` with the points of the subtree at ``root``:
    depth first, the nearer child (by the split plane) entered at once, the farther one pushed
    with the squared distance to its bounding box and checked again when popped."""
    pts, _, lo, hi, left, right, start, end, dim, split = tree[:10]
    sp = 1
    stack[0] = root
    bounds[0] = 0.0
    while sp > 0:
        sp -= 1
        if bounds[sp] >= d2:
            continue
        node = stack[sp]
        left_child = left[node]
        while left_child >= 0:
            right_child = right[node]
            dd = dim[node]
            xv = x0 if dd == 0 else (x1 if dd == 1 else x2)
            if xv <= split[node]:
                near, far = left_child, right_child
            else:
                near, far = right_child, left_child
            bf = box_d2(x0, x1, x2, lo, hi, far)
            if bf < d2:
                stack[sp] = far
                bounds[sp] = bf
                sp += 1
            node = near
            left_child = left[node]
        for k in range(start[node], end[node]):
            a, b, c = x0 - pts[k, 0], x1 - pts[k, 1], x2 - pts[k, 2]
            d = a * a + b * b + c * c
            if d < d1:
                d2 = d1
                d1 = d
                j1 = k
            elif d < d2:
                d2 = d
    return j1, d1, d2


@njit(cache=True, inline="always")
def nearest2(tree, x0: float, x1: float, x2: float, warm: int, stack: np.ndarray, bounds: np.ndarray):
    """Nearest neighbour of the point ``(x0, x1, x2)``: ``(tree position, d1, d2)``, squared
    distances of the nearest and the second nearest (``inf`` if the tree has one point).
    ``stack (STACK,)`` int64 and ``bounds (STACK,)`` float64 are scratch space.

    ``warm``: a tree position near the answer (the previous neighbour of a moving query), or -1.
    A warm search starts at the leaf holding ``warm`` and climbs: each level adds the sibling
    subtree (pruned by its box) until the ball of radius ``sqrt(d2)`` around the query lies
    inside the current node's cell, which no point outside it can enter. A query that barely
    moved touches one or two leaves.
    """
    lo, hi, left, right, parent, leaf_of = tree[2], tree[3], tree[4], tree[5], tree[10], tree[11]
    clo, chi = tree[12], tree[13]
    if warm < 0:
        return _subtree(tree, x0, x1, x2, 0, -1, np.inf, np.inf, stack, bounds)
    node = leaf_of[warm]
    j1, d1, d2 = _subtree(tree, x0, x1, x2, node, -1, np.inf, np.inf, stack, bounds)
    while True:
        up = parent[node]
        if up < 0:
            break
        rad = np.sqrt(d2)
        if (
            x0 - clo[node, 0] >= rad
            and chi[node, 0] - x0 >= rad
            and x1 - clo[node, 1] >= rad
            and chi[node, 1] - x1 >= rad
            and x2 - clo[node, 2] >= rad
            and chi[node, 2] - x2 >= rad
        ):
            break
        sib = right[up] if left[up] == node else left[up]
        if box_d2(x0, x1, x2, lo, hi, sib) < d2:
            j1, d1, d2 = _subtree(tree, x0, x1, x2, sib, j1, d1, d2, stack, bounds)
        node = up
    return j1, d1, d2


@njit(cache=True)
def nn_indices(tree, x: np.ndarray):
    """Exact nearest neighbours of ``x (k, 3)``: ``(squared distance (k,), tree position (k,))``."""
    k = x.shape[0]
    out_d = np.empty(k)
    out_j = np.empty(k, np.int64)
    stack = np.empty(STACK, np.int64)
    bounds = np.empty(STACK)
    for i in range(k):
        j, d1, _ = nearest2(tree, x[i, 0], x[i, 1], x[i, 2], -1, stack, bounds)
        out_d[i] = d1
        out_j[i] = j
    return out_d, out_j
