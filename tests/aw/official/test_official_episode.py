"""Episode archives read into per-frame part poses with MuJoCo."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest

from aw.formats import FormatError
from aw.official import read_episode

from official_fixtures import episode_members, episode_poses, qpos_rows, scene_xml, write_archive

IDS = ["p01", "p02", "p03"]
SIZES = [(0.1, 0.05, 0.02), (0.05, 0.05, 0.05), (0.2, 0.01, 0.03)]


def _targets(seed=0):
    rng = np.random.default_rng(seed)
    t = np.concatenate([rng.normal(size=(3, 3)), rng.normal(size=(3, 4))], axis=1)
    t[:, 3:] /= np.linalg.norm(t[:, 3:], axis=1, keepdims=True)
    t[:, 3:] *= np.sign(t[:, 3:4])
    return t


def test_poses_restored_from_qpos(tmp_path):
    poses = episode_poses(_targets(), 7)
    arc = write_archive(tmp_path / "e.zip", episode_members(IDS, SIZES, poses, mesh_asset=True),
                        {"sample_id": "s1", "system": "agentX", "started_at": "2025-05-01T10:00:00Z"})
    ep = read_episode(arc)
    assert ep.sample_id == "s1" and ep.system == "agentX" and ep.part_ids == IDS
    assert ep.poses.shape == (7, 3, 7)
    np.testing.assert_allclose(ep.poses, poses, atol=1e-15)
    assert [f.call for f in ep.frames] == [None, 1, 2, 3, 4, 5, 6]
    assert [c.tool for c in ep.calls][-1] == "capture_scene" and ep.end_event()["reason"] == "finished"


def test_non_unit_quaternions_are_normalized_by_kinematics(tmp_path):
    poses = episode_poses(_targets(), 3)
    scaled = poses.copy()
    scaled[..., 3:] *= 3.0
    m = episode_members(IDS, SIZES, poses)
    m["frames.bin"] = qpos_rows(scaled).astype("<f8").tobytes()
    ep = read_episode(write_archive(tmp_path / "e.zip", m, {"sample_id": "s"}))
    np.testing.assert_allclose(ep.poses, poses, atol=1e-12)


def test_body_mapping_and_mjstate_layout(tmp_path):
    poses = episode_poses(_targets(), 4)
    m = episode_members(IDS, SIZES, poses)
    # bodies named differently from the parts, and full physics states as rows
    xml = scene_xml(["b_a", "b_b", "b_c"], SIZES)
    m["world/model.xml"] = xml.encode()
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    spec = int(mujoco.mjtState.mjSTATE_PHYSICS)
    rows = []
    for row in qpos_rows(poses):
        data.qpos[:] = row
        data.qvel[:] = 0.5
        state = np.empty(mujoco.mj_stateSize(model, spec))
        mujoco.mj_getState(model, data, state, spec)
        rows.append(state)
    m["frames.bin"] = np.asarray(rows, "<f8").tobytes()
    man = {"sample_id": "s", "bodies": {"p01": "b_a", "p02": "b_b", "p03": "b_c"},
           "state": {"layout": "mjstate", "spec": spec, "width": len(rows[0])}}
    ep = read_episode(write_archive(tmp_path / "e.zip", m, man))
    assert ep.part_ids == IDS
    np.testing.assert_allclose(ep.poses, poses, atol=1e-15)


@pytest.mark.parametrize("change, message", [
    (lambda m: m.update({"frames.bin": m["frames.bin"][:-8]}), "frames.bin: .* bytes is not a whole number of 21-float64 rows"),
    (lambda m: m.update({"frames.bin": m["frames.bin"] + np.zeros(21).tobytes()}), "frames.jsonl has 4 lines but frames.bin has 5 rows"),
    (lambda m: m.update({"frames.bin": np.full((4, 21), np.nan).tobytes()}), "frames.bin: non-finite values in row 0"),
    (lambda m: m.update({"world/model.xml": b"<mujoco><worldbody><body name='x'></worldbody></mujoco>"}), "world/model.xml: MuJoCo cannot load it"),
    (lambda m: m.update({"world/model.xml": scene_xml(["q1", "q2", "q3"], SIZES).encode()}), None),
    (lambda m: m.update({"frames.jsonl": b'{"frame": 0}\n{"frame": 2}\n{"frame": 2}\n{"frame": 3}\n'}), "frames.jsonl: line 2: frame index 2, expected 1"),
    (lambda m: m.update({"frames.jsonl": b'{"frame": 0}\n{"frame": 1, "call": 77}\n{"frame": 2}\n{"frame": 3}\n'}), "frame 1 names call 77"),
    (lambda m: m.update({"calls.jsonl": b'{"seq": 2, "tool": "a"}\n{"seq": 1, "tool": "b"}\n'}), "calls.jsonl: seq values must be unique and increasing"),
    (lambda m: m.update({"calls.jsonl": b'{"seq": 1}\n'}), "calls.jsonl: line 1: tool: missing"),
    (lambda m: m.update({"events.jsonl": b'{"t": 0\n'}), "events.jsonl: line 1: not valid JSON"),
])
def test_malformed_episodes(tmp_path, change, message):
    poses = episode_poses(_targets(), 4)
    m = episode_members(IDS, SIZES, poses)
    change(m)
    arc = write_archive(tmp_path / "e.zip", m, {"sample_id": "s", "bodies": {p: p for p in IDS}})
    with pytest.raises(FormatError, match=message or "world/model.xml: no body named 'p01'") as exc:
        read_episode(arc)
    assert str(arc) in str(exc.value)


def test_manifest_problems(tmp_path):
    m = episode_members(IDS, SIZES, episode_poses(_targets(), 3))
    with pytest.raises(FormatError, match="sample_id .*missing"):
        read_episode(write_archive(tmp_path / "a.zip", m, {}))
    with pytest.raises(FormatError, match="state.width is 5 but the model's qpos has 21 values"):
        read_episode(write_archive(tmp_path / "b.zip", m, {"sample_id": "s", "state": {"width": 5}}))
    with pytest.raises(FormatError, match="state.layout: expected 'qpos' or 'mjstate'"):
        read_episode(write_archive(tmp_path / "c.zip", m, {"sample_id": "s", "state": {"layout": "xpos"}}))
    assert json.loads(m["frames.jsonl"].splitlines()[0])["frame"] == 0
