"""The evaluator's speed machinery, beneath the protocol modules of :mod:`aw_eval`.

The protocol asks two things of it, and only through the names exported here:

- **nearest neighbours** in fixed clouds: :class:`TaskIndex` (a task's search structures, built
  once: its :meth:`~TaskIndex.part_cd` is the exact part-to-part Chamfer distance), and
  :func:`build_tree` / :func:`graph_for` for clouds of one's own;
- **farthest-point samples** of many clouds at once: :func:`fps_batch` (compiled, the protocol's
  indices);
- **ICP from many starts**: :class:`ICPProblem` (the protocol's ICP rule from one start, with
  exact certified neighbours; :meth:`TaskIndex.assembly_problem` builds one for a checkpoint)
  and :func:`coarse_to_fine` (``fast`` mode's pruning of starts).

Beneath it, in :mod:`aw.kernels` (shared with the official preparation's geometry groups):
compiled KD-trees (``kdtree``), Delaunay walks with Voronoi certificates (``delaunay``), walks
through a posed assembly's parts (``partwalk``) and the fused ICP kernel (``icp``). Here: the
coarse stage (``fast``), the task's index (``index``); and their XLA counterpart for accelerators
(``jax_icp``: the same ICP batched over checkpoints x starts, its neighbours from fixed-shape
per-query leaf-box certificates of ``leafbox``, exact). Nothing here decides what is scored: every result is
the protocol's (``fast`` excepted, whose agreement is measured).
"""

from aw.kernels.icp import ICPProblem, ICPResult, build_tree, graph_for
from aw_eval.kernels.compile import compile_kernels
from aw_eval.kernels.fast import FastSettings, coarse_to_fine, fast_settings, same_basin
from aw_eval.kernels.fps import fps_batch
from aw_eval.kernels.index import TaskIndex, mean_squared_norm
from aw_eval.kernels.jax_icp import accelerator_present, icp_batch, part_cd_batch

__all__ = [
    "FastSettings",
    "fast_settings",
    "ICPProblem",
    "ICPResult",
    "TaskIndex",
    "accelerator_present",
    "build_tree",
    "coarse_to_fine",
    "compile_kernels",
    "fps_batch",
    "graph_for",
    "icp_batch",
    "mean_squared_norm",
    "part_cd_batch",
    "same_basin",
]
