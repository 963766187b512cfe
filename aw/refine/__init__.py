"""Geometric refiners: given a task's fragments (never its targets) and optional initial poses,
return a pose per part, the anchor (the part with the most shared samples) kept where it is.

- :mod:`aw.refine.base`: the request, the checks every answer passes, :class:`RefinerError`.
- :mod:`aw.refine.exchange`: the JSON files of the external-command interface.
- :mod:`aw.refine.plugins`: finding a refiner (built in, a ``assemblyworld.refiners`` entry
  point, or an external command) and running it in a child process with a time limit.
- :mod:`aw.refine.classical`: pairwise fracture-surface registration, no model weights.
- :mod:`aw.refine.runs`: refining a suite's tasks (from their layout or a run's final state)
  into run directories.

``aw-run``'s refiner options and the four-arm bidirectional study, which run agents and refiners
side by side, sit one floor up, in :mod:`aw.runner.refiner_cli` and :mod:`aw.runner.refinement_study`.
"""

from aw.refine.base import RefineRequest, RefinerError, anchor_index, check_poses

__all__ = ["RefineRequest", "RefinerError", "anchor_index", "check_poses"]
