"""Full-resolution symmetric ICP, compiled (numba), with certified warm-started neighbours.

The iteration is the protocol's (see :func:`aw_eval.reference.icp`) and gives the same numbers
up to floating-point summation order; only the nearest-neighbour search differs:

- the target's search structures are built once per task: the backward query maps the target
  points into the prediction's frame (``R^T (T - t)``) instead of building a tree of the moved
  prediction in every iteration, and searches there either the prediction's own tree and graph
  or, for a checkpoint of a task (:meth:`ICPProblem.for_assembly`), each part's baked cloud,
  whose structures are built once per task too (:mod:`aw.kernels.partwalk`);
- consecutive iterations move little, so most neighbours are *certified* unchanged without a
  search. Where the reference cloud has a Delaunay graph, the Voronoi certificate (a point
  last searched at ``x_ref`` keeps its nearest ``j`` while ``|x - x_ref|`` is below the
  distance from ``x_ref`` to the nearest face of ``j``'s Voronoi cell; see
  :mod:`aw.kernels.delaunay`), which stays wide far from the cloud; else the ball one (nearest
  ``j``, second-nearest distance ``d2``: ``j`` stays while ``|x - y_j| + |x - x_ref| < d2``).
  Checking the ball one as well where there is a graph saved 1-3% of the searches and cost
  more than they did (its roots, a branch per query);
- a point that fails both is searched again: by a walk on the Delaunay graph from its previous
  neighbour (or from the previous query's answer, when nearer), else by a warm-started KD-tree
  search (:func:`aw.kernels.kdtree.nearest2`) where Qhull gave no graph. Either way the result is
  the exact nearest neighbour (up to exact distance ties), not an approximation;
- one compiled pass per direction and iteration does the transform, the certificate or search,
  the objective and the pairs of the next Kabsch fit (no NumPy temporaries).

Arrays: ``p (n, 3)`` prediction, ``t_pts (m, 3)`` target, rotations ``(3, 3)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from aw.kernels.delaunay import DelaunayGraph, build_graph, cloud_neighbours, graph_of, no_graph, to_search, walk
from aw.kernels.kdtree import STACK, KDTree, build_tree, nearest2
from aw.kernels.partwalk import PartClouds, no_part_clouds, part_maps, parts_pass

__all__ = ["CertifiedNN", "ICPProblem", "ICPResult", "build_tree", "graph_for", "kabsch_pairs", "nearest_positions"]

# Safety margin of the certificate in normalized units (coordinates are O(1); rounding is ~1e-16).
_MARGIN = 1e-10


@njit(cache=True)
def _certified_pass(
    tree,
    graph,
    x: np.ndarray,
    cand: np.ndarray,
    xref: np.ndarray,
    slack: np.ndarray,
    fresh: bool,
    stack: np.ndarray,
    bounds: np.ndarray,
) -> int:
    """Update ``cand (k,)`` (tree positions) to the exact nearest neighbours of ``x (k, 3)``;
    returns the number of points searched. Certificate state: ``xref (k, 3)`` where each point
    was last searched, ``slack (k, 2)`` the second-nearest squared distance there (the ball
    certificate, KD-tree searches) and the square of its Voronoi margin less the safety margin
    (graph searches, -1 where none is left; see :mod:`aw.kernels.delaunay`).
    ``graph``: Delaunay graph of the tree's points in tree order (empty: KD-tree searches).

    With a graph only the Voronoi certificate is checked: the ball one saved 1-3% of the
    searches, and its three roots cost more than those searches
    (``docs/performance.md``, round 7). The certificates are checked first, then the queries
    that failed are searched, in order."""
    pts = tree[0]
    use_graph = graph[0].shape[0] > 0
    k = x.shape[0]
    todo = np.empty(k, np.int64)
    if fresh or use_graph:
        count = to_search(x, xref, slack[:, 1], 1.0, fresh, todo)
    else:
        count = 0
        for i in range(k):
            x0, x1, x2 = x[i, 0], x[i, 1], x[i, 2]
            j = cand[i]
            e, f, g = x0 - xref[i, 0], x1 - xref[i, 1], x2 - xref[i, 2]
            a, b, c = x0 - pts[j, 0], x1 - pts[j, 1], x2 - pts[j, 2]
            todo[count] = i
            ok = np.sqrt(a * a + b * b + c * c) + np.sqrt(e * e + f * f + g * g) + _MARGIN < np.sqrt(slack[i, 0])
            count += 0 if ok else 1
    prev = -1
    for q in range(count):
        i = todo[q]
        x0, x1, x2 = x[i, 0], x[i, 1], x[i, 2]
        j = prev if fresh else cand[i]  # queries come in tree order: the previous answer is close by
        if use_graph:
            if j < 0:  # the first query of a cold pass: its walk then only computes the margin
                j = nearest2(tree, x0, x1, x2, -1, stack, bounds)[0]
            elif prev >= 0 and prev != j:
                # the previous query searched (a spatial neighbour in tree order) has already
                # walked this iteration's motion: start from its answer when it is nearer
                a, b, c = x0 - pts[j, 0], x1 - pts[j, 1], x2 - pts[j, 2]
                e, f, g = x0 - pts[prev, 0], x1 - pts[prev, 1], x2 - pts[prev, 2]
                if e * e + f * f + g * g < a * a + b * b + c * c:
                    j = prev
            j, _, slack[i, 0], margin = walk(pts, graph, x0, x1, x2, j)
            margin -= _MARGIN
            slack[i, 1] = margin * margin if margin > 0.0 else -1.0
        else:
            j, _, slack[i, 0] = nearest2(tree, x0, x1, x2, j, stack, bounds)
        prev = j
        cand[i] = j
        xref[i, 0], xref[i, 1], xref[i, 2] = x0, x1, x2
    return count


class CertifiedNN:
    """Exact nearest neighbours of a moving query set ``(k, 3)`` in a fixed reference set ``(m, 3)``
    (the certificate of the module docstring; compiled)."""

    def __init__(self, ref: np.ndarray, tree: KDTree | None = None):
        self.tree = build_tree(ref) if tree is None else tree
        # the last answers, kept to start the next query from (made at the first query)
        self.cand: np.ndarray | None = None  # (k,) tree positions
        self.xref: np.ndarray | None = None  # (k, 3) the query points they answer
        self.d2: np.ndarray | None = None  # (k, 2) their two smallest squared distances
        self.n_searched = 0
        self._stack = np.empty(STACK, np.int64)
        self._bounds = np.empty(STACK)

    def query(self, x: np.ndarray) -> np.ndarray:
        """Exact nearest-neighbour rows (in the reference set's order) ``(k,)`` of ``x (k, 3)``."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        fresh = False
        if self.cand is None or self.xref is None or self.d2 is None:  # the first query
            fresh = True
            self.cand = np.zeros(len(x), np.int64)
            self.xref = np.zeros((len(x), 3))
            self.d2 = np.zeros((len(x), 2))
        self.n_searched += _certified_pass(
            tuple(self.tree), tuple(no_graph()), x, self.cand, self.xref, self.d2, fresh, self._stack, self._bounds
        )
        return self.tree.index[self.cand]


@njit(cache=True)
def _evaluate(p, t, tree_t, tree_p, gt, gp, parts, r, tr, fc, fx, fd, bc, bx, bd, fresh, xs, ys, stack, bounds, stats):
    """Objective at ``(r, tr)`` and neighbours of both directions (tree positions into ``fc``,
    ``bc``); returns ``(objective, searched)``. ``p (n, 3)``, ``t (m, 3)`` in tree order (``p`` in
    the part clouds' order when ``parts = (clouds, A, b, divisor, warm)`` has parts: the
    backward search then walks the parts' graphs, see :mod:`aw.kernels.partwalk`, adding its
    searches and walks to ``stats (2,)``)."""
    n, m = p.shape[0], t.shape[0]
    for i in range(n):
        for k in range(3):
            xs[i, k] = r[k, 0] * p[i, 0] + r[k, 1] * p[i, 1] + r[k, 2] * p[i, 2] + tr[k]
    for i in range(m):
        a, b, c = t[i, 0] - tr[0], t[i, 1] - tr[1], t[i, 2] - tr[2]
        for k in range(3):  # R^T (T - t)
            ys[i, k] = r[0, k] * a + r[1, k] * b + r[2, k] * c
    searched = _certified_pass(tree_t, gt, xs, fc, fx, fd, fresh, stack, bounds)
    if parts[0][1].shape[0] > 0:
        searched += parts_pass(parts[0], parts[1], parts[2], parts[3], ys, bc, bx, bd, fresh, parts[4], stats)
    else:
        searched += _certified_pass(tree_p, gp, ys, bc, bx, bd, fresh, stack, bounds)
    sf = 0.0
    for i in range(n):
        j = fc[i]
        a, b, c = xs[i, 0] - t[j, 0], xs[i, 1] - t[j, 1], xs[i, 2] - t[j, 2]
        sf += a * a + b * b + c * c
    sb = 0.0
    for i in range(m):
        j = bc[i]
        a, b, c = t[i, 0] - xs[j, 0], t[i, 1] - xs[j, 1], t[i, 2] - xs[j, 2]
        sb += a * a + b * b + c * c
    return sf / n + sb / m, searched


@njit(cache=True)
def kabsch_pairs(p, t, fc, bc):
    """Proper Kabsch fit of ``p`` onto ``t`` on the forward pairs ``(p_i, t_fc[i])`` and the backward
    pairs ``(p_bc[k], t_k)``, two-pass like :func:`aw_eval.reference.kabsch`: every sum runs over
    the pairs in that order (forward, then backward), in scalar accumulators (no temporaries)."""
    n, m = p.shape[0], t.shape[0]
    s0 = s1 = s2 = d0 = d1 = d2 = 0.0
    # two loops, not one with a branch per pair: that branch made an iteration's per-point cost 2-3x
    for i in range(n):
        j = fc[i]
        s0 += p[i, 0]
        s1 += p[i, 1]
        s2 += p[i, 2]
        d0 += t[j, 0]
        d1 += t[j, 1]
        d2 += t[j, 2]
    for j in range(m):
        i = bc[j]
        s0 += p[i, 0]
        s1 += p[i, 1]
        s2 += p[i, 2]
        d0 += t[j, 0]
        d1 += t[j, 1]
        d2 += t[j, 2]
    k = n + m
    cs = np.array([s0 / k, s1 / k, s2 / k])
    cd = np.array([d0 / k, d1 / k, d2 / k])
    h00 = h01 = h02 = h10 = h11 = h12 = h20 = h21 = h22 = 0.0
    for q in range(k):
        if q < n:
            i, j = q, fc[q]
        else:
            i, j = bc[q - n], q - n
        a0, a1, a2 = p[i, 0] - cs[0], p[i, 1] - cs[1], p[i, 2] - cs[2]
        b0, b1, b2 = t[j, 0] - cd[0], t[j, 1] - cd[1], t[j, 2] - cd[2]
        h00 += a0 * b0
        h01 += a0 * b1
        h02 += a0 * b2
        h10 += a1 * b0
        h11 += a1 * b1
        h12 += a1 * b2
        h20 += a2 * b0
        h21 += a2 * b1
        h22 += a2 * b2
    h = np.array([[h00, h01, h02], [h10, h11, h12], [h20, h21, h22]])
    u, _, vt = np.linalg.svd(h)
    v = vt.T
    d = 1.0 if np.linalg.det(v @ u.T) >= 0 else -1.0
    for c in range(3):
        v[c, 2] *= d
    r = v @ u.T
    return r, cd - r @ cs


@njit(cache=True, nogil=True)  # registrations run in threads (aw.pair_search.components)
def _icp(p, t, tree_t, tree_p, gt, gp, parts, r0, t0, max_iters, tol, stop_at):
    n, m = p.shape[0], t.shape[0]
    fc = np.zeros(n, np.int64)
    bc = np.zeros(m, np.int64)
    fx = np.zeros((n, 3))
    bx = np.zeros((m, 3))
    fd = np.zeros((n, 2))
    bd = np.zeros((m, 2))
    xs = np.empty((n, 3))
    ys = np.empty((m, 3))
    stack = np.empty(STACK, np.int64)
    bounds = np.empty(STACK)
    stats = np.zeros(2, np.int64)
    obj, searched = _evaluate(
        p, t, tree_t, tree_p, gt, gp, parts, r0, t0, fc, fx, fd, bc, bx, bd, True, xs, ys, stack, bounds, stats
    )
    best, best_r, best_t = obj, r0.copy(), t0.copy()
    prev = obj
    it = 0
    if obj <= stop_at:
        return best, best_r, best_t, 0, searched, stats
    while it < max_iters:
        it += 1
        r, tr = kabsch_pairs(p, t, fc, bc)
        new, s = _evaluate(
            p, t, tree_t, tree_p, gt, gp, parts, r, tr, fc, fx, fd, bc, bx, bd, False, xs, ys, stack, bounds, stats
        )
        searched += s
        if new < best:
            best, best_r, best_t = new, r, tr
        if new <= stop_at:
            break
        if prev - new < tol:
            break
        prev = new
    return best, best_r, best_t, it, searched, stats


@njit(cache=True)
def _nearest_positions(tree, graph, x):
    k = x.shape[0]
    cand = np.empty(k, np.int64)
    _certified_pass(
        tree, graph, x, cand, np.empty((k, 3)), np.empty((k, 2)), True, np.empty(STACK, np.int64), np.empty(STACK)
    )
    return cand


def nearest_positions(tree: KDTree, graph: DelaunayGraph | None, x: np.ndarray) -> np.ndarray:
    """Exact nearest neighbours (tree positions ``(k,)``) of ``x (k, 3)``: Delaunay walks, each from
    the previous query's answer (neighbours in space when ``x`` is in a spatially coherent order),
    or KD-tree searches where there is no graph."""
    x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3)
    return _nearest_positions(tuple(tree), tuple(graph or no_graph()), x)


