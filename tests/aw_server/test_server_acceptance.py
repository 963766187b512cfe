"""Acceptance: a scripted client that knows the hidden targets (test side only) assembles the parts
through set_object_pose, and through translate_objects + rotate_objects (world and camera frames,
single parts and a group); the recorded final poses are the targets, and aw_eval scores them
PA = SR = 100%."""

from __future__ import annotations

import anyio
import numpy as np
import pytest
from aw_server_helpers import quat_close, server_params
from mcp import Client
from scipy.spatial.transform import Rotation

from aw.formats import read_final, read_trajectory
from aw.pose import quat_to_matrix


def _xyz_angles(m: np.ndarray) -> list[float]:
    """Angles (degrees) that rotate_objects applies X, then Y, then Z about fixed axes to give ``m``:
    scipy's lowercase 'xyz' is exactly that extrinsic sequence, m = Rz @ Ry @ Rx."""
    return [float(a) for a in Rotation.from_matrix(m).as_euler("xyz", degrees=True)]


async def _ok(c, tool, args):
    r = await c.call_tool(tool, args)
    assert not r.is_error, (tool, args, r.content)
    return r.structured_content


async def _assemble_set_pose(c, targets):
    for pid, t in targets.parts.items():
        await _ok(c, "set_object_pose", {"id": pid, "position": t.pose[:3], "quaternion": t.pose[3:]})


async def _assemble_relative(c, targets):
    goal = {pid: np.array(t.pose) for pid, t in targets.parts.items()}
    await _ok(c, "move_camera", {"yaw": 25, "pitch": -15})
    cam = (await _ok(c, "get_state", {}))["camera"]
    axes = np.stack([cam["right"], cam["up"], cam["forward"]], axis=1)  # columns: camera axes in world

    # p01 entirely in camera space: about camera axes, then a camera-frame translation. The axes
    # (right, up, forward) form a left-handed basis A, and each angle turns right-handedly about
    # its axis vector, so rotating by angles a means R = A Rz(-c) Ry(-b) Rx(-a) A^T.
    assert np.linalg.det(axes) == pytest.approx(-1.0)
    r = quat_to_matrix(goal["p01"][3:])
    angles = [-a for a in _xyz_angles(axes.T @ r @ axes)]
    await _ok(c, "rotate_objects", {"ids": ["p01"], "angles": angles, "space": "camera"})
    await _ok(c, "translate_objects", {"ids": ["p01"], "delta": list(axes.T @ goal["p01"][:3]), "space": "camera"})

    # p02 and p03: rotate each in world space about its origin (the default pivot), then move them
    # together as a group, then correct p03 alone.
    for pid in ("p02", "p03"):
        await _ok(c, "rotate_objects", {"ids": [pid], "angles": _xyz_angles(quat_to_matrix(goal[pid][3:]))})
    gid = (await _ok(c, "group_objects", {"ids": ["p02", "p03"], "name": "legs"}))["group"]["id"]
    await _ok(c, "translate_objects", {"ids": [gid], "delta": list(goal["p02"][:3])})
    await _ok(c, "translate_objects", {"ids": ["p03"], "delta": list(goal["p03"][:3] - goal["p02"][:3])})
    await _ok(c, "ungroup_objects", {"ids": [gid]})


ROUTES = {"set_object_pose": _assemble_set_pose, "translate+rotate": _assemble_relative}


@pytest.fixture(scope="module")
def assembled(box_task, tmp_path_factory):
    """Run both scripted episodes once; {route: run_dir}."""
    task_dir, _, targets = box_task
    runs = {}

    async def episode(route, run):
        async with Client(server_params(task_dir, run, "--system", "oracle")) as c:
            await _ok(c, "start_episode", {})
            await ROUTES[route](c, targets)

    for route in ROUTES:
        run = tmp_path_factory.mktemp("accept") / "run"
        anyio.run(episode, route, run)
        runs[route] = run
    return runs


@pytest.mark.parametrize("route", list(ROUTES))
def test_final_poses_are_the_targets(assembled, box_task, route):
    _, _, targets = box_task
    run = assembled[route]
    final = read_final(run / "final.json")
    assert final.reason == "disconnect"
    for pid, t in targets.parts.items():
        got = np.array(final.poses[pid])
        assert np.abs(got[:3] - np.array(t.pose[:3])).max() <= 1e-9, (pid, got, t.pose)
        assert quat_close(got[3:], t.pose[3:], 1e-9), (pid, got, t.pose)
    traj = read_trajectory(run / "trajectory.jsonl")
    assert traj.checkpoints()[-1].poses == final.poses
    assert all(c.ok for c in traj.calls)


@pytest.mark.parametrize("route", list(ROUTES))
def test_aw_eval_scores_full_marks(assembled, box_task, route):
    aw_eval = pytest.importorskip("aw_eval")
    if not (hasattr(aw_eval, "score") and hasattr(aw_eval, "load_task_geometry")):
        pytest.skip("aw_eval.score is not available yet")
    task_dir, targets_path, _ = box_task
    geom = aw_eval.load_task_geometry(task_dir, targets_path)
    final = read_final(assembled[route] / "final.json")
    poses = np.array([final.poses[pid] for pid in geom.part_ids])
    res = aw_eval.score(geom, poses)
    assert float(res.pa) == 1.0 and float(res.sr) == 1.0
