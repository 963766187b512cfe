"""``aw_eval``: the AssemblyWorld evaluator (Appendix A.3 of the paper).

Public API (see ``docs/evaluator.md`` for a worked example):

- :class:`ProtocolSettings` – every number of the protocol;
- :func:`load_task_geometry` / :class:`TaskGeometry` – per-task clouds, divisor and equivalence
  groups, computed once and cached; ``TaskGeometry.from_points`` for given clouds;
- :func:`score` / :func:`score_batch` – one checkpoint ``(P, 7)`` / many ``(N, P, 7)``, ``mode``
  ``"exact"`` (equal to the reference) or ``"fast"`` (coarse-to-fine, agreement measured);
- :func:`chamfer`, :func:`register`, :func:`register_checkpoint`, :func:`equivalence_groups`;
- :func:`rescore_thresholds` – PA/SR at other thresholds with registration and matching fixed;
- :func:`part_diagnostics` – centroid offsets and centred CDs for failure classes;
- :func:`fracture_metrics` – the source-level fracture protocol (RE, TE, PA, CD).

:mod:`aw_eval.reference` is the plain NumPy/SciPy statement of the same protocol.

Layout, top-down: :mod:`aw_eval.scoring` (score a checkpoint) -> :mod:`aw_eval.starts`,
:mod:`aw_eval.registration`, :mod:`aw_eval.matching`, :mod:`aw_eval.metrics` (the protocol's
steps), over :mod:`aw_eval.geometry` and :mod:`aw_eval.sampling` (a task's clouds) and
:mod:`aw_eval.settings` (its numbers); the speed machinery lives beneath, in :mod:`aw_eval.kernels`.
"""

from aw_eval.chamfer import chamfer
from aw_eval.equivalence import equivalence_groups
from aw_eval.fracture import FractureMetrics, fracture_metrics
from aw_eval.geometry import TaskGeometry, default_cache_dir, load_task_geometry
from aw_eval.metrics import rescore_thresholds
from aw_eval.registration import MODES, register, register_checkpoint
from aw_eval.results import BatchScores, Registration, ScoreResult
from aw_eval.scoring import PartDiagnostics, part_diagnostics, score, score_batch
from aw_eval.settings import PROTOCOL_VERSION, ProtocolSettings

__version__ = f"0.1.0+protocol{PROTOCOL_VERSION}"

__all__ = [
    "BatchScores",
    "FractureMetrics",
    "MODES",
    "PartDiagnostics",
    "ProtocolSettings",
    "Registration",
    "ScoreResult",
    "TaskGeometry",
    "chamfer",
    "default_cache_dir",
    "equivalence_groups",
    "fracture_metrics",
    "load_task_geometry",
    "part_diagnostics",
    "register",
    "register_checkpoint",
    "rescore_thresholds",
    "score",
    "score_batch",
]
