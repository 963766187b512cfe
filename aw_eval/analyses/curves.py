"""Quality curves over normalized interaction time and absolute time budgets
(``fig:behavior`` (d), ``fig:budget_all``), and PA decreases between checkpoints.

The score at a time point is that of the state after the last operation completed by then: the
initial state applies before the first operation, the final state persists after the episode
ended, and nothing is interpolated between checkpoints. Normalized time runs from the first to
the last environment call (as the activity bins); at 1 the final state is used, so terminal
values agree with the result tables. An absolute budget at or after the episode's end also
gives the final state. Unscored runs count 0 everywhere; a run with only ``final.json`` (no
trajectory) contributes its final score at every point.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from aw_eval.study.model import RunScore
from aw_eval.study.table import Study

__all__ = [
    "NORMALIZED_POINTS",
    "BUDGET_MINUTES",
    "state_index",
    "normalized_times",
    "normalized_states",
    "normalized_values",
    "budget_values",
    "quality_curves",
    "pa_decreases",
]

NORMALIZED_POINTS = tuple(round(0.1 * i, 10) for i in range(11))
BUDGET_MINUTES = (0, 1, 2, 5, 10, 15, 20, 30, 45, 60)


def state_index(ck_t: np.ndarray, t: float) -> int:
    """Index of the checkpoint in force at time ``t``: the last one whose operation (and every
    earlier one) completed by ``t``; 0 (the initial state) if none has."""
    times = np.maximum.accumulate(np.asarray(ck_t[1:], dtype=np.float64)) if len(ck_t) > 1 else np.zeros(0)
    return int(np.searchsorted(times, t, side="right"))


def _values_at(r: RunScore, times: Sequence[float | None], metric: str) -> np.ndarray:
    """``metric`` of run ``r`` at each time (None = the final state)."""
    final = float(getattr(r, metric))
    if not r.scored:
        return np.zeros(len(times))
    ck = getattr(r, "ck_" + metric)
    out = np.empty(len(times))
    for i, t in enumerate(times):
        if t is None or len(ck) == 0:
            out[i] = final
        else:
            out[i] = float(ck[state_index(r.ck_t, t)])
    return out


def normalized_times(r: RunScore, points: Sequence[float] = NORMALIZED_POINTS) -> list[float | None]:
    """Seconds of one run at normalized times ``points`` (None at 1: the final state)."""
    if len(r.call_t):
        t0, t1 = float(r.call_t.min()), float(r.call_t.max())
    else:
        t0 = t1 = 0.0
    return [None if u >= 1 else t0 + u * (t1 - t0) for u in points]


def normalized_states(r: RunScore, points: Sequence[float] = NORMALIZED_POINTS) -> list[int | None]:
    """The checkpoint in force at each normalized time (None: the final state), as
    :func:`normalized_values` reads its scores."""
    no_checkpoints = len(r.ck_pa) == 0
    return [None if t is None or no_checkpoints else state_index(r.ck_t, t) for t in normalized_times(r, points)]


def normalized_values(r: RunScore, metric: str, points: Sequence[float] = NORMALIZED_POINTS) -> np.ndarray:
    """``metric`` of one run at normalized times ``points`` (1 = the final state)."""
    return _values_at(r, normalized_times(r, points), metric)


def budget_values(r: RunScore, metric: str, minutes: Sequence[float] = BUDGET_MINUTES) -> np.ndarray:
    """``metric`` of one run truncated at absolute budgets (minutes since start_episode)."""
    times = [None if (not r.has_trajectory or 60.0 * m >= r.end_t) else 60.0 * m for m in minutes]
    return _values_at(r, times, metric)


def quality_curves(
    study: Study, points: Sequence[float] = NORMALIZED_POINTS, minutes: Sequence[float] = BUDGET_MINUTES
) -> dict[str, Any]:
    """Per system, eq.-3 PA/SR (percent) over normalized time and budgets, the final values, and
    how many episodes still changed poses after the largest budget."""
    d = study.design
    out: dict[str, Any] = {"points": list(points), "budget_minutes": list(minutes), "systems": {}}
    if d is None:
        return out
    last = 60.0 * max(minutes) if minutes else 0.0
    for s in study.systems:
        runs = [study.score(s, t) for t in d.task_ids]
        row: dict[str, Any] = {}
        for m in ("pa", "sr"):
            norm = np.stack([normalized_values(r, m, points) for r in runs])
            bud = np.stack([budget_values(r, m, minutes) for r in runs])
            row[m] = {
                "normalized": (100 * d.weights @ norm).tolist(),
                "budget": (100 * d.weights @ bud).tolist(),
                "final": 100 * float(d.weights @ np.array([getattr(r, m) for r in runs])),
            }
        row["edits_after_last_budget"] = int(
            sum(1 for r in runs if r.scored and len(r.ck_t) > 1 and r.ck_t[1:].max() > last)
        )
        out["systems"][s] = row
    return out


def pa_decreases(study: Study) -> dict[str, Any]:
    """Per system: decreases of PA between consecutive checkpoints; how many change at least one
    matched assignment; how many persist with the earlier checkpoint's registration held fixed
    (re-matched), and with both its registration and its matching held fixed."""
    out = {}
    for s in study.systems:
        n = {"decreases": 0, "with_assignment_change": 0, "persist_alignment_fixed": 0, "persist_both_fixed": 0}
        for t in study.original_ids:
            r = study.score(s, t)
            if not r.scored or r.n_checkpoints < 2:
                continue
            dec = np.flatnonzero(np.diff(r.ck_pa) < -1e-12)
            n["decreases"] += len(dec)
            if len(r.ck_drop_index) == len(dec):  # diagnosed by the scoring job
                n["with_assignment_change"] += int(r.ck_drop_assignment_changed.sum())
                n["persist_alignment_fixed"] += int(r.ck_drop_persist_alignment.sum())
                n["persist_both_fixed"] += int(r.ck_drop_persist_both.sum())
            elif r.ck_assignment.size:  # no diagnosis saved: assignment changes only
                n["with_assignment_change"] += int(
                    np.sum(np.any(r.ck_assignment[dec + 1] != r.ck_assignment[dec], axis=1))
                )
        out[s] = n
    return out
