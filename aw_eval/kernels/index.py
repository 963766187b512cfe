"""A task's search structures, built once per task and process: the narrow interface through
which the protocol asks for nearest neighbours and ICP problems.

``TaskIndex`` holds the normalized target (``(P, n, 3)`` parts, ``(P n, 3)`` joined) with the
joined target's KD-tree, and every part's cloud in its baked frame (which a checkpoint only moves
rigidly) with its KD-tree and Delaunay graph, joined for walks through a posed assembly
(:mod:`aw.kernels.partwalk`). A part-to-part distance walks the baked graphs both ways (a
target part is its baked cloud posed), so no target part has structures of its own, and a
part's Qhull run is shared with the equivalence search. The joined target's Delaunay graph
(``graph_t``, one Qhull run over all the points) is built on the first checkpoint's ICP: a
walk through the target's parts would spare it, but visits every part's box per searched
query and took twice the CPU per checkpoint at 100 parts. Nothing here depends on a checkpoint.
"""

from __future__ import annotations

import numpy as np

from aw.kernels.icp import ICPProblem, graph_for, nearest_positions
from aw.kernels.kdtree import build_tree
from aw.kernels.partwalk import build_part_clouds, part_maps
from aw_eval.kernels.leafbox import LeafBoxes, build_leaf_boxes, build_part_leaves

__all__ = ["TaskIndex", "mean_squared_norm"]

_UNBUILT = object()