@dataclass
class ICPResult:
    objective: float
    rotation: np.ndarray  # (3, 3)
    translation: np.ndarray  # (3,)
    iterations: int  # Kabsch fits done
    searched: int  # query points that needed a tree search (both directions)
    part_searches: int = 0  # of which backward searches through the parts' clouds (for_assembly)
    part_walks: int = 0  # the part walks those took (several per search where parts touch)


class ICPProblem:
    """Registration of one prediction ``p (n, 3)`` onto one target ``t_pts (m, 3)``.

    ``tree_t`` (target) may be shared across checkpoints of a task; ``tree_p`` is built here
    unless given (both from :func:`aw.kernels.kdtree.build_tree`). The search always certifies
    (it never changes a result). :meth:`for_assembly` searches the prediction through its parts'
    clouds instead (no structure built per checkpoint).
    """

    def __init__(
        self,
        p: np.ndarray,
        t_pts: np.ndarray,
        tree_t: KDTree | None = None,
        tree_p: KDTree | None = None,
        graph_t: DelaunayGraph | None = None,
        graph_p: DelaunayGraph | None = None,
    ):
        self.tree_t = build_tree(t_pts) if tree_t is None else tree_t
        self.tree_p = build_tree(p) if tree_p is None else tree_p
        # the kernels work in tree order; sums over all points do not depend on the order
        self._p = self.tree_p.points
        self._t = self.tree_t.points
        self._gt = tuple(graph_t or no_graph())
        self._gp = tuple(graph_p or no_graph())
        self._parts = _NO_PARTS

    @classmethod
    def for_assembly(
        cls,
        pred_parts: np.ndarray,
        poses: np.ndarray,
        divisor: float,
        clouds: PartClouds,
        t_pts: np.ndarray,
        rotations: np.ndarray,
        tree_t: KDTree | None = None,
        graph_t: DelaunayGraph | None = None,
    ) -> ICPProblem:
        """The prediction ``pred_parts (P, n, 3)`` of the poses ``(P, 7)`` with rotation matrices
        ``rotations (P, 3, 3)`` (normalized by ``divisor``), searched by walks in its parts' baked
        clouds ``clouds`` (built once per task, :func:`aw.kernels.partwalk.build_part_clouds`)
        instead of a tree of its own."""
        prob = cls.__new__(cls)
        prob.tree_t = build_tree(t_pts) if tree_t is None else tree_t
        prob.tree_p = _no_tree()
        prob._p = np.ascontiguousarray(pred_parts[clouds.part_of, clouds.rows])  # the clouds' row order
        prob._t = prob.tree_t.points
        prob._gt = tuple(graph_t or no_graph())
        prob._gp = tuple(no_graph())
        a, b = part_maps(poses, divisor, rotations)
        prob._parts = (tuple(clouds), a, b, float(divisor), np.zeros(len(a), np.int64))
        return prob

    def run(
        self, r0: np.ndarray, t0: np.ndarray, max_iters: int, tol: float, stop_at: float | None = None
    ) -> ICPResult:
        """The protocol's ICP from ``(r0, t0)``; returns the best state visited.

        ``stop_at``: return as soon as the objective is ``<= stop_at`` (for yes/no questions such
        as "is the best CD <= 1e-4?", whose answer cannot change afterwards).
        """
        r0 = np.ascontiguousarray(r0, dtype=np.float64)
        t0 = np.ascontiguousarray(t0, dtype=np.float64)
        stop = -np.inf if stop_at is None else float(stop_at)
        obj, r, t, it, searched, stats = _icp(
            self._p,
            self._t,
            tuple(self.tree_t),
            tuple(self.tree_p),
            self._gt,
            self._gp,
            self._parts,
            r0,
            t0,
            int(max_iters),
            float(tol),
            stop,
        )
        return ICPResult(float(obj), r, t, int(it), int(searched), int(stats[0]), int(stats[1]))


_NO_PARTS = (tuple(no_part_clouds()), np.zeros((0, 3, 3)), np.zeros((0, 3)), 1.0, np.zeros(0, np.int64))
_NO_TREE: list = []


def _no_tree() -> KDTree:
    """A one-point tree standing in for the prediction's when the part clouds are searched."""
    if not _NO_TREE:
        _NO_TREE.append(build_tree(np.zeros((1, 3))))
    return _NO_TREE[0]


def graph_for(tree: KDTree, cloud: np.ndarray | None = None) -> DelaunayGraph | None:
    """Delaunay graph of a tree's points in tree order (``None`` where Qhull cannot build one).
    ``cloud (n, 3)``: a similar image of the tree's points, row for row (``tree.points[k]`` is the
    image of ``cloud[tree.index[k]]``), whose Qhull run is shared by every frame it is searched in
    (:func:`aw.kernels.delaunay.cloud_neighbours`)."""
    if cloud is None:
        return build_graph(tree.points)
    found = cloud_neighbours(cloud)
    return None if found is None else graph_of(found, tree.points, tree.index)
