"""Exact nearest-neighbour candidate lists on a uniform grid, for lookups of fixed shape (XLA).

For a fixed cloud ``points (m, 3)`` a uniform grid of cubic cells covers the cloud's bounding
box (widened by a margin). Every cell lists every point that can be the nearest neighbour of
some location in the cell:

- ``u`` = the smallest, over all points, of a point's *farthest* distance to the cell box: any
  location in the cell has a point within ``u``;
- the list = every point whose *nearest* distance to the box is ``<= u``: a point farther than
  that from the whole box cannot be nearest anywhere in it. Every point tied at the nearest
  distance of a location is listed too (its box distance is at most that distance, <= ``u``).

So a query in a cell finds its exact nearest neighbour among the cell's list; with the list in
ascending point index, the first minimum over the list is the brute-force first minimum (lowest
index on an exact tie). Rounding cannot drop the computed first minimum: each cell box is
widened by ``1e-9`` of a cell (a query that rounds into a neighbouring cell still lies in the
widened box) and the test ``box distance^2 <= u^2`` carries a relative and an absolute slack far
above float64 rounding of squared distances of O(1) coordinates.

Lists are padded to a fixed ``K`` with their last (largest) index, which never changes a first
minimum. A cell whose list is longer than ``K`` splits into 8 (level by level, shortest lists
first, up to ``depth`` levels and a node budget); a leaf still longer than ``K`` is marked
*overflowing*. Queries there, and queries outside the grid, are not answered by the grid at
all: the caller takes the brute-force path for them (:mod:`aw_eval.kernels.jax_icp`). Nothing
is truncated. Far from the cloud a list (every point that can be nearest anywhere in the cell)
grows with the distance times the cell's size, so there the grid answers little.

Built in numba on the host: a KD-tree of the cloud (:mod:`aw_eval.kernels.kdtree`) gives each
cell centre's nearest point ``p0``; ``maxdist(p0, box)`` bounds ``u`` from above, the points within
that bound of the box are enumerated by a box-to-box pruned tree walk (stopping once there are
more than ``enum_cap``), ``u`` is the smallest farthest distance among them (the point attaining
``u`` is among them), and the list keeps those within ``u``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from aw_eval.kernels.kdtree import STACK, build_tree, nearest2

__all__ = ["CellGrid", "PartGrids", "JOINED_K", "JOINED_MARGIN_CELLS", "build_cell_grid", "build_part_grids", "grid_shape", "brute_first_min", "grid_lookup",
           "leaf_of", "DEFAULT_K"]

DEFAULT_K = 32
# A whole assembly's cloud in one grid (the jax backend's forward searches, built once per
# task): longer lists and a wider margin, so that queries of misaligned starts, far from any
# surface, are still answered by the grid (measured: 98% of the queries at the starts of an
# 8-part checkpoint, all at its registration; per-part grids with K = 32 answered about half).
JOINED_K = 128
JOINED_MARGIN_CELLS = 4
# Grid cells per cloud point (over the widened bounding box) and the margin around the box, in
# cells. More cells: shorter lists, more cells to build and store.
CELLS_PER_POINT = 1.0
MARGIN_CELLS = 2
DEPTH = 4  # splits of a root cell at most
NODES_PER_POINT = 64  # node budget per cloud point
ENUM_PER_K = 8  # a list longer than ENUM_PER_K * K is not split (far from the cloud: it would not fit)
_WIDEN = 1e-9  # cell box widening, in cells
_REL = 1e-9  # slack of the candidate test, relative to u^2 ...
_ABS = 1e-9  # ... and absolute, in cell sides squared


class CellGrid(NamedTuple):
    """Candidate lists of one cloud (see the module docstring), on a grid whose cells may split.

    ``lo (3,)`` grid origin, ``inv_h`` 1 / root cell side, ``dims (3,)`` root cells per axis,
    ``depth`` levels of splitting at most. Nodes ``(N,)``: root cell ``(a, b, c)`` is node
    ``(a * dims[1] + b) * dims[2] + c``; ``child (N,)`` the first of a split node's 8 children
    (octant ``4 x + 2 y + z`` by the halves it takes), -1 for a leaf; ``cand (N, K)`` int32 a
    leaf's ascending point indices padded with the last; ``over (N,)`` bool a leaf whose list is
    longer than ``K``; ``count (N,)`` the list's length (for an overflowing leaf a lower bound)."""

    lo: np.ndarray
    inv_h: float
    dims: np.ndarray
    depth: int
    child: np.ndarray
    cand: np.ndarray
    over: np.ndarray
    count: np.ndarray


