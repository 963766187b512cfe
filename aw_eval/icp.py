"""Full-resolution symmetric ICP with KD-trees built once and certified warm-started neighbours.

The iteration is the protocol's (see :func:`aw_eval.reference.icp`) and gives the same numbers;
only the nearest-neighbour search differs:

- the target tree is built once per task, the prediction tree once per checkpoint: the
  backward query maps the target points into the prediction's frame (``R^T (T - t)``) instead
  of building a tree of the moved prediction in every iteration;
- consecutive iterations move little, so most neighbours are *certified* unchanged without a
  search: if a query point was last searched exactly at ``x_ref``, where its nearest neighbour
  was ``j`` and its second-nearest distance ``d2``, then at a new position ``x`` every other
  reference point is at least ``d2 - |x - x_ref|`` away, so ``j`` is still the nearest whenever
  ``|x - y_j| < d2 - |x - x_ref|``. Only the points that fail this test are searched again
  (with ``k = 2``, which renews ``x_ref`` and ``d2``). The result is the exact nearest
  neighbour (up to exact distance ties), not an approximation.

Arrays: ``p (n, 3)`` prediction, ``t_pts (m, 3)`` target, rotations ``(3, 3)``.
"""

from __future__ import annotations

import ctypes
import glob
import os
from dataclasses import dataclass

import numpy as np
import pykdtree
from pykdtree.kdtree import KDTree

from aw_eval.reference import kabsch

__all__ = ["CertifiedNN", "ICPProblem", "ICPResult", "build_tree", "limit_kdtree_threads"]

# Safety margin of the certificate in normalized units (coordinates are O(1); rounding is ~1e-16).
_MARGIN = 1e-10


# Below this many query points a plain search per iteration is cheaper than certifying.
_CERTIFY_MIN = 3000


def limit_kdtree_threads(n: int | None = None) -> bool:
    """Set the OpenMP thread count of pykdtree's bundled libgomp (default ``$AW_KDTREE_THREADS``
    or 1). Queries here are small and many: thread start-up costs more than it saves, and
    throughput comes from one process per core instead. Returns False if the library is absent."""
    n = int(os.environ.get("AW_KDTREE_THREADS", "1")) if n is None else int(n)
    libs = glob.glob(os.path.join(os.path.dirname(pykdtree.__file__) + ".libs", "libgomp*"))
    try:
        lib = ctypes.CDLL(libs[0]) if libs else ctypes.CDLL("libgomp.so.1")
        lib.omp_set_num_threads(max(1, n))
        return True
    except (OSError, AttributeError):
        return False


limit_kdtree_threads()


def build_tree(points: np.ndarray) -> KDTree:
    """A KD-tree (pykdtree) of ``points (n, 3)`` float64 (C-contiguous copy kept by the tree)."""
    return KDTree(np.ascontiguousarray(points, dtype=np.float64), leafsize=16)


