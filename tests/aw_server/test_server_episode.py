"""A full episode against the real aw-serve over stdio: queries, edits, groups, camera, captures,
and what ends up in trajectory.jsonl, captures/ and final.json."""

from __future__ import annotations

import numpy as np
import pytest
from aw_server_helpers import image_diff, png_bytes, quat_close, result_png, server_params
from mcp import Client

from aw.formats import read_final, read_trajectory
from aw.pose import quat_to_matrix

pytestmark = pytest.mark.anyio


async def test_full_episode(box_task, tmp_path):
    task_dir, _, _ = box_task
    run = tmp_path / "run"
    async with Client(server_params(task_dir, run, "--system", "scripted")) as c:
        # Calls before start_episode are served and recorded as inactive.
        pre = await c.call_tool("get_state", {})
        assert not pre.is_error and pre.structured_content["episode"]["started"] is False

        r = await c.call_tool("start_episode", {"task": "box3"})
        assert not r.is_error and r.structured_content["episode"]["started"] is True
        again = await c.call_tool("start_episode", {})
        assert not again.is_error and "already started" in again.structured_content["message"]

        lst = (await c.call_tool("list_objects", {})).structured_content
        assert [o["id"] for o in lst["objects"]] == ["p01", "p02", "p03"] and lst["groups"] == []

        obj = (await c.call_tool("get_object", {"id": "p02"})).structured_content
        assert obj["position"] == [0.0, 0.0, 0.0] and obj["quaternion"] == [1.0, 0.0, 0.0, 0.0]
        lo, hi = np.array(obj["local_bounds"]["min"]), np.array(obj["local_bounds"]["max"])
        assert np.allclose(obj["extents"], hi - lo) and np.all(hi > lo)

        scene = (await c.call_tool("get_scene", {})).structured_content
        assert scene["conventions"]["up"] == "+Z" and scene["conventions"]["quaternion"] == "(w, x, y, z)"
        assert scene["settings"]["image_size"] == [1024, 768] and scene["settings"]["vertical_fov_deg"] == 38.0
        assert scene["reference"] == {"condition": "none", "images": 0}
        assert len(scene["objects"]) == 3 and scene["episode"]["budget_minutes"] == 60.0

        # Observation, then a pose edit: the edit returns status only; the picture changes.
        cap0 = await c.call_tool("capture_scene", {})
        img0 = result_png(cap0)
        assert img0.size == (1024, 768)
        moved = await c.call_tool("translate_objects", {"ids": ["p02"], "delta": [0.0, -0.5, 0.3]})
        assert not moved.is_error and moved.structured_content == {"status": "ok", "changed": ["p02"]}
        cap1 = await c.call_tool("capture_scene", {})
        img1 = result_png(cap1)
        assert image_diff(img0, img1) > 0.2

        # Camera orbit changes the picture; poses are untouched.
        cam = await c.call_tool("move_camera", {"yaw": 40, "pitch": 10, "zoom": 0.8})
        assert cam.structured_content["camera"]["yaw"] == pytest.approx(-20.0)
        img2 = result_png(await c.call_tool("capture_scene", {}))
        assert image_diff(img1, img2) > 0.5

        # Camera-space translation: delta along right/up/forward.
        st = (await c.call_tool("get_state", {})).structured_content
        right, up, fwd = (np.array(st["camera"][k]) for k in ("right", "up", "forward"))
        before = np.array(st["poses"]["p03"]["position"])
        await c.call_tool("translate_objects", {"ids": ["p03"], "delta": [0.1, 0.2, -0.3], "space": "camera"})
        after = np.array((await c.call_tool("get_object", {"id": "p03"})).structured_content["position"])
        assert np.allclose(after - before, 0.1 * right + 0.2 * up - 0.3 * fwd, atol=1e-12)

        # Groups select their parts; rotation about the default pivot (mean of body origins).
        g = (await c.call_tool("group_objects", {"ids": ["p01", "p03"], "name": "top+leg"})).structured_content
        gid = g["group"]["id"]
        assert g["group"]["members"] == ["p01", "p03"] and g["changed"] == []
        st = (await c.call_tool("get_state", {})).structured_content
        p1, p3 = (np.array(st["poses"][k]["position"]) for k in ("p01", "p03"))
        rot = await c.call_tool("rotate_objects", {"ids": [gid], "angles": [0, 0, 90]})
        assert rot.structured_content == {"status": "ok", "changed": ["p01", "p03"]}
        st2 = (await c.call_tool("get_state", {})).structured_content
        pivot = (p1 + p3) / 2
        rz = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
        assert np.allclose(st2["poses"]["p01"]["position"], rz @ (p1 - pivot) + pivot, atol=1e-12)
        assert np.allclose(quat_to_matrix(st2["poses"]["p03"]["quaternion"]), rz, atol=1e-12)
        assert st2["groups"] == [{"id": gid, "name": "top+leg", "members": ["p01", "p03"]}]
        grp = (await c.call_tool("get_object", {"id": gid})).structured_content
        assert grp["type"] == "group" and grp["members"] == ["p01", "p03"]

        # X then Y then Z about world axes, about an explicit pivot.
        await c.call_tool("set_object_pose", {"id": "p02", "position": [0.5, 0.5, 0.5], "quaternion": [1, 0, 0, 0]})
        await c.call_tool("rotate_objects", {"ids": ["p02"], "angles": [90, 90, 0], "pivot": [0, 0, 0]})
        o = (await c.call_tool("get_object", {"id": "p02"})).structured_content
        rx = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0.0]])
        ry = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0.0]])
        assert np.allclose(quat_to_matrix(o["quaternion"]), ry @ rx, atol=1e-12)
        assert np.allclose(o["position"], ry @ rx @ np.array([0.5, 0.5, 0.5]), atol=1e-12)

        # set_object_pose normalizes the quaternion and keeps the other half of the pose.
        await c.call_tool("set_object_pose", {"id": "p02", "quaternion": [0, 0, 0, 2]})
        o2 = (await c.call_tool("get_object", {"id": "p02"})).structured_content
        assert quat_close(o2["quaternion"], [0, 0, 0, 1], 1e-12) and np.allclose(o2["position"], o["position"])

        ung = await c.call_tool("ungroup_objects", {"ids": [gid]})
        assert ung.structured_content == {"status": "ok", "removed": [gid], "changed": []}
        last = await c.call_tool("capture_scene", {})
        final_state = (await c.call_tool("get_state", {})).structured_content

    # ---- the recording
    traj = read_trajectory(run / "trajectory.jsonl")
    assert traj.header.task_id == "box3_none" and traj.header.system == "scripted"
    assert traj.header.part_ids == ["p01", "p02", "p03"]
    assert all(p == [0, 0, 0, 1, 0, 0, 0] for p in traj.header.initial_poses.values())
    calls = traj.calls
    assert [c.seq for c in calls] == list(range(1, len(calls) + 1))
    assert calls[0].tool == "get_state" and calls[0].episode_active is False and calls[0].t < 0.0
    assert calls[1].tool == "start_episode" and calls[1].episode_active and calls[1].args == {"task": "box3"}
    ts = [c.t for c in calls]
    assert ts == sorted(ts) and all(c.ok for c in calls)
    assert all(c.camera is not None for c in calls)
    edits = [c for c in calls if c.poses is not None]
    assert [c.tool for c in edits] == [
        "translate_objects",
        "translate_objects",
        "rotate_objects",
        "set_object_pose",
        "rotate_objects",
        "set_object_pose",
    ]
    assert edits[0].changed == ["p02"] and edits[0].args == {
        "ids": ["p02"],
        "delta": [0.0, -0.5, 0.3],
        "space": "world",
    }
    # Non-edits record no poses; group calls change no pose.
    assert all(c.poses is None and c.changed == [] for c in calls if c.tool in ("group_objects", "move_camera"))
    cam_call = next(c for c in calls if c.tool == "move_camera")
    assert cam_call.camera.yaw == pytest.approx(-20.0)

    # Captures: kept in the run dir, same bytes the agent got, paths relative to the run dir.
    caps = [c for c in calls if c.tool == "capture_scene"]
    assert len(caps) == 4
    for c in caps:
        assert c.image == f"captures/{c.seq:06d}.png" and (run / c.image).is_file()
    assert (run / caps[-1].image).read_bytes() == png_bytes(last)
    assert (run / caps[0].image).read_bytes() == png_bytes(cap0)

    assert traj.end is not None and traj.end.reason == "disconnect"
    final = read_final(run / "final.json")
    assert final.reason == "disconnect" and final.task_id == "box3_none"
    for pid, p in final_state["poses"].items():
        assert np.allclose(final.poses[pid], p["position"] + p["quaternion"], atol=0)
    assert traj.final_poses() == final.poses
    assert traj.checkpoints()[-1].poses == final.poses
