"""Interaction dynamics (Appendix C.1) on hand-made call logs."""

from __future__ import annotations

import numpy as np
import pytest

from aw_eval.analyses.dynamics import EvalCalls, activity_shares, call_positions, magnitude_summary, stage_summary
from aw_eval.study.episode import call_kind

INSPECT, OBSERVE, MANIPULATE, OTHER = 0, 1, 2, 3  # the indices of KIND_NAMES


def _evals():
    a = EvalCalls(
        call_t=np.arange(10.0),
        call_kind=np.array(
            [INSPECT, INSPECT, OBSERVE, MANIPULATE, MANIPULATE, OBSERVE, OTHER, MANIPULATE, OBSERVE, OBSERVE], np.int8
        ),
        edit_call=np.array([3, 4, 7]),
        edit_translation=np.array([0.2, 0.05, 0.4]),
        edit_rotation_deg=np.array([0.1, 30.0, 0.0]),
        edit_revisit=np.array([False, True, False]),
        weight=0.75,
    )
    b = EvalCalls(
        call_t=np.array([0.0, 0.5, 10.0]),
        call_kind=np.array([INSPECT, MANIPULATE, OBSERVE], np.int8),
        edit_call=np.array([1]),
        edit_translation=np.array([0.6]),
        edit_rotation_deg=np.array([0.0]),
        edit_revisit=np.array([False]),
        weight=0.25,
    )
    return [a, b]


def test_call_kinds():
    assert [call_kind(t) for t in ("list_objects", "get_object", "get_scene", "get_state")] == [INSPECT] * 4
    assert [call_kind(t) for t in ("capture_scene", "move_camera")] == [OBSERVE] * 2
    assert [call_kind(t) for t in ("translate_objects", "rotate_objects", "set_object_pose")] == [MANIPULATE] * 3
    assert [call_kind(t) for t in ("group_objects", "ungroup_objects", "start_episode", "bogus")] == [OTHER] * 4


def test_positions_and_degenerate_interval():
    assert call_positions(np.array([2.0, 4.0, 6.0])).tolist() == [0.0, 0.5, 1.0]
    assert call_positions(np.array([3.0, 3.0])).tolist() == [0.0, 0.0]


def test_activity_shares_weighted_within_active_bins():
    shares, active = activity_shares(_evals())
    # bin 0: A all inspect; B half inspect, half manipulate -> weights .75/.25
    assert shares[0].tolist() == pytest.approx([0.875, 0.0, 0.125, 0.0])
    assert active.tolist() == [2, 1, 1, 1, 1, 1, 1, 1, 1, 2]
    assert shares[3].tolist() == pytest.approx([0, 0, 1, 0])  # A alone, weight renormalized
    assert shares[6].tolist() == pytest.approx([0, 0, 0, 1])  # grouping etc. stay in the denominator
    assert shares[9].tolist() == pytest.approx([0, 1, 0, 0])
    assert np.allclose(shares.sum(axis=1), 1.0)


def test_empty_bins_are_omitted():
    ev = EvalCalls(
        np.array([0.0, 10.0]),
        np.array([INSPECT, OBSERVE], np.int8),
        np.zeros(0, int),
        np.zeros(0),
        np.zeros(0),
        np.zeros(0, bool),
        1.0,
    )
    shares, active = activity_shares([ev])
    assert np.isnan(shares[4]).all() and active[4] == 0


def test_magnitudes_per_bin_and_the_half_degree_rule():
    m = magnitude_summary(_evals())
    assert m["translation"][0] == pytest.approx(0.6)  # B's edit; A has none in bin 0
    assert m["translation"][3] == pytest.approx(0.2)  # 0.1 degrees counts as a translation
    assert m["rotation_deg"][4] == pytest.approx(30.0)
    assert m["translation"][4] is None  # no translation there: never a zero
    assert m["translation"][7] == pytest.approx(0.4)


def test_stages_and_revisits():
    st = stage_summary(_evals())
    assert st["translation_early"] == pytest.approx(0.2)  # weighted median of 0.2 (w .75) and 0.6 (w .25)
    assert st["translation_late"] == pytest.approx(0.4)
    assert st["rotation_early"] is None and st["rotation_late"] is None  # the rotation sits in the middle third
    assert st["revisit"] == pytest.approx(100 / 3)
