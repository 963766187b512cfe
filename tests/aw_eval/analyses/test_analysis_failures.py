"""Failure classes (Appendix C.2) and translation fractions, hand-computed."""

from __future__ import annotations

import numpy as np
import pytest

from aw_eval.analyses.failures import CLASSES, classify_parts, failure_analysis, translation_fractions
from tests.aw_eval.score_helpers import make_study, paper_entries, run_from_errors


def test_each_class_in_the_papers_order():
    #            correct  never   far    trans   near    orient  mixed  correct-but-unmoved
    errors = [0.005, 0.5, 0.5, 0.5, 0.02, 0.5, 0.5, 0.01]
    centred = [0.0, 0.0, 0.0, 0.005, 0.005, 0.05, 0.05, 0.0]
    offset = [0.0, 5.0, 3.5, 0.5, 0.05, 0.1, 0.5, 0.0]
    moved = [True, False, True, True, True, True, True, False]
    cl = classify_parts(errors, centred, offset, moved)
    assert [CLASSES[c] for c in cl] == [
        "correct",
        "never_moved",
        "far_displaced",
        "translation_dominated",
        "near_threshold",
        "orientation_dominated",
        "mixed",
        "correct",
    ]


def test_cutoffs_are_inclusive_as_stated():
    # centred CD exactly 0.01 counts as <= 0.01; offset exactly 0.1 is not > 0.1; offset 3 is not far
    cl = classify_parts([0.5, 0.5, 0.5], [0.01, 0.01, 0.01], [0.1, 0.1000001, 3.0], [True] * 3)
    assert [CLASSES[c] for c in cl] == ["near_threshold", "translation_dominated", "translation_dominated"]


def test_part_vs_task_pooled_fractions():
    t = CLASSES.index("translation_dominated")
    m = CLASSES.index("mixed")
    runs = [
        np.array([0, t, t, m]),  # 2 of 3 wrong parts
        np.array([t, m, m, m, m]),  # 1 of 5
        np.array([0, 0]),
    ]  # success: not a failed task
    part, task, n_failed, n_wrong = translation_fractions(runs)
    assert (n_failed, n_wrong) == (2, 8)
    assert part == pytest.approx(100 * 3 / 8)
    assert task == pytest.approx(100 * (2 / 3 + 1 / 5) / 2)


def test_failure_analysis_grid_and_counts():
    entries = paper_entries(n_objects=1, n_parts=3)
    runs = {}
    for e in entries:
        runs[("A", e.task_id)] = run_from_errors(
            "A", e.task_id, [0.0, 0.3, 0.3], centred=[0, 0.008, 0.03], offset=[0, 0.15, 0.15]
        )
    study = make_study(entries, runs)
    f = failure_analysis(study)["systems"]["A"]
    assert f["failed_tasks"] == 5 and f["wrong_parts"] == 10
    assert f["class_counts"]["translation_dominated"] == 5 and f["class_counts"]["mixed"] == 5
    assert f["translation_part_pooled"] == pytest.approx(50.0)
    grid = f["grid"]  # rows: offset cutoff 0.05, 0.1, 0.2; columns: centred 0.005, 0.01, 0.02
    assert grid[2][1]["part_pooled"] == 0.0  # offset 0.15 <= 0.2: near-threshold, not translation
    assert grid[0][2]["part_pooled"] == pytest.approx(50.0)
    assert grid[0][0]["part_pooled"] == 0.0  # centred 0.008 > 0.005
    assert f["grid_range"] == [0.0, 50.0]