def grid_shape(points: np.ndarray, cells_per_point: float = CELLS_PER_POINT,
               margin_cells: int = MARGIN_CELLS, dims: np.ndarray | None = None) -> tuple[np.ndarray, float, np.ndarray]:
    """``(lo (3,), h, dims (3,))`` of the grid over ``points (m, 3)``: cubic cells, about
    ``cells_per_point * m`` of them over the bounding box plus ``margin_cells`` on every side.
    ``dims``: a fixed number of cells per axis instead (the cell side then fits the widest axis)."""
    pmin, pmax = points.min(axis=0), points.max(axis=0)
    ext = np.maximum(pmax - pmin, 1e-12 * max(1.0, float(np.abs(points).max())))
    if dims is None:
        h = float(np.cbrt(np.prod(ext) / (cells_per_point * len(points))))
        h = max(h, float(ext.max()) / 256)  # at most 256 cells along any axis ...
        h = min(h, float(ext.max()) / 4)  # ... at least 4 along the widest
        dims = np.ceil(ext / h).astype(np.int64) + 2 * margin_cells
    else:
        dims = np.asarray(dims, np.int64)
        h = float(np.max(ext / np.maximum(dims - 2 * margin_cells, 1)))
    lo = (pmin + pmax) / 2 - h * dims / 2
    return lo, h, dims


@njit(cache=True)
def _box_box_d2(alo, ahi, blo0, blo1, blo2, bhi0, bhi1, bhi2, node):
    d = 0.0
    g = max(alo[node, 0] - bhi0, blo0 - ahi[node, 0], 0.0)
    d += g * g
    g = max(alo[node, 1] - bhi1, blo1 - ahi[node, 1], 0.0)
    d += g * g
    g = max(alo[node, 2] - bhi2, blo2 - ahi[node, 2], 0.0)
    d += g * g
    return d


@njit(cache=True)
def _cell_list(tree, b0, b1, b2, e0, e1, e2, h, enum_cap, found, bd, stack, bounds, nstack):
    """Candidate list of the box ``[b, e]`` into ``found`` (tree positions, unsorted); returns its
    length, or ``enum_cap + 1`` where more than ``enum_cap`` points lie within the first bound."""
    pts, _, nlo, nhi, left, right, start, end = tree[:8]
    j0 = nearest2(tree, (b0 + e0) / 2, (b1 + e1) / 2, (b2 + e2) / 2, -1, stack, bounds)[0]
    f0 = max(abs(pts[j0, 0] - b0), abs(pts[j0, 0] - e0))
    f1 = max(abs(pts[j0, 1] - b1), abs(pts[j0, 1] - e1))
    f2 = max(abs(pts[j0, 2] - b2), abs(pts[j0, 2] - e2))
    ub = (f0 * f0 + f1 * f1 + f2 * f2) * (1 + _REL) + _ABS * h * h
    # every point within ub of the box (box-to-box pruned walk), at most enum_cap + 1
    n_found = 0
    sp = 1
    nstack[0] = 0
    while sp > 0 and n_found <= enum_cap:
        sp -= 1
        node = nstack[sp]
        if _box_box_d2(nlo, nhi, b0, b1, b2, e0, e1, e2, node) > ub:
            continue
        if left[node] >= 0:
            nstack[sp] = left[node]
            nstack[sp + 1] = right[node]
            sp += 2
            continue
        for k in range(start[node], end[node]):
            g0 = max(b0 - pts[k, 0], pts[k, 0] - e0, 0.0)
            g1 = max(b1 - pts[k, 1], pts[k, 1] - e1, 0.0)
            g2 = max(b2 - pts[k, 2], pts[k, 2] - e2, 0.0)
            d = g0 * g0 + g1 * g1 + g2 * g2
            if d <= ub and n_found <= enum_cap:
                found[n_found] = k
                bd[n_found] = d
                n_found += 1
    if n_found > enum_cap:
        return n_found
    u2 = np.inf  # the smallest farthest distance: attained by a point found (its box distance <= ub)
    for q in range(n_found):
        k = found[q]
        f0 = max(abs(pts[k, 0] - b0), abs(pts[k, 0] - e0))
        f1 = max(abs(pts[k, 1] - b1), abs(pts[k, 1] - e1))
        f2 = max(abs(pts[k, 2] - b2), abs(pts[k, 2] - e2))
        u2 = min(u2, f0 * f0 + f1 * f1 + f2 * f2)
    thr = u2 * (1 + _REL) + _ABS * h * h
    n_keep = 0
    for q in range(n_found):
        if bd[q] <= thr:
            found[n_keep] = found[q]
            n_keep += 1
    return n_keep


