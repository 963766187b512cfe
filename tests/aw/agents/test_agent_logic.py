"""Agent logic that needs no server: the oracle's noise model, the heuristic's box arithmetic,
reading tool results."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from aw.agents import AGENTS, NEEDS_TARGETS
from aw.agents.base import AgentContext, ObjectInfo, object_ids
from aw.agents.heuristic import _stick_axis, _world_box
from aw.agents.oracle import ROTATION_DEG_PER_LEVEL, TRANSLATION_PER_LEVEL, noisy_pose
from aw.pose import apply_pose, quat_to_matrix


def _pose(rng) -> np.ndarray:
    q = Rotation.random(random_state=int(rng.integers(1 << 30))).as_quat(scalar_first=True)
    return np.concatenate([rng.normal(size=3), q if q[0] >= 0 else -q])


def test_registry():
    assert set(AGENTS) == {"idle", "random", "oracle", "heuristic"}
    assert NEEDS_TARGETS == {"oracle"}


def test_zero_noise_is_the_target_exactly():
    rng = np.random.default_rng(1)
    target = _pose(rng)
    assert np.array_equal(noisy_pose(target, np.array([0.3, -0.2, 0.1]), 0.0, 1.0, rng), target)


def test_noise_rotates_about_the_part_centre_with_the_documented_means():
    rng = np.random.default_rng(2)
    target = _pose(rng)
    centre = np.array([1.5, -0.7, 0.2])  # far from the body origin, as baked placements are
    level, size = 1.0, 2.0
    shifts, angles = [], []
    for _ in range(4000):
        got = noisy_pose(target, centre, level, size, rng)
        c_target = apply_pose(target, centre[None])[0]
        c_got = apply_pose(got, centre[None])[0]
        shifts.append(np.linalg.norm(c_got - c_target))
        rel = quat_to_matrix(got[3:]) @ quat_to_matrix(target[3:]).T
        angles.append(np.degrees(np.arccos(np.clip((np.trace(rel) - 1) / 2, -1, 1))))
    # Exponential magnitudes: the means are the documented scales (within sampling error).
    assert np.mean(shifts) == pytest.approx(TRANSLATION_PER_LEVEL * level * size, rel=0.06)
    assert np.mean(angles) == pytest.approx(ROTATION_DEG_PER_LEVEL * level, rel=0.06)


def test_agent_randomness_depends_on_seed_and_task_only():
    a = AgentContext(task_id="t1", seed=3).rng("x").random(4)
    assert np.array_equal(a, AgentContext(task_id="t1", seed=3).rng("x").random(4))
    assert not np.array_equal(a, AgentContext(task_id="t2", seed=3).rng("x").random(4))
    assert not np.array_equal(a, AgentContext(task_id="t1", seed=4).rng("x").random(4))


def test_heuristic_box_arithmetic():
    lo, hi = np.array([0.0, 0.0, 0.0]), np.array([2.0, 0.2, 0.1])
    rot = Rotation.from_euler("xyz", [0, 90, 0], degrees=True).as_matrix()
    wlo, whi = _world_box(rot, lo, hi)
    assert np.allclose(whi - wlo, [0.1, 0.2, 2.0])  # the stick stands up
    stick = ObjectInfo("p1", "p1", np.zeros(3), np.array([1.0, 0, 0, 0]), lo, hi)
    panel = ObjectInfo("p2", "p2", np.zeros(3), np.array([1.0, 0, 0, 0]), lo, np.array([1.0, 0.8, 0.05]))
    assert _stick_axis(stick) == 0 and _stick_axis(panel) is None


def test_reading_tool_results():
    assert object_ids({"objects": [{"id": "p01"}, {"id": "p02"}], "groups": [{"id": "g1"}]}) == (["p01", "p02"], ["g1"])
    rec = {
        "id": "p01",
        "position": [0, 0, 0],
        "quaternion": [1, 0, 0, 0],
        "extents": [1, 2, 3],
        "local_bounds": {"min": [0, 0, 0], "max": [1, 2, 3]},
    }
    info = ObjectInfo.from_record(rec)
    assert np.allclose(info.local_centre, [0.5, 1, 1.5])
    with pytest.raises(ValueError, match="cannot read"):
        ObjectInfo.from_record({"id": "p01"})
    with pytest.raises(ValueError, match="neither a list nor an object"):
        object_ids("p01")
