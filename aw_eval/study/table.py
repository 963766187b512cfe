"""The in-memory study: suite entries, systems, one record per (system, task), task facts.

Everything the statistics, analyses and reports read goes through :class:`Study`, which can be
built from cached results (``aw-score``) or directly from :class:`RunScore` objects (tests).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aw.formats import RunInfo, SuiteEntry
from aw_eval.stats import Design, TaskMeta
from aw_eval.study.model import RunScore, TaskFacts

__all__ = ["RunRecord", "Study", "task_meta", "METRICS"]

METRICS = ("pa", "sr", "sra", "scd")


@dataclass
class RunRecord:
    """A run's scores plus its ``run.json`` (``info``; None when absent or unreadable).
    ``running``: who was still recording the run when it was scored (``aw.runlock``), else None."""

    score: RunScore
    info: RunInfo | None = None
    info_problem: str | None = None
    run_dir: Path | None = None
    running: str | None = None


def task_meta(e: SuiteEntry) -> TaskMeta:
    return TaskMeta(e.task_id, e.source, e.condition, e.object_id, e.weight, e.category, e.n_parts)


@dataclass
class Study:
    """A scored study.

    Attributes:
        entries: every manifest entry (originals and robustness variants).
        systems: system names, sorted.
        runs: ``(system, task_id) -> RunRecord`` for every system and every suite task (missing
            runs included, with status ``missing``).
        facts: ``task_id -> TaskFacts`` for tasks whose geometry was loaded.
        unknown_runs: runs found for tasks that are not in the suite (reported, ignored).
    """

    suite_name: str
    entries: list[SuiteEntry]
    systems: list[str]
    runs: dict[tuple[str, str], RunRecord]
    facts: dict[str, TaskFacts] = field(default_factory=dict)
    unknown_runs: list[dict[str, Any]] = field(default_factory=list)
    settings: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._entry = {e.task_id: e for e in self.entries}
        originals = [e for e in self.entries if e.variant == "original"]
        self.design = Design.from_tasks([task_meta(e) for e in originals]) if originals else None

    def entry(self, task_id: str) -> SuiteEntry:
        return self._entry[task_id]

    @property
    def original_ids(self) -> list[str]:
        return self.design.task_ids if self.design is not None else []

    def record(self, system: str, task_id: str) -> RunRecord:
        return self.runs[(system, task_id)]

    def score(self, system: str, task_id: str) -> RunScore:
        return self.runs[(system, task_id)].score

    def values(self, metric: str, task_ids: Sequence[str] | None = None) -> np.ndarray:
        """``(S, T)`` final-state values of ``metric`` (pa, sr, sra as fractions; scd raw, NaN
        where not scored) over ``task_ids`` (default: the design's original tasks)."""
        if metric not in METRICS:
            raise ValueError(f"unknown metric {metric!r}; expected one of {METRICS}")
        ids = self.original_ids if task_ids is None else list(task_ids)
        out = np.empty((len(self.systems), len(ids)))
        for i, s in enumerate(self.systems):
            for j, t in enumerate(ids):
                out[i, j] = getattr(self.runs[(s, t)].score, metric)
        return out

    def n_parts(self, task_id: str) -> int:
        f = self.facts.get(task_id)
        return f.n_parts if f is not None else self.entry(task_id).n_parts
