"""Quality at normalized checkpoints and absolute budgets: no interpolation, final persists."""

from __future__ import annotations

import numpy as np
import pytest

from aw_eval.analyses.curves import budget_values, normalized_values, pa_decreases, quality_curves, state_index
from aw_eval.study import RunScore
from tests.aw_eval.score_helpers import make_study, paper_entries, run_from_errors


def _run() -> RunScore:
    r = run_from_errors("A", "t", [0.0] * 4)  # final PA 1
    r.ck_t = np.array([0.0, 10.0, 20.0, 30.0])
    r.ck_pa = np.array([0.0, 0.25, 0.5, 0.75])
    r.ck_sr = np.zeros(4)
    r.ck_seq = np.arange(4)
    r.call_t = np.array([5.0, 10.0, 20.0, 30.0, 40.0])
    r.end_t = 50.0
    return r


def test_state_index_uses_completed_operations():
    t = np.array([0.0, 10.0, 20.0])
    assert [state_index(t, x) for x in (-1, 0, 9.99, 10, 25)] == [0, 0, 0, 1, 2]
    # a clock that runs backwards: the second op is not complete before the first
    assert state_index(np.array([0.0, 10.0, 5.0, 30.0]), 7.0) == 0


def test_normalized_points():
    v = normalized_values(_run(), "pa", [0.0, 0.2, 0.5, 0.9, 1.0])
    assert v.tolist() == [0.0, 0.25, 0.5, 0.75, 1.0]  # 1 is the final state (final.json)


def test_budgets_truncate_and_final_persists():
    v = budget_values(_run(), "pa", [0, 10 / 60, 0.5, 1.0])
    assert v.tolist() == [0.0, 0.25, 0.75, 1.0]  # 60 s is after the end (50 s): final state


def test_unscored_runs_are_zero_everywhere():
    r = RunScore.unscored("A", "t", "missing", ["no run"])
    assert normalized_values(r, "pa").tolist() == [0.0] * 11
    assert budget_values(r, "sr").tolist() == [0.0] * 10


def test_study_curves_end_at_the_table_values():
    entries = paper_entries(n_objects=2, n_parts=2)
    runs = {}
    for e in entries:
        r = run_from_errors("A", e.task_id, [0.0, 0.5])
        r.ck_t, r.ck_pa, r.ck_sr, r.ck_seq = np.array([0.0, 100.0]), np.array([0.0, 0.5]), np.zeros(2), np.arange(2)
        r.ck_assignment = np.array([[0, 1], [1, 0]])
        r.call_t, r.end_t = np.array([50.0, 100.0, 4000.0]), 4000.0
        runs[("A", e.task_id)] = r
    study = make_study(entries, runs)
    c = quality_curves(study)["systems"]["A"]
    assert c["pa"]["normalized"][-1] == pytest.approx(50.0) == c["pa"]["final"]
    assert c["pa"]["normalized"][0] == 0.0
    assert c["pa"]["budget"][-1] == pytest.approx(50.0)  # 60 min < 4000 s end, state after the edit at 100 s
    assert c["edits_after_last_budget"] == 0
    dec = pa_decreases(study)["A"]
    zero = {"decreases": 0, "with_assignment_change": 0, "persist_alignment_fixed": 0, "persist_both_fixed": 0}
    assert dec == zero
    r = runs[("A", entries[0].task_id)]
    r.ck_pa = np.array([0.5, 0.0])
    assert pa_decreases(study)["A"] == {**zero, "decreases": 1, "with_assignment_change": 1}
    r.ck_drop_index, r.ck_drop_assignment_changed = np.array([0]), np.array([True])
    r.ck_drop_persist_alignment, r.ck_drop_persist_both = np.array([False]), np.array([True])
    assert pa_decreases(study)["A"] == {
        "decreases": 1,
        "with_assignment_change": 1,
        "persist_alignment_fixed": 0,
        "persist_both_fixed": 1,
    }


def test_calls_before_the_clock_start_have_negative_times():
    """Queries before start_episode / the first edit are recorded at their real negative times:
    budgets count from the clock start, normalized time from the first call."""
    from aw_eval.analyses.dynamics import call_positions

    r = _run()
    r.call_t = np.array([-20.0, -10.0, 0.0, 10.0, 20.0, 30.0])
    assert budget_values(r, "pa", [0, 10 / 60]).tolist() == [0.0, 0.25]
    v = normalized_values(r, "pa", [0.0, 0.4, 0.6, 1.0])  # t = -20, 0, 10, final
    assert v.tolist() == [0.0, 0.0, 0.25, 1.0]
    pos = call_positions(r.call_t)
    assert pos[0] == 0.0 and pos[-1] == 1.0 and np.all(np.diff(pos) > 0)
