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
  ball certificate of :mod:`aw.kernels.kdtree`;
- the Voronoi cell of a point is cut out by the bisector planes with its Delaunay neighbours
  alone, so the last scan of a walk also gives the distance from ``x`` to the nearest face of
  the cell of its nearest point: a certificate for the next query of a moving point (it keeps
  its nearest point while it moves less than that). Far from a cloud this slack is about the
  sample spacing, where the ball certificate of :mod:`aw.kernels.kdtree` (half the gap between the
  nearest and second-nearest distances) shrinks like ``spacing^2 / distance``.

The graph comes from Qhull (``scipy.spatial.Delaunay``), built once per fixed cloud (a target
per task, a prediction per checkpoint in its own frame). :func:`build_graph` returns ``None``
where Qhull cannot triangulate every point (fewer than 5 points, a flat or a degenerate cloud,
duplicate points); callers then keep the KD-tree search.

A walk is a few scans of about 14 neighbours, and a scan is two minima (distance and margin)
over them: it runs in explicit 4-wide SIMD vectors (:func:`_scan`; numba leaves such
min-reductions scalar), over rows padded to whole vectors with far sentinels. Same numbers,
bitwise (ICP about 30% faster with it and the
certificate pass of :func:`uncertified`: docs/performance.md, round 7).

Arrays: ``points (n, 3)`` float64; the graph in CSR form ``indptr (n + 1,)``, ``indices (nnz,)``,
with per-edge ``coords (3, nnz)`` and ``half_inv (nnz,)`` (see :class:`DelaunayGraph`).
"""

from __future__ import annotations

import hashlib
from typing import Any, NamedTuple

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic
from scipy.spatial import Delaunay, QhullError

__all__ = [
    "DelaunayGraph",
    "build_graph",
    "cloud_neighbours",
    "delaunay_neighbours",
    "graph_of",
    "walk",
    "no_graph",
    "uncertified",
    "to_search",
]


# Every row of a graph holds a multiple of LANES entries (padded with SENTINEL neighbours), so
# that a scan runs in whole SIMD vectors of LANES doubles with no remainder loop.
LANES = 4
# A padding neighbour's coordinates: its squared distance from any query within 1e20 of the
# origin (coordinates here are normalized or baked, O(1)-O(1e4)) is about 3e60, never the
# nearest, nor its face the nearest face (its ``half_inv`` is 1).
SENTINEL = 1e30


class DelaunayGraph(NamedTuple):
    """Delaunay neighbours of every point, CSR: the neighbours of ``i`` are
    ``indices[indptr[i]:indptr[i + 1]]`` (rows of the cloud it was built on), each row padded
    to a multiple of :data:`LANES` with neighbours at :data:`SENTINEL` (``indices``: ``i``
    itself) after the real ones."""

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
    found = delaunay_neighbours(pts)
    return None if found is None else graph_of(found, pts)


def delaunay_neighbours(points: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The Delaunay neighbours of ``points (n, 3)`` in CSR form ``(indptr (n + 1,), indices
    (nnz,))`` over their rows (one Qhull run), or ``None`` where Qhull leaves a point out or
    fails. They do not change under a rotation, reflection, translation or uniform scaling of
    the points (the empty-sphere property is kept), so one run serves a cloud in every frame:
    :func:`graph_of` makes the graph of any such image of it, in any row order."""
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
    return indptr.astype(np.int64), indices.astype(np.int64)


# Neighbours of the clouds seen in this process, by content (FIFO, at most this many clouds): a
# task's equivalence groups and its search structures search one part's cloud in two frames
# (its PCA frame, its baked frame), and one Qhull run serves both.
_NEIGHBOURS: dict = {}
_NEIGHBOURS_MAX = 1024


