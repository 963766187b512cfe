"""Exact nearest neighbours and the protocol's ICP, compiled (numba): KD-trees
(:mod:`aw.kernels.kdtree`), Delaunay walks (:mod:`aw.kernels.delaunay`), walks through a
prediction's part clouds (:mod:`aw.kernels.partwalk`) and the ICP kernel
(:mod:`aw.kernels.icp`). They sit beneath both the evaluator (``aw_eval``, whose
:mod:`aw_eval.kernels` re-exports them) and the official preparation's geometry groups
(:mod:`aw.prepare.official_similarity`)."""
