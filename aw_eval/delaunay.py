"""Exact nearest neighbours by walking the Delaunay graph of a fixed cloud (compiled, numba).

Why: far from a cloud, a query's nearest-neighbour ball is wide and a KD-tree must open every
leaf the ball's shell cuts (about 1 us per query here), and the nearest neighbour of a far
query changes with every move, so no certificate survives. A walk on the Delaunay graph pays
only for the distance it travels.

Three classical facts make the walk exact and its certificates free (general position, i.e. up
to exact distance ties):

- if a point ``a`` of the cloud is not the nearest to ``x``, some Delaunay neighbour of ``a`` is
  strictly nearer (the segment from ``a`` to ``x`` leaves the Voronoi cell of ``a`` through a face
  shared with a neighbour, and beyond that face ``x`` is nearer to the neighbour); so steepest
  descent from any start ends at the nearest point;
- the second-nearest point of ``x`` is a Delaunay neighbour of the nearest (shrink the ball
  through it towards it until the nearest leaves), so the last scan also gives ``d2`` for the
  ball certificate of :mod:`aw_eval.kdtree`;
- the Voronoi cell of a point is cut out by the bisector planes with its Delaunay neighbours
  alone, so the last scan of a walk also gives the distance from ``x`` to the nearest face of
  the cell of its nearest point: a certificate for the next query of a moving point (it keeps
  its nearest point while it moves less than that). Far from a cloud this slack is about the
  sample spacing, where the ball certificate of :mod:`aw_eval.kdtree` (half the gap between the
  nearest and second-nearest distances) shrinks like ``spacing^2 / distance``.

The graph comes from Qhull (``scipy.spatial.Delaunay``), built once per fixed cloud (a target
per task, a prediction per checkpoint in its own frame). :func:`build_graph` returns ``None``
where Qhull cannot triangulate every point (fewer than 5 points, a flat or a degenerate cloud,
duplicate points); callers then keep the KD-tree search.

Arrays: ``points (n, 3)`` float64; the graph in CSR form ``indptr (n + 1,)``, ``indices (nnz,)``,
with per-edge ``coords (3, nnz)`` and ``half_inv (nnz,)`` (see :class:`DelaunayGraph`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit
from scipy.spatial import Delaunay, QhullError

__all__ = ["DelaunayGraph", "build_graph", "walk", "no_graph"]


class DelaunayGraph(NamedTuple):
    """Delaunay neighbours of every point, CSR: the neighbours of ``i`` are
    ``indices[indptr[i]:indptr[i + 1]]`` (rows of the cloud it was built on)."""

    indptr: np.ndarray  # (n + 1,) int64
    indices: np.ndarray  # (nnz,) int64
    coords: np.ndarray  # (3, nnz) coordinates of each edge's far end, laid out for SIMD scans
    half_inv: np.ndarray  # (nnz,) 1 / (2 |y_i - y_v|) per edge (i, v): bisector distances


def no_graph() -> DelaunayGraph:
    """The empty graph the kernels read as "search with the KD-tree instead"."""
    return DelaunayGraph(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((3, 0)), np.zeros(0))


def build_graph(points: np.ndarray) -> DelaunayGraph | None:
    """Delaunay graph of ``points (n, 3)``, or ``None`` where Qhull leaves a point out or fails."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) < 5:
        return None
    try:
        tri = Delaunay(pts)
    except (QhullError, ValueError):
        return None
    if len(tri.coplanar) or len(np.unique(tri.simplices)) != len(pts):
        return None  # a point outside the triangulation could never be reached by a walk
    indptr, indices = tri.vertex_neighbor_vertices
    rows = np.repeat(np.arange(len(pts)), np.diff(indptr))
    length = np.linalg.norm(pts[indices] - pts[rows], axis=1)
    if not np.all(length > 0):
        return None
    coords = np.ascontiguousarray(pts[indices].T)
    return DelaunayGraph(indptr.astype(np.int64), indices.astype(np.int64), coords, 0.5 / length)


# No NaN/inf/signed-zero assumptions let the scans vectorize; no reassociation or contraction,
# so every distance is computed exactly as elsewhere (the walk's answer does not change).
@njit(cache=True, fastmath={"nnan", "ninf", "nsz"})
def walk(pts: np.ndarray, graph, x0: float, x1: float, x2: float, j: int):
    """Steepest descent from row ``j`` to the nearest point of ``x = (x0, x1, x2)``: ``(row, d1, d2,
    margin)``, the squared distances of the nearest and the second nearest (a Delaunay neighbour
    of the nearest), and the distance from ``x`` to the nearest face of its Voronoi cell (the
    bisector planes with its Delaunay neighbours): ``x`` can move by less than ``margin`` and
    keep its nearest neighbour. ``graph``: a :class:`DelaunayGraph` of
    ``pts (n, 3)`` as a tuple."""
    indptr, indices, coords, half_inv = graph
    cx, cy, cz = coords[0], coords[1], coords[2]
    a, b, c = x0 - pts[j, 0], x1 - pts[j, 1], x2 - pts[j, 2]
    dj = a * a + b * b + c * c
    while True:
        lo, hi = indptr[j], indptr[j + 1]
        bd = np.inf
        margin = np.inf
        for k in range(lo, hi):
            a, b, c = x0 - cx[k], x1 - cy[k], x2 - cz[k]
            d = a * a + b * b + c * c
            bd = min(bd, d)
            margin = min(margin, (d - dj) * half_inv[k])
        if not bd < dj:
            return j, dj, bd, margin
        for k in range(lo, hi):  # the first neighbour at the smallest distance
            a, b, c = x0 - cx[k], x1 - cy[k], x2 - cz[k]
            if a * a + b * b + c * c == bd:
                j = indices[k]
                break
        dj = bd