@njit(cache=True)
def _build(tree, lo, h, dims, k_max, enum_cap, depth, max_nodes):
    """Root cells of the grid, then each cell whose list is longer than ``k_max`` (and at most
    ``enum_cap``) split into 8 children, down to ``depth`` levels below the root, while the
    nodes number at most ``max_nodes``."""
    index = tree[1]
    g_total = dims[0] * dims[1] * dims[2]
    cap = max(max_nodes, g_total)
    cand = np.zeros((cap, k_max), np.int32)  # overflowing and inner rows stay 0 (any valid index)
    over = np.zeros(cap, np.bool_)
    count = np.zeros(cap, np.int64)
    child = np.full(cap, -1, np.int64)  # first of 8 children (octant order), -1: a leaf
    level = np.zeros(cap, np.int64)
    cell = np.zeros((cap, 3), np.int64)  # index at the node's level
    found = np.empty(enum_cap + 1, np.int64)
    bd = np.empty(enum_cap + 1)
    stack = np.empty(STACK, np.int64)
    bounds = np.empty(STACK)
    nstack = np.empty(STACK * 8, np.int64)
    for a in range(dims[0]):
        for b in range(dims[1]):
            for c in range(dims[2]):
                row = (a * dims[1] + b) * dims[2] + c
                cell[row, 0], cell[row, 1], cell[row, 2] = a, b, c
    n_nodes = g_total
    first, stop = 0, g_total  # the nodes of the current level
    while first < stop:
        for node in range(first, stop):
            hl = h / (1 << level[node])
            widen = _WIDEN * hl
            b0 = lo[0] + cell[node, 0] * hl - widen
            b1 = lo[1] + cell[node, 1] * hl - widen
            b2 = lo[2] + cell[node, 2] * hl - widen
            e0 = lo[0] + (cell[node, 0] + 1) * hl + widen
            e1 = lo[1] + (cell[node, 1] + 1) * hl + widen
            e2 = lo[2] + (cell[node, 2] + 1) * hl + widen
            n = _cell_list(tree, b0, b1, b2, e0, e1, e2, hl, enum_cap, found, bd, stack, bounds, nstack)
            count[node] = n
            if n > k_max:
                over[node] = True
            else:
                for q in range(n):
                    found[q] = index[found[q]]
                srt = np.sort(found[:n])
                for q in range(k_max):
                    cand[node, q] = srt[min(q, n - 1)]
        # split the overflowing nodes of this level, shortest lists first, while the budget lasts
        # (a list longer than enum_cap is far from the cloud: splitting would not bring it to k_max)
        order = np.argsort(count[first:stop], kind="mergesort") + first
        for node in order:
            if not over[node] or count[node] > enum_cap or level[node] >= depth or n_nodes + 8 > cap:
                continue
            over[node] = False
            child[node] = n_nodes
            for o in range(8):
                q = n_nodes + o
                level[q] = level[node] + 1
                cell[q, 0] = 2 * cell[node, 0] + (o >> 2)
                cell[q, 1] = 2 * cell[node, 1] + ((o >> 1) & 1)
                cell[q, 2] = 2 * cell[node, 2] + (o & 1)
            n_nodes += 8
        first, stop = stop, n_nodes
    return cand[:n_nodes].copy(), over[:n_nodes].copy(), count[:n_nodes].copy(), child[:n_nodes].copy()


