"""The checks every refiner answer passes (aw.refine.base.check_poses) and the anchor rule."""

from __future__ import annotations

import numpy as np
import pytest

from aw.refine.base import RefineRequest, RefinerError, anchor_index, check_poses, identity_poses, returned_start


def _request(n_points=(30, 50), initial=None) -> RefineRequest:
    ids = [f"p{i}" for i in range(len(n_points))]
    pts = [np.zeros((n, 3)) for n in n_points]
    start = identity_poses(len(ids)) if initial is None else np.asarray(initial, float)
    return RefineRequest("t", ids, pts, [], [], start)


def test_anchor_is_the_part_with_most_samples_first_in_sorted_id_order_on_ties():
    assert anchor_index([np.zeros((3, 3)), np.zeros((5, 3))]) == 1
    pts = [np.zeros((5, 3)), np.zeros((5, 3))]
    assert anchor_index(pts, ["b", "a"]) == 1  # "a" sorts first
    assert anchor_index(pts, ["a", "b"]) == 0


def test_a_good_answer_comes_back_normalised():
    req = _request()
    poses = identity_poses(2)
    poses[0] = [0.1, 0.2, 0.3, 2.0, 0.0, 0.0, 0.0]  # the non-anchor part, quaternion not unit
    out = check_poses("r", req, poses)
    assert np.allclose(out[0, 3:], [1, 0, 0, 0]) and np.allclose(out[0, :3], [0.1, 0.2, 0.3])


@pytest.mark.parametrize(
    "poses, message",
    [
        (identity_poses(1), "refiner r: returned 1 pose for 2 parts"),
        (identity_poses(3), "refiner r: returned 3 poses for 2 parts"),
        (np.zeros((2, 6)), "each pose needs 7 numbers"),
        ([[np.nan, 0, 0, 1, 0, 0, 0], [0, 0, 0, 1, 0, 0, 0]], "non-finite pose for p0"),
        ([[0, 0, 0, 1, 0, 0, 0], [0, 0, np.inf, 1, 0, 0, 0]], "non-finite pose for p1"),
        ([[0, 0, 0, 0, 0, 0, 0], [0, 0, 0, 1, 0, 0, 0]], "zero quaternion for p0"),
        ([[0, 0, 0, 1, 0, 0, 0], [0.01, 0, 0, 1, 0, 0, 0]], "moved the anchor p1"),
        ([[0, 0, 0, 1, 0, 0, 0], [0, 0, 0, 0, 1, 0, 0]], "moved the anchor p1"),
        ("nonsense", "refiner r: poses are not numbers"),
    ],
)
def test_bad_answers_are_named(poses, message):
    with pytest.raises(RefinerError, match=message.replace("(", r"\(")):
        check_poses("r", _request(), poses)


def test_the_anchor_keeps_a_given_initial_pose_up_to_sign_and_rounding():
    start = identity_poses(2)
    start[1] = [0.5, -0.25, 1.0, 0.0, 0.0, 0.0, 1.0]
    req = _request(initial=start)
    answer = start.copy()
    answer[1, 3:] *= -1  # the same rotation
    answer[1, 0] += 1e-9
    answer[0] = [1, 2, 3, 1, 0, 0, 0]
    out = check_poses("r", req, answer)
    assert np.allclose(out[0, :3], [1, 2, 3])


def test_returned_start_within_1e_9_and_up_to_quaternion_sign():
    start = identity_poses(2)
    start[1] = [0.5, -0.25, 1.0, 0.0, 0.0, 0.0, 1.0]
    same = start.copy()
    same[1, 3:] *= -1  # the same rotation
    same[0, 0] += 5e-10
    assert returned_start(start, same)
    moved = start.copy()
    moved[1, 2] += 2e-9
    turned = start.copy()
    turned[0, 3:] = [np.cos(1e-8), np.sin(1e-8), 0, 0]
    assert not returned_start(start, moved) and not returned_start(start, turned)
    assert not returned_start(start, start[:1])