class TaskIndex:
    """Search structures of one task: ``target_parts (P, n, 3)`` normalized target points,
    ``clouds (P, n, 3)`` the parts' samples in their baked frames (unnormalized), and the target
    ``poses (P, 7)``, their ``rotations (P, 3, 3)`` and ``divisor`` with ``target_parts = (R
    clouds + t) / divisor`` (needed by :meth:`part_cd`)."""

    def __init__(
        self,
        target_parts: np.ndarray,
        clouds: np.ndarray,
        poses: np.ndarray | None = None,
        divisor: float | None = None,
        rotations: np.ndarray | None = None,
    ):
        if poses is not None and (divisor is None or rotations is None):
            raise ValueError("TaskIndex: the target poses come with their divisor and rotations")
        self.target_parts = target_parts
        self.target = np.ascontiguousarray(target_parts.reshape(-1, 3))  # (P n, 3)
        self.tree_t = build_tree(self.target)
        self._clouds = clouds
        self._poses = None if poses is None else np.asarray(poses, dtype=np.float64)
        self._rotations = rotations
        self._divisor = divisor
        self._graph_t = _UNBUILT
        self._parts_built = False
        self._medium: dict[int, tuple] = {}
        self._leaves: tuple[float, LeafBoxes, LeafBoxes] | None = None

    @property
    def graph_t(self):
        """Delaunay graph of the joined target in tree order (``None`` where Qhull cannot)."""
        if self._graph_t is _UNBUILT:
            self._graph_t = graph_for(self.tree_t)
        return self._graph_t

    def _build_parts(self) -> None:
        if self._parts_built:
            return
        tp = self.target_parts
        self.target_boxes = (tp.min(axis=1), tp.max(axis=1))  # ((P, 3), (P, 3))
        self.target_means = tp.mean(axis=1)  # (P, 3)
        self.baked = [(tree, graph_for(tree, c)) for tree, c in ((build_tree(c), c) for c in self._clouds)]
        self.part_clouds = build_part_clouds(self.baked)  # None: a part has no graph
        # normalized target -> baked frames (c = A y + b), for part_cd's forward searches
        self.target_maps = None
        if self._poses is not None and self._divisor is not None and self._rotations is not None:
            self.target_maps = part_maps(self._poses, self._divisor, self._rotations)
        self._parts_built = True

    def assembly_problem(
        self, poses: np.ndarray, rotations: np.ndarray, pred_parts: np.ndarray, divisor: float
    ) -> ICPProblem:
        """Full-resolution ICP of a checkpoint (``poses (P, 7)``, their ``rotations (P, 3, 3)``,
        ``pred_parts (P, n, 3)`` normalized) onto the target. The backward search walks the
        parts' baked clouds: nothing is built per checkpoint. Where a part has no Delaunay graph,
        the prediction gets its own tree and graph (same results, slower)."""
        self._build_parts()
        if self.part_clouds is not None:
            return ICPProblem.for_assembly(
                pred_parts,
                poses,
                divisor,
                self.part_clouds,
                self.target,
                rotations,
                tree_t=self.tree_t,
                graph_t=self.graph_t,
            )
        return self.own_problem(pred_parts)[0]

    def own_problem(self, pred_parts: np.ndarray) -> tuple[ICPProblem, bool]:
        """ICP of ``pred_parts (P, n, 3)`` searched through its own KD-tree and Delaunay graph
        (built here, per checkpoint); the flag says whether Qhull gave a graph."""
        tree_p = build_tree(pred_parts.reshape(-1, 3))
        graph_p = graph_for(tree_p)
        prob = ICPProblem(
            tree_p.points, self.target, tree_t=self.tree_t, tree_p=tree_p, graph_t=self.graph_t, graph_p=graph_p
        )
        return prob, graph_p is not None

    def medium_problem(self, pred_parts: np.ndarray, m: int) -> ICPProblem:
        """ICP of the first ``m`` samples of every part of ``pred_parts (P, n, 3)`` onto the same
        prefix of the target's parts (the target side's tree and graph built once per ``m``)."""
        if m not in self._medium:
            pts = np.ascontiguousarray(self.target_parts[:, :m].reshape(-1, 3))
            tree = build_tree(pts)
            self._medium[m] = (pts, tree, graph_for(tree))
        pts, tree, graph = self._medium[m]
        return ICPProblem(np.ascontiguousarray(pred_parts[:, :m].reshape(-1, 3)), pts, tree_t=tree, graph_t=graph)

    def part_cd(self, moved_parts: np.ndarray, to_baked: tuple, i: int, j: int) -> float:
        """CD(registered pred part ``i``, target part ``j``) with squared distances from normalized
        coordinates, as the reference computes them. Forward: the moved points mapped into part
        ``j``'s baked frame by the target pose's map, searched in that baked cloud's tree and graph
        (target part ``j`` is that cloud posed); backward: the target points mapped into part
        ``i``'s baked frame by ``to_baked = (A (P, 3, 3), b (P, 3))`` (``c = A y + b``), searched in
        its baked cloud's tree and graph. Needs the target poses."""
        self._build_parts()
        if self.target_maps is None:
            raise ValueError("TaskIndex.part_cd needs the target poses and divisor")
        (tree_j, graph_j), (tree_i, graph_i) = self.baked[j], self.baked[i]
        # queries in their own trees' order: consecutive queries are neighbours in space, so each
        # walk starts next to its answer (FPS order would jump across the part)
        x, y = moved_parts[i][tree_i.index], self.target_parts[j][tree_j.index]
        ta, tb = self.target_maps
        fwd = nearest_positions(tree_j, graph_j, x @ ta[j].T + tb[j])  # tree positions of cloud j = rows of y
        a, b = to_baked
        bwd = nearest_positions(tree_i, graph_i, y @ a[i].T + b[i])  # tree positions of part i = rows of x
        return mean_squared_norm(x - y[fwd]) + mean_squared_norm(y - x[bwd])

    def part_leaves(self, divisor: float) -> tuple[LeafBoxes, LeafBoxes]:
        """``(target, baked)``: :class:`aw_eval.kernels.leafbox.LeafBoxes` of the joined target (one
        cloud) and of the parts' baked clouds over ``divisor`` (what a checkpoint moves rigidly into
        the normalized prediction), for the jax backend; built once per task (milliseconds)."""
        key = float(divisor)
        if self._leaves is None or self._leaves[0] != key:
            self._leaves = (key, build_leaf_boxes(self.target), build_part_leaves(self._clouds / key))
        return self._leaves[1], self._leaves[2]

    def part_bounds(self) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
        """``(means (P, 3), (box lows (P, 3), box highs (P, 3)))`` of the target parts."""
        self._build_parts()
        return self.target_means, self.target_boxes


def mean_squared_norm(d: np.ndarray) -> float:
    """``mean(sum(d * d, axis=1))`` of ``d (k, 3)``, the same sums in the same order (each row's
    ``(d0^2 + d1^2) + d2^2``, then NumPy's mean) without the slow short-axis reduction."""
    s = d[:, 0] * d[:, 0]
    s += d[:, 1] * d[:, 1]
    s += d[:, 2] * d[:, 2]
    return float(np.mean(s))