def build_cell_grid(points: np.ndarray, k: int = DEFAULT_K, cells_per_point: float = CELLS_PER_POINT,
                    margin_cells: int = MARGIN_CELLS, depth: int = DEPTH, max_nodes: int | None = None,
                    tree=None) -> CellGrid:
    """Candidate lists (padded to ``k``) of :func:`grid_shape`'s grid over ``points (m, 3)``, cells
    split up to ``depth`` times where a list is longer than ``k`` (at most ``max_nodes`` nodes,
    default ``NODES_PER_POINT * m``); ``tree``: the cloud's KD-tree where the caller has it."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        raise ValueError("a cell grid needs at least one point")
    lo, h, dims = grid_shape(pts, cells_per_point, margin_cells)
    tree = build_tree(pts) if tree is None else tree
    nodes = int(NODES_PER_POINT * len(pts)) if max_nodes is None else int(max_nodes)
    cand, over, count, child = _build(tuple(tree), lo, h, dims, int(k), max(ENUM_PER_K * int(k), 256), int(depth), nodes)
    return CellGrid(lo, 1.0 / h, dims, int(depth), child, cand, over, count)


def leaf_of(grid: CellGrid, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(node (k,), inside (k,))``: the leaf holding every query ``x (k, 3)`` (as the XLA lookup
    finds it: ``floor((x - lo) * inv_h * 2^depth)`` at the finest level, its high bits above)
    and whether the query lies in the grid."""
    d = grid.depth
    f = np.floor((x - grid.lo) * (grid.inv_h * (1 << d)))
    inside = np.all((f >= 0) & (f < grid.dims * (1 << d)), axis=1)
    fine = np.clip(f, 0, grid.dims * (1 << d) - 1).astype(np.int64)
    root = fine >> d
    node = (root[:, 0] * grid.dims[1] + root[:, 1]) * grid.dims[2] + root[:, 2]
    for lev in range(1, d + 1):
        bits = (fine >> (d - lev)) & 1
        c = grid.child[node]
        node = np.where(c >= 0, c + 4 * bits[:, 0] + 2 * bits[:, 1] + bits[:, 2], node)
    return node, inside


def brute_first_min(x: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Brute-force nearest rows of ``ref (m, 3)`` for ``x (k, 3)``: first minimum of the squared
    distances summed as the protocol sums them (a reference for tests)."""
    d = ((x[:, None, 0] - ref[None, :, 0]) ** 2 + (x[:, None, 1] - ref[None, :, 1]) ** 2) + (x[:, None, 2] - ref[None, :, 2]) ** 2
    return np.argmin(d, axis=1)


def grid_lookup(grid: CellGrid, x: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Host version of the XLA lookup: ``(index (k,), answered (k,))``; ``index`` is the first
    minimum over the query's leaf list where ``answered`` (inside the grid, list not
    overflowing), -1 elsewhere (the caller's brute-force path)."""
    node, inside = leaf_of(grid, x)
    ok = inside & ~grid.over[node]
    c = grid.cand[node]  # (k, K)
    y = ref[c]
    d = ((x[:, None, 0] - y[..., 0]) ** 2 + (x[:, None, 1] - y[..., 1]) ** 2) + (x[:, None, 2] - y[..., 2]) ** 2
    idx = c[np.arange(len(x)), np.argmin(d, axis=1)]
    return np.where(ok, idx, -1), ok


class PartGrids(NamedTuple):
    """Cell grids of ``P`` clouds of ``n`` points each, stacked for XLA (nodes padded to the most):
    ``lo (P, 3)``, ``inv_h (P,)``, ``dims (P, 3)``, ``child (P, N)`` int32, ``cand (P, N, K)``
    int32 indices into the joined clouds ``(P n, 3)`` (part ``q``'s point ``j`` is ``q n + j``),
    ``over (P, N)``, the clouds' bounding boxes ``box_lo, box_hi (P, 3)`` (lower bounds for the
    parts a query's grid does not answer), and the common ``depth``."""

    lo: np.ndarray
    inv_h: np.ndarray
    dims: np.ndarray
    child: np.ndarray
    cand: np.ndarray
    over: np.ndarray
    box_lo: np.ndarray
    box_hi: np.ndarray
    depth: int


def build_part_grids(parts: np.ndarray, k: int = DEFAULT_K, depth: int = DEPTH, margin_cells: int = MARGIN_CELLS,
                     nodes_per_point: float = NODES_PER_POINT) -> PartGrids:
    """:func:`build_cell_grid` of every cloud of ``parts (P, n, 3)``, stacked (:class:`PartGrids`)."""
    parts = np.ascontiguousarray(parts, dtype=np.float64)
    n = parts.shape[1]
    grids = [build_cell_grid(c, k=k, depth=depth, margin_cells=margin_cells, max_nodes=int(nodes_per_point * n))
             for c in parts]
    nodes = max(len(g.child) for g in grids)
    child = np.full((len(grids), nodes), -1, np.int32)
    cand = np.zeros((len(grids), nodes, k), np.int32)
    over = np.ones((len(grids), nodes), bool)  # padding nodes are never reached
    for q, g in enumerate(grids):
        child[q, : len(g.child)] = g.child
        cand[q, : len(g.child)] = g.cand + q * n
        over[q, : len(g.child)] = g.over
    return PartGrids(np.stack([g.lo for g in grids]), np.array([g.inv_h for g in grids]),
                     np.stack([g.dims for g in grids]).astype(np.int32), child, cand, over, parts.min(axis=1),
                     parts.max(axis=1), int(depth))