class CertifiedNN:
    """Nearest neighbours of a moving query set ``(k, 3)`` in a fixed reference set ``(m, 3)``.

    Each searched point keeps its ``K`` nearest candidates at the search position ``x_ref`` and
    the ``K``-th distance ``dK``. At a new position ``x``, every non-candidate is at least
    ``dK - |x - x_ref|`` away, so the best candidate is the nearest neighbour whenever its
    distance is below that bound; only the points failing the test are searched again.
    """

    __slots__ = ("ref", "tree", "k", "cand", "xref", "dk", "n_searched")

    def __init__(self, ref: np.ndarray, tree: KDTree, k: int = 2, certify: bool = True):
        self.ref = ref
        self.tree = tree
        self.k = int(min(k, len(ref))) if certify else 1
        self.cand = None
        self.xref = None
        self.dk = None
        self.n_searched = 0

    def _search(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d, i = self.tree.query(q, k=self.k)
        i = i.reshape(len(q), self.k).astype(np.int64)
        d = d.reshape(len(q), self.k)
        # With every reference point a candidate nothing lies outside: the bound is infinite.
        dk = d[:, -1] if self.k < len(self.ref) else np.full(len(q), np.inf)
        return i, dk

    def query(self, x: np.ndarray) -> np.ndarray:
        """Exact nearest-neighbour indices ``(k,)`` of the rows of ``x (k, 3)``."""
        if self.k == 1:  # no certificate: a plain search
            self.n_searched += len(x)
            _, i = self.tree.query(x, k=1)
            return i.reshape(-1).astype(np.int64)
        if self.cand is None:
            self.cand, self.dk = self._search(x)
            self.xref = x.copy()
            self.n_searched += len(x)
            return self.cand[:, 0].copy()
        diff = x - self.xref
        move = np.sqrt(np.einsum("ij,ij->i", diff, diff))
        cur = x[:, None, :] - self.ref[self.cand]  # (k, K, 3)
        dist = np.einsum("ijk,ijk->ij", cur, cur)
        arg = np.argmin(dist, axis=1)
        rows = np.arange(len(x))
        dmin = np.sqrt(dist[rows, arg])
        idx = self.cand[rows, arg]
        bad = np.flatnonzero(dmin + move + _MARGIN >= self.dk)
        if bad.size:
            xb = x[bad]
            i, dk = self._search(xb)
            self.cand[bad] = i
            self.dk[bad] = dk
            self.xref[bad] = xb
            idx[bad] = i[:, 0]
            self.n_searched += bad.size
        return idx


@dataclass
class ICPResult:
    objective: float
    rotation: np.ndarray  # (3, 3)
    translation: np.ndarray  # (3,)
    iterations: int  # Kabsch fits done
    searched: int  # query points that needed a tree search (both directions)


class ICPProblem:
    """Registration of one prediction ``p (n, 3)`` onto one target ``t_pts (m, 3)``.

    ``tree_t`` (target) may be shared across checkpoints of a task; ``tree_p`` is built here
    unless given. ``certify``: use certified warm starts (default: when a side has at least
    3000 points; below that a plain search per iteration is cheaper). Results are the same.
    """

    def __init__(self, p: np.ndarray, t_pts: np.ndarray, tree_t: KDTree | None = None, tree_p: KDTree | None = None,
                 certify: bool | None = None):
        self.certify = certify
        self.p = np.ascontiguousarray(p, dtype=np.float64)
        self.t = np.ascontiguousarray(t_pts, dtype=np.float64)
        self.tree_t = build_tree(self.t) if tree_t is None else tree_t
        self.tree_p = build_tree(self.p) if tree_p is None else tree_p

    def _evaluate(self, fwd: CertifiedNN, bwd: CertifiedNN, r: np.ndarray, t: np.ndarray):
        # Same arithmetic as the reference objective: x = p R^T + t, squared differences.
        x = self.p @ r.T + t
        f = fwd.query(x)
        b = bwd.query((self.t - t) @ r)  # R^T (T - t), row form
        df = x - self.t[f]
        db = self.t - x[b]
        obj = float(np.sum(df**2, axis=1).mean() + np.sum(db**2, axis=1).mean())
        return obj, f, b

    def run(self, r0: np.ndarray, t0: np.ndarray, max_iters: int, tol: float, stop_at: float | None = None) -> ICPResult:
        """The protocol's ICP from ``(r0, t0)``; returns the best state visited.

        ``stop_at``: return as soon as the objective is ``<= stop_at`` (for yes/no questions such
        as "is the best CD <= 1e-4?", whose answer cannot change afterwards).
        """
        auto = self.certify is None
        fwd = CertifiedNN(self.t, self.tree_t, certify=len(self.p) >= _CERTIFY_MIN if auto else self.certify)
        bwd = CertifiedNN(self.p, self.tree_p, certify=len(self.t) >= _CERTIFY_MIN if auto else self.certify)
        obj, f, b = self._evaluate(fwd, bwd, r0, t0)
        best = (obj, r0, t0)
        prev = obj
        it = 0
        if stop_at is not None and obj <= stop_at:
            return ICPResult(obj, r0, t0, 0, fwd.n_searched + bwd.n_searched)
        for it in range(1, max_iters + 1):
            src = np.concatenate([self.p, self.p[b]])
            dst = np.concatenate([self.t[f], self.t])
            r, t = kabsch(src, dst)
            new, f, b = self._evaluate(fwd, bwd, r, t)
            if new < best[0]:
                best = (new, r, t)
            if stop_at is not None and new <= stop_at:
                break
            if prev - new < tol:
                break
            prev = new
        return ICPResult(best[0], best[1], best[2], it, fwd.n_searched + bwd.n_searched)
