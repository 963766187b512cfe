"""aw.episode without MCP: recording, the episode clock and budget, ending, captures, failures."""

from __future__ import annotations

import io
import os

import numpy as np
import pytest
import trimesh
from PIL import Image

from aw.episode import Episode, EpisodeError, RunDirError
from aw.formats import Task, TaskPart, read_final, read_trajectory
from aw.pose import quat_to_matrix
from aw.prompt import task_prompt


class Clock:
    """A settable monotonic clock (seconds)."""

    def __init__(self):
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def _task() -> tuple[Task, list[trimesh.Trimesh]]:
    ids = ["p01", "p02"]
    task = Task(
        task_id="ep",
        source="custom",
        dataset="test",
        object_id="ep",
        prompt=task_prompt("none"),
        parts=[TaskPart(id=i, mesh=f"parts/{i}.obj") for i in ids],
    )
    meshes = [trimesh.creation.box([0.4, 0.2, 0.1]), trimesh.creation.box([0.1, 0.1, 0.3])]
    meshes[1].apply_translation([0.6, 0, 0])
    return task, meshes


@pytest.fixture
def episode(tmp_path):
    task, meshes = _task()
    clock = Clock()
    ep = Episode(task, meshes, tmp_path / "run", system="unit", budget_minutes=1.0, clock=clock)
    ep.clock = clock
    yield ep
    ep.close()


def test_recording_and_clock(episode):
    ep, clock, run = episode, episode.clock, episode.run_dir
    ep.call("list_objects")
    clock.now += 5
    ep.call("get_object", {"id": "p02"})
    clock.now += 5  # 10 s after the server started
    assert "budget is 1 minutes" in ep.call("start_episode", {"task": "x"})["message"]
    clock.now += 2.5
    assert ep.call("translate_objects", {"ids": ["p01"], "delta": [0, 0, 1], "space": None}) == {
        "status": "ok",
        "changed": ["p01"],
    }
    clock.now += 1
    assert ep.call("start_episode")["message"].startswith("the episode was already started 3.5 s ago")
    with pytest.raises(EpisodeError, match="unknown id 'zz'"):
        ep.call("rotate_objects", {"ids": ["zz"], "angles": [0, 0, 1]})
    clock.now += 1
    assert ep.close("disconnect") == "disconnect"
    assert ep.close("error") == "disconnect"  # idempotent
    with pytest.raises(EpisodeError, match="ended"):
        ep.call("list_objects")

    traj = read_trajectory(run / "trajectory.jsonl")
    assert traj.header.system == "unit" and traj.header.part_ids == ["p01", "p02"]
    rows = [(c.seq, c.tool, c.t, c.episode_active, c.ok) for c in traj.calls]
    assert rows == [
        (1, "list_objects", -10.0, False, True),  # real times before the clock start, never a fake 0
        (2, "get_object", -5.0, False, True),
        (3, "start_episode", 0.0, True, True),
        (4, "translate_objects", 2.5, True, True),
        (5, "start_episode", 3.5, True, True),
        (6, "rotate_objects", 3.5, True, False),
    ]
    # Optional arguments given as None are "not given"; defaults are not invented.
    assert traj.calls[3].args == {"ids": ["p01"], "delta": [0, 0, 1]}
    assert traj.calls[3].poses == {"p01": [0, 0, 1, 1, 0, 0, 0], "p02": [0, 0, 0, 1, 0, 0, 0]}
    assert traj.calls[5].error.startswith("unknown id 'zz'") and traj.calls[5].poses is None
    assert traj.end.reason == "disconnect" and traj.end.t == 4.5 and traj.end.server_t == 14.5
    assert [c.server_t for c in traj.calls] == [0.0, 5.0, 10.0, 12.5, 13.5, 13.5]
    assert read_final(run / "final.json").poses == traj.end.poses
    # In the file, calls before the clock start carry no t (the clock had not started).
    first = (run / "trajectory.jsonl").read_text().splitlines()[1]
    assert '"server_t":0.0' in first and '"t":' not in first


