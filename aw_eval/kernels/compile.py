"""Compile (or load from numba's on-disk cache) every kernel once, before scoring."""

from __future__ import annotations

import numpy as np

from aw.kernels.icp import CertifiedNN, ICPProblem, build_tree, graph_for, nearest_positions
from aw.kernels.partwalk import build_part_clouds
from aw.rotation_bound import compile_search
from aw_eval.kernels.fast import coarse_icp
from aw_eval.kernels.fps import fps_batch

__all__ = ["compile_kernels"]

_COMPILED = False


def compile_kernels() -> None:
    """Run every kernel of the evaluator on tiny inputs, so that scoring processes start warm
    (numba caches compiled kernels beside their modules), the equivalence search's rotation
    bound included. The install step runs it once; later calls in the same process return at
    once."""
    global _COMPILED
    if _COMPILED:
        return
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(40, 3)), rng.normal(size=(30, 3))
    ta, tb = build_tree(a), build_tree(b)
    ta.query(b)
    CertifiedNN(a, ta).query(b)
    nearest_positions(ta, graph_for(ta), b)
    nearest_positions(ta, None, b)
    ICPProblem(a, b, tree_t=tb, tree_p=ta).run(np.eye(3), np.zeros(3), 3, 1e-9, stop_at=1e-4)
    ICPProblem(a, b, tree_t=tb, tree_p=ta, graph_t=graph_for(tb), graph_p=graph_for(ta)).run(
        np.eye(3), np.zeros(3), 3, 1e-9
    )
    parts = rng.normal(size=(2, 20, 3))
    trees = [build_tree(c) for c in parts]
    clouds = build_part_clouds([(tree, graph_for(tree)) for tree in trees])
    if clouds is None:  # Qhull triangulates these random clouds; a failure here is a broken install
        raise RuntimeError("compile_kernels: no Delaunay graph for the warm-up clouds")
    poses = np.array([[0.1, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], [0.0, 0.2, 0.0, 0.0, 1.0, 0.0, 0.0]])
    turns = np.array([np.eye(3), np.diag([1.0, -1.0, -1.0])])  # the poses' rotations: identity, half turn about x
    ICPProblem.for_assembly(parts, poses, 1.0, clouds, b, turns, tree_t=tb, graph_t=graph_for(tb)).run(
        np.eye(3), np.zeros(3), 3, 1e-9
    )
    coarse_icp(a.reshape(2, 20, 3), b[:20].reshape(2, 10, 3), np.eye(3)[None], np.zeros((1, 3)), 8, 3, 1e-9)
    fps_batch(rng.normal(size=(2, 50, 3)), 10)
    compile_search()
    _COMPILED = True
