"""Batch rescoring of whole studies: suite + runs of many systems -> cached per-run scores ->
an in-memory :class:`Study` for the statistics, analyses and reports.

- :mod:`~aw_eval.study.episode`: a recorded run as arrays (checkpoint poses, final state, calls,
  edit magnitudes);
- :mod:`~aw_eval.study.job`: the pure per-task job (:func:`score_task`);
- :mod:`~aw_eval.study.cache`: the resumable cache keyed by input hashes;
- :mod:`~aw_eval.study.runner`: discovery, dispatch (in-process, process pool, Dask) and assembly;
- :mod:`~aw_eval.study.table`: the :class:`Study` container;
- :mod:`~aw_eval.study.model`: :class:`RunScore` / :class:`TaskFacts` and their ``.npz`` form.
"""

from aw_eval.study.episode import EpisodeArrays, RunUnreadable, call_kind, edit_magnitudes, read_episode
from aw_eval.study.job import RunRequest, ScoreSettings, TaskJob, TaskOutput, score_task
from aw_eval.study.model import STATUS_MISSING, STATUS_SCORED, STATUS_UNREADABLE, RunScore, TaskFacts
from aw_eval.study.runner import ScoreStats, ScoringFailed, StudyError, discover_runs, score_study
from aw_eval.study.table import RunRecord, Study

__all__ = [
    "EpisodeArrays",
    "RunRecord",
    "RunRequest",
    "RunScore",
    "RunUnreadable",
    "STATUS_MISSING",
    "STATUS_SCORED",
    "STATUS_UNREADABLE",
    "ScoreSettings",
    "ScoreStats",
    "Study",
    "ScoringFailed",
    "StudyError",
    "TaskFacts",
    "TaskJob",
    "TaskOutput",
    "call_kind",
    "discover_runs",
    "edit_magnitudes",
    "read_episode",
    "score_study",
    "score_task",
]