def test_first_edit_starts_the_clock(episode):
    """An agent that never calls start_episode is still limited: its first edit starts the budget."""
    ep, clock, run = episode, episode.clock, episode.run_dir
    ep.call("get_state")
    clock.now += 3
    assert not ep.started
    ep.call("translate_objects", {"ids": ["p01"], "delta": [0, 0, 1]})
    assert ep.started and ep.call("get_state")["episode"]["started"] is True
    clock.now += 61
    with pytest.raises(EpisodeError, match="budget of 1 minutes is exhausted"):
        ep.call("translate_objects", {"ids": ["p01"], "delta": [0, 0, 1]})
    assert ep.close() == "timeout"
    traj = read_trajectory(run / "trajectory.jsonl")
    assert [(c.t, c.episode_active) for c in traj.calls] == [(-3.0, False), (0.0, True), (0.0, True), (61.0, True)]
    assert read_final(run / "final.json").poses["p01"] == [0, 0, 1, 1, 0, 0, 0]


def test_clock_never_started(tmp_path):
    """Only queries: the clock never starts; times are real and end at 0 (the end record)."""
    task, meshes = _task()
    clock = Clock()
    ep = Episode(task, meshes, tmp_path / "run", clock=clock)
    ep.call("list_objects")
    clock.now += 2
    ep.call("get_state")
    clock.now += 1
    ep.close()
    traj = read_trajectory(tmp_path / "run" / "trajectory.jsonl")
    assert [c.t for c in traj.calls] == [-3.0, -1.0] and traj.end.t == 0.0


def test_budget(episode):
    ep, clock, run = episode, episode.clock, episode.run_dir
    ep.call("start_episode")
    clock.now += 59
    ep.call("set_object_pose", {"id": "p02", "position": [1, 1, 1]})
    assert not (run / "final.json").exists()
    clock.now += 2
    with pytest.raises(EpisodeError, match="budget of 1 minutes is exhausted: edits are refused"):
        ep.call("translate_objects", {"ids": ["p02"], "delta": [1, 0, 0]})
    # The final state is kept at once, before the session closes.
    assert read_final(run / "final.json").reason == "timeout"
    for tool, args in [("group_objects", {"ids": ["p01"]}), ("set_object_pose", {"id": "p01", "position": [0, 0, 0]})]:
        with pytest.raises(EpisodeError, match="budget"):
            ep.call(tool, args)
    assert ep.call("get_state")["episode"]["timed_out"] is True
    ep.call("move_camera", {"yaw": 10})
    assert ep.close("disconnect") == "timeout"
    final = read_final(run / "final.json")
    assert final.reason == "timeout" and final.poses["p02"] == [1, 1, 1, 1, 0, 0, 0]
    traj = read_trajectory(run / "trajectory.jsonl")
    assert traj.end.reason == "timeout" and [c.ok for c in traj.calls] == [True, True, False, False, False, True, True]


def test_run_dir_refusal_and_overwrite(tmp_path):
    task, meshes = _task()
    run = tmp_path / "run"
    Episode(task, meshes, run).close()
    with pytest.raises(RunDirError, match="already holds a recording"):
        Episode(task, meshes, run)
    ep = Episode(task, meshes, run, overwrite=True)
    ep.call("list_objects")
    ep.close()
    traj = read_trajectory(run / "trajectory.jsonl")
    assert len(traj.calls) == 1


def test_bad_budget(tmp_path):
    task, meshes = _task()
    for bad in (0, -1, float("nan"), float("inf"), 1e9, 1e308):
        with pytest.raises(ValueError, match="budget_minutes"):
            Episode(task, meshes, tmp_path / f"r{bad}", budget_minutes=bad)


