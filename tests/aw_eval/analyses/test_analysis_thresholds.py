"""Threshold sweep with saved errors."""

from __future__ import annotations

import numpy as np
import pytest

from aw_eval.analyses.thresholds import DEFAULT_THRESHOLDS, sweep_errors, threshold_sweep
from tests.aw_eval.score_helpers import make_study, paper_entries, run_from_errors


def test_sweep_errors_hand_computed():
    pa, sr = sweep_errors([np.array([0.001, 0.01, 0.05]), None], [0.001, 0.01, 0.1])
    assert pa[0].tolist() == pytest.approx([1 / 3, 2 / 3, 1.0])
    assert sr[0].tolist() == [0.0, 0.0, 1.0]
    assert pa[1].tolist() == [0.0, 0.0, 0.0]


def test_default_thresholds_include_the_protocol_cutoff_and_match_final_scores():
    assert 0.01 in DEFAULT_THRESHOLDS
    entries = paper_entries(n_objects=3, n_parts=3)
    rng = np.random.default_rng(0)
    runs = {("A", e.task_id): run_from_errors("A", e.task_id, rng.choice([0.001, 0.05], size=3)) for e in entries}
    study = make_study(entries, runs)
    sw = threshold_sweep(study)["systems"]["A"]
    i = DEFAULT_THRESHOLDS.index(0.01)
    d = study.design
    assert sw["pa"][i] == pytest.approx(100 * d.weights @ study.values("pa")[0])
    assert sw["sr"][i] == pytest.approx(100 * d.weights @ study.values("sr")[0])
    assert np.all(np.diff(sw["pa"]) >= -1e-12)  # monotone in the threshold
