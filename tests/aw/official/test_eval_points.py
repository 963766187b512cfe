"""``SUITE/eval_points/<task>.npz``: round trip and refusals naming the file."""

from __future__ import annotations

import numpy as np
import pytest

from aw.formats import FormatError
from aw.official.eval_points import EvalInputs, read_eval_inputs, write_eval_inputs
from tests.aw.official.builders import FINAL, evaluation_points


def inputs() -> EvalInputs:
    return EvalInputs("t", ["0", "1", "2"], evaluation_points(), FINAL, 0.7, [["0", "2"], ["1"]])


def test_round_trip(tmp_path):
    write_eval_inputs(tmp_path / "t.npz", inputs())
    back = read_eval_inputs(tmp_path / "t.npz")
    assert back.part_ids == ["0", "1", "2"] and back.groups == [["0", "2"], ["1"]] and back.divisor == 0.7
    assert np.array_equal(back.points, evaluation_points()) and np.array_equal(back.target_poses, FINAL)
    assert back.group_labels().tolist() == [0, 1, 0]


@pytest.mark.parametrize(
    "change,message",
    [
        ({"points": np.zeros((3, 999, 3))}, "points"),
        ({"part_ids": np.array(["1", "0", "2"])}, "sorted"),
        ({"scale_divisor": np.float64(-1)}, "positive"),
        ({"target_poses": np.zeros((3, 7))}, "zero quaternion"),
        ({"equivalence_groups": np.array([0.5, 1, 2])}, "integer"),
    ],
)
def test_refusals(tmp_path, change, message):
    arrays = {
        "part_ids": np.array(["0", "1", "2"]),
        "points": evaluation_points(),
        "target_poses": FINAL,
        "scale_divisor": np.float64(0.7),
        "equivalence_groups": np.array([0, 1, 2]),
    }
    np.savez(tmp_path / "t.npz", **{**arrays, **change})
    with pytest.raises(FormatError, match=message) as info:
        read_eval_inputs(tmp_path / "t.npz")
    assert "t.npz" in str(info.value)
    np.savez(tmp_path / "u.npz", points=evaluation_points())
    with pytest.raises(FormatError, match="arrays missing"):
        read_eval_inputs(tmp_path / "u.npz")