def test_unknown_tool_and_arguments(episode):
    with pytest.raises(EpisodeError, match="unknown tool 'reset'"):
        episode.call("reset")
    with pytest.raises(EpisodeError, match="invalid arguments for get_object"):
        episode.call("get_object", {"name": "p01"})
    with pytest.raises(EpisodeError, match="invalid arguments for list_objects"):
        episode.call("list_objects", {"verbose": True})
    episode.close()
    calls = read_trajectory(episode.run_dir / "trajectory.jsonl").calls
    assert [(c.tool, c.ok) for c in calls] == [("reset", False), ("get_object", False), ("list_objects", False)]


def test_recorded_args_are_json(episode):
    with pytest.raises(EpisodeError):
        episode.call("translate_objects", {"ids": ["p01"], "delta": [float("nan"), float("inf"), 0]})
    episode.reject("translate_objects", {"ids": ["p01"], "delta": "x" * 50_000}, "too big")
    episode.reject("translate_objects", "not a dict", "bad")
    episode.close()
    calls = read_trajectory(episode.run_dir / "trajectory.jsonl").calls
    assert calls[0].args["delta"] == ["nan", "inf", 0]
    assert "_truncated" in calls[1].args and calls[1].error == "too big"
    assert calls[2].args == {"_raw": "not a dict"}


def test_camera_frame_rotation_directions(episode):
    """The rotate_objects description's claims about camera-frame angles."""
    cam = episode.call("get_state")["camera"]
    right, up, fwd = (np.array(cam[k]) for k in ("right", "up", "forward"))
    for angles, vec, expected in [
        ([0, 0, 90], right, -up),  # about forward: clockwise in the image
        ([90, 0, 0], up, -fwd),  # about right: the top tilts toward the camera
        ([0, 90, 0], right, fwd),  # about up: the right side turns away
    ]:
        episode.call("set_object_pose", {"id": "p01", "quaternion": [1, 0, 0, 0]})
        episode.call("rotate_objects", {"ids": ["p01"], "angles": angles, "space": "camera"})
        q = episode.call("get_object", {"id": "p01"})["quaternion"]
        assert np.allclose(quat_to_matrix(q) @ vec, expected, atol=1e-12), angles


def test_capture_with_the_real_renderer(episode):
    cap = episode.call("capture_scene")
    img = Image.open(io.BytesIO(cap.png))
    assert img.format == "PNG" and img.size == (1024, 768) and (cap.width, cap.height) == (1024, 768)
    assert cap.path == "captures/000001.png" and (episode.run_dir / cap.path).read_bytes() == cap.png
    arr = np.asarray(img.convert("RGB"), dtype=float)
    assert arr.std() > 1.0  # parts are visible, not a blank frame
    episode.close()
    assert read_trajectory(episode.run_dir / "trajectory.jsonl").calls[0].image == cap.path


def test_renderer_failure_is_an_internal_error(tmp_path):
    task, meshes = _task()

    def broken(_meshes):
        raise RuntimeError("no GL here: /usr/lib/secret/libEGL.so")

    ep = Episode(task, meshes, tmp_path / "run", renderer_factory=broken)
    with pytest.raises(EpisodeError) as info:
        ep.call("capture_scene")
    assert str(info.value) == "capture_scene failed with an internal error; the scene is unchanged"
    assert ep.call("list_objects")["objects"][0]["id"] == "p01"  # still serving
    ep.close()
    calls = read_trajectory(tmp_path / "run" / "trajectory.jsonl").calls
    assert calls[0].error.startswith("internal error: RuntimeError") and calls[0].image is None


def test_huge_integers_are_recorded_not_fatal(episode):
    """Integers beyond 64 bits (a fuzzer's) are recorded as text; recording never fails on them."""
    for value in (10**30, -(10**30), 10**5000):
        with pytest.raises(EpisodeError, match="invalid arguments"):
            episode.call("list_objects", {"x": value})
    episode.reject("get_object", {"id": 2**64}, "invalid")
    episode.close()
    traj = read_trajectory(episode.run_dir / "trajectory.jsonl")
    assert [c.args for c in traj.calls] == [
        {"x": str(10**30)},
        {"x": str(-(10**30))},
        {"x": "<integer of 16610 bits>"},
        {"id": str(2**64)},
    ]