def cloud_neighbours(cloud: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`delaunay_neighbours` of ``cloud (n, 3)``, computed once per process and cloud."""
    pts = np.ascontiguousarray(cloud, dtype=np.float64).reshape(-1, 3)
    key = hashlib.blake2b(pts.tobytes(), digest_size=20).digest()
    if key in _NEIGHBOURS:
        return _NEIGHBOURS[key]
    found = delaunay_neighbours(pts)
    while len(_NEIGHBOURS) >= _NEIGHBOURS_MAX:
        _NEIGHBOURS.pop(next(iter(_NEIGHBOURS)), None)
    _NEIGHBOURS[key] = found
    return found


def graph_of(
    neighbours: tuple[np.ndarray, np.ndarray], points: np.ndarray, order: np.ndarray | None = None
) -> DelaunayGraph | None:
    """The :class:`DelaunayGraph` of ``points (n, 3)`` from :func:`delaunay_neighbours` of (an
    image of) them under a similarity; ``order (n,)``: the neighbours' row of each point
    (``points[k]`` is row ``order[k]``, e.g. a KD-tree's ``index``), else the same rows. ``None``
    where two points coincide."""
    indptr, indices = neighbours
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    if order is not None:  # renumber: new row k is old row order[k]
        position = np.empty(len(order), np.int64)
        position[order] = np.arange(len(order))
        degree = np.diff(indptr)[order]
        new_ptr = np.concatenate([[0], np.cumsum(degree)]).astype(np.int64)
        take = np.repeat(indptr[order] - new_ptr[:-1], degree) + np.arange(new_ptr[-1])
        indptr, indices = new_ptr, position[indices[take]]
    rows = np.repeat(np.arange(len(pts)), np.diff(indptr))
    length = np.linalg.norm(pts[indices] - pts[rows], axis=1)
    if not np.all(length > 0):
        return None
    return _padded(indptr, indices, pts, 0.5 / length)


def _padded(indptr: np.ndarray, indices: np.ndarray, pts: np.ndarray, half_inv: np.ndarray) -> DelaunayGraph:
    """The CSR rows ``indptr (n + 1,)``, ``indices (nnz,)`` with their ``half_inv (nnz,)``, each
    padded to a multiple of :data:`LANES` (see :class:`DelaunayGraph`)."""
    n = len(indptr) - 1
    degree = np.diff(indptr)
    padded = -(-degree // LANES) * LANES
    new_ptr = np.concatenate([[0], np.cumsum(padded)]).astype(np.int64)
    rows = np.repeat(np.arange(n), degree)
    at = new_ptr[rows] + (np.arange(len(indices)) - np.repeat(indptr[:-1], degree))
    new_idx = np.repeat(np.arange(n, dtype=np.int64), padded)
    new_idx[at] = indices
    coords = np.full((3, new_ptr[-1]), SENTINEL)
    coords[:, at] = pts[indices].T
    new_half = np.ones(new_ptr[-1])
    new_half[at] = half_inv
    return DelaunayGraph(new_ptr, new_idx, coords, new_half)


def _scan_typing(typingctx, cx, cy, cz, half_inv, lo, hi, x0, x1, x2, dj):
    """``(min_k d_k, min_k (d_k - dj) half_inv[k])`` over ``k`` in ``lo:hi`` (a whole number of
    :data:`LANES`-vectors), ``d_k = |x - (cx, cy, cz)[k]|^2``, in explicit SIMD vectors: numba
    leaves min-reductions scalar. Each lane computes exactly the scalar arithmetic (no
    contraction, no reassociation) and a minimum does not depend on order, so the results are
    bitwise those of the scalar loop."""
    sig = types.UniTuple(types.float64, 2)(cx, cy, cz, half_inv, lo, hi, x0, x1, x2, dj)

    def codegen(context, builder, signature, args):
        f64, i64, i32 = ir.DoubleType(), ir.IntType(64), ir.IntType(32)
        vec = ir.VectorType(f64, LANES)
        data = [context.make_array(signature.args[i])(context, builder, args[i]).data for i in range(4)]
        lo, hi = args[4], args[5]

        def splat(v):
            out = ir.Constant(vec, None)
            for lane in range(LANES):
                out = builder.insert_element(out, v, ir.Constant(i32, lane))
            return out

        qx, qy, qz, qd = (splat(v) for v in args[6:10])
        vmin = builder.module.declare_intrinsic(f"llvm.minnum.v{LANES}f64", (), ir.FunctionType(vec, [vec, vec]))
        smin = builder.module.declare_intrinsic("llvm.minnum.f64", (), ir.FunctionType(f64, [f64, f64]))
        entry = builder.block
        loop = builder.append_basic_block("scan.loop")
        done = builder.append_basic_block("scan.done")
        builder.branch(loop)
        builder.position_at_end(loop)
        k, best, margin = builder.phi(i64), builder.phi(vec), builder.phi(vec)
        inf = ir.Constant(vec, [float("inf")] * LANES)
        k.add_incoming(lo, entry)
        best.add_incoming(inf, entry)
        margin.add_incoming(inf, entry)
        ex, ey, ez, eh = (
            builder.load(builder.bitcast(builder.gep(p, [k], inbounds=True), vec.as_pointer()), align=8) for p in data
        )
        a, b, c = builder.fsub(qx, ex), builder.fsub(qy, ey), builder.fsub(qz, ez)
        d = builder.fadd(builder.fadd(builder.fmul(a, a), builder.fmul(b, b)), builder.fmul(c, c))
        next_best = builder.call(vmin, [best, d], fastmath=("nnan", "nsz"))
        next_margin = builder.call(vmin, [margin, builder.fmul(builder.fsub(d, qd), eh)], fastmath=("nnan", "nsz"))
        k_next = builder.add(k, ir.Constant(i64, LANES))
        k.add_incoming(k_next, loop)
        best.add_incoming(next_best, loop)
        margin.add_incoming(next_margin, loop)
        builder.cbranch(builder.icmp_signed("<", k_next, hi), loop, done)
        builder.position_at_end(done)

        def lanes_min(v):
            out = builder.extract_element(v, ir.Constant(i32, 0))
            for lane in range(1, LANES):
                out = builder.call(smin, [out, builder.extract_element(v, ir.Constant(i32, lane))])
            return out

        return context.make_tuple(builder, signature.return_type, [lanes_min(next_best), lanes_min(next_margin)])

    return sig, codegen


# Called from compiled code without the typing context; to a type checker, an untyped callable.
_scan: Any = intrinsic(_scan_typing)


# No reassociation or contraction: every distance is computed exactly as elsewhere (the walk's
# answer does not change).
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
        bd, margin = _scan(cx, cy, cz, half_inv, lo, hi, x0, x1, x2, dj)
        if not bd < dj:
            return j, dj, bd, margin
        for k in range(lo, hi):  # the first neighbour at the smallest distance
            a, b, c = x0 - cx[k], x1 - cy[k], x2 - cz[k]
            if a * a + b * b + c * c == bd:
                j = indices[k]
                break
        dj = bd


@njit(cache=True)
def uncertified(x: np.ndarray, xref: np.ndarray, margin2: np.ndarray, scale: float, todo: np.ndarray) -> int:
    """The queries of ``x (k, 3)`` that moved as far as their Voronoi margin since they were
    searched at ``xref (k, 3)`` (``margin2 (k,)``: squared margins less the safety margin, in
    units whose squares are ``scale`` times those of ``x``), in order, into ``todo``; returns
    their count. Branch-free: during ICP about half the queries fail, in no pattern a branch
    predictor learns, and a branch per query cost more than this pass."""
    count = 0
    for i in range(x.shape[0]):
        e, f, g = x[i, 0] - xref[i, 0], x[i, 1] - xref[i, 1], x[i, 2] - xref[i, 2]
        todo[count] = i
        count += 0 if (e * e + f * f + g * g) * scale < margin2[i] else 1  # moved + margin, without a root
    return count


@njit(cache=True)
def to_search(x: np.ndarray, xref: np.ndarray, margin2: np.ndarray, scale: float, fresh: bool, todo: np.ndarray) -> int:
    """The queries of a certified pass to search, in order, into ``todo``; returns their count:
    every query of a ``fresh`` pass (no certificate yet), else :func:`uncertified`."""
    if not fresh:
        return uncertified(x, xref, margin2, scale, todo)
    for i in range(x.shape[0]):
        todo[i] = i
    return x.shape[0]