def test_unrecordable_text_and_depth_are_recorded_escaped(episode):
    """Lone surrogates (JSON's "\\ud800" decodes to one) and deep nesting once made the recorder
    raise after the scene had changed: a group existed that no line recorded."""
    group = episode.call("group_objects", {"ids": ["p01", "p02"], "name": "a\ud800b"})["group"]
    deep: list = []
    for _ in range(300):
        deep = [deep]
    episode.reject("translate_objects", {"ids": ["p01"], "delta": deep, "\udc00": 1}, "bad \ud83d")
    with pytest.raises(EpisodeError):
        episode.call("list_objects", {"x": deep})
    episode.close()
    calls = read_trajectory(episode.run_dir / "trajectory.jsonl").calls
    assert [c.tool for c in calls] == ["group_objects", "translate_objects", "list_objects"]
    assert calls[0].ok and calls[0].args["name"] == "a\\ud800b" and episode.scene.groups[group["id"]]
    assert calls[1].error == "bad \\ud83d" and "\\udc00" in calls[1].args
    level = calls[1].args["delta"]
    for _ in range(31):
        level = level[0]
    assert level == "<nested deeper than 32 levels>"


def _fail_trajectory_writes(ep: Episode) -> None:
    """From now on the trajectory's writes fail as on a full disk (ENOSPC from /dev/full)."""
    full = os.open("/dev/full", os.O_WRONLY)
    os.dup2(full, ep._writer._fd)
    os.close(full)


@pytest.mark.parametrize(
    "tool, args",
    [
        ("translate_objects", {"ids": ["p01"], "delta": [1, 0, 0]}),
        ("rotate_objects", {"ids": ["p01", "p02"], "angles": [0, 0, 90]}),
        ("set_object_pose", {"id": "p02", "position": [0, 1, 0]}),
        ("group_objects", {"ids": ["p01", "p02"], "name": "pair"}),
        ("ungroup_objects", {"ids": ["g1"]}),
        ("move_camera", {"yaw": 30}),
        ("capture_scene", {}),
    ],
)
def test_a_call_whose_recording_fails_changes_nothing(episode, tool, args, caplog):
    """Record first, or undo: the reply says recording failed, the scene, groups and camera are
    as before, no capture file is left, and the episode takes no further calls."""
    if tool == "ungroup_objects":
        episode.call("group_objects", {"ids": ["p01", "p02"]})
    before = episode.call("get_state")
    n_captures = len(list((episode.run_dir / "captures").iterdir()))
    _fail_trajectory_writes(episode)
    with pytest.raises(EpisodeError) as info:
        episode.call(tool, args)
    message = str(info.value)
    assert message.startswith("recording failed (No space left on device)") and "\n" not in message
    assert "Errno" not in message
    assert episode.scene.pose_dict() == {
        p: [float(v) for v in before["poses"][p]["position"] + before["poses"][p]["quaternion"]]
        for p in episode.part_ids
    }
    assert episode.scene.groups_list() == before["groups"]
    assert episode.scene.camera.describe() == before["camera"]
    assert len(list((episode.run_dir / "captures").iterdir())) == n_captures
    for later in [("get_state", {}), ("translate_objects", {"ids": ["p02"], "delta": [0, 0, 1]})]:
        with pytest.raises(EpisodeError, match="recording failed"):
            episode.call(*later)
    assert episode.reject("get_object", {"id": 1}, "id must be a string").startswith("recording failed")
    assert [r.levelname for r in caplog.records if "recording" in r.getMessage()] == ["ERROR"]  # once
