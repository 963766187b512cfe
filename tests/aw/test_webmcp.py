"""aw.webmcp without MCP: the official page tools' schemas, id mapping, result shapes, error
objects, recording, the implicit start and the group rule."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from aw.episode import Episode
from aw.formats import Task, TaskPart, read_trajectory
from aw.prompt import task_prompt
from aw.webmcp import (
    ENABLED_TOOLS,
    PAGE_TOOLS,
    BadInput,
    NotRegistered,
    WebMcpPage,
    check_arguments,
    mesh_geom_sizes,
    parse_tool_input,
    registered_tools,
)


class Clock:
    def __init__(self):
        self.now = 10.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def page(tmp_path):
    # Part ids deliberately out of order: the catalogue follows the sorted ids.
    ids = ["z9", "a1", "m5"]
    task = Task(
        task_id="t1",
        source="custom",
        dataset="test",
        object_id="t1",
        prompt=task_prompt("none"),
        parts=[TaskPart(id=i, mesh=f"parts/{i}.obj") for i in ids],
    )
    meshes = [
        trimesh.creation.box([0.4, 0.2, 0.1]),
        trimesh.creation.box([0.2, 0.2, 0.2]),
        trimesh.creation.box([0.1, 0.1, 0.3]),
    ]
    clock = Clock()
    ep = Episode(task, meshes, tmp_path / "run", budget_minutes=1.0, clock=clock)
    ep.clock = clock
    yield WebMcpPage(ep)
    ep.close()


def test_registered_tools_follow_enabled_tools():
    assert len(PAGE_TOOLS) == 14
    tools = registered_tools()
    assert tools == [n for n in ENABLED_TOOLS if n != "end_episode"] and len(tools) == 12
    assert "apply_force" not in tools and "advance_simulation" not in tools
    assert registered_tools(("advance_simulation", "list_objects", "list_objects")) == [
        "advance_simulation",
        "list_objects",
    ]
    for t in PAGE_TOOLS.values():
        assert t.input_schema["additionalProperties"] is False


@pytest.mark.parametrize(
    ("tool", "args", "expected"),
    [
        ("list_objects", {"x": 1}, "unexpected argument 'x'"),
        ("get_object", {}, "id is required"),
        ("get_object", {"id": ""}, "id must not be empty"),
        ("translate_objects", {"ids": ["a"], "delta": [1, 2]}, "delta must have exactly 3 items, got 2"),
        ("translate_objects", {"ids": ["a"], "delta": "[1, 2, 3]"}, "delta must be an array, got a string"),
        ("translate_objects", {"ids": [], "delta": [1, 2, 3]}, "ids must have at least 1 item, got 0"),
        ("translate_objects", {"ids": ["a", "a"], "delta": [1, 2, 3]}, "ids must not repeat an item"),
        ("translate_objects", {"ids": ["a"], "delta": [1, True, 3]}, "delta[1] must be a number, got a boolean"),
        ("translate_objects", {"ids": ["a"], "delta": [1, float("inf"), 3]}, "delta[1] must be a finite number"),
        ("translate_objects", {"ids": ["a"], "delta": [1, 2, 3], "space": "local"}, "space must be one of"),
        ("rotate_objects", {"ids": ["a"], "angles": [1, 2, 3], "pivot": [0, 0]}, "pivot must have exactly 3 items"),
        ("set_object_pose", {"id": "a"}, "give at least one of position or quaternion"),
        ("set_object_pose", {"id": "a", "quaternion": [1, 0, 0]}, "quaternion must have exactly 4 items"),
        ("group_objects", {"ids": ["a"], "name": "n" * 201}, "name must have at most 200 characters, got 201"),
        ("move_camera", {"yaw": 180.5}, "yaw must be <= 180, got 180.5"),
        ("move_camera", {"pitch": -86}, "pitch must be >= -85, got -86"),
        ("move_camera", {"zoom": 0.2}, "zoom must be >= 0.25, got 0.2"),
        ("move_camera", {"zoom": 4.5}, "zoom must be <= 4, got 4.5"),
        ("apply_force", {"id": "a", "force": [1, 2]}, "force must have exactly 3 items"),
        ("advance_simulation", {"duration": 0}, "duration must be > 0, got 0"),
        ("advance_simulation", {"duration": 61}, "duration must be <= 60, got 61"),
        ("start_episode", {"task": 3}, "task must be a string, got a number"),
    ],
)
def test_schema_errors_name_the_argument(tool, args, expected):
    problems = check_arguments(PAGE_TOOLS[tool].input_schema, args)
    assert any(expected in p for p in problems), problems


@pytest.mark.parametrize(
    ("tool", "args"),
    [
        ("move_camera", {}),
        ("move_camera", {"yaw": -180, "pitch": 85, "zoom": 0.25, "right": 1e3, "up": -2}),
        ("set_object_pose", {"id": "a", "quaternion": [1, 0, 0, 0]}),
        ("advance_simulation", {"duration": 60}),
        ("group_objects", {"ids": ["a", "b"], "name": "n" * 200}),
        ("start_episode", {"task": "x"}),
    ],
)
def test_schema_accepts_the_bounds(tool, args):
    assert check_arguments(PAGE_TOOLS[tool].input_schema, args) == []


def test_catalogue_ids_and_recording(page):
    ep = page.episode
    out = page.execute("list_objects", {}).output
    assert out == {
        "objects": [
            {"id": f"part-000{k}", "name": f"Part {pid}", "type": "rigid", "collisionEnabled": False}
            for k, pid in ((1, "a1"), (2, "m5"), (3, "z9"))
        ],
        "groups": [],
    }
    # The first page-tool call started the episode (as the official runtime does).
    assert ep.started
    r = page.execute("translate_objects", {"ids": ["part-0003"], "delta": [0.5, 0, 0]})
    assert r.output == {"status": "completed", "physics": "disabled", "index": 1}
    assert ep.scene.poses["z9"][:3].tolist() == [0.5, 0.0, 0.0]
    obj = page.execute("get_object", {"id": "part-0003"}).output
    assert obj["position"] == [0.5, 0.0, 0.0] and obj["quaternion"] == [1.0, 0.0, 0.0, 0.0]
    # MuJoCo's mesh geom size: half-sizes in the principal frame (box 0.4 x 0.2 x 0.1, smallest first).
    assert obj["geometries"][0]["index"] == 2 and obj["geometries"][0]["size"] == pytest.approx([0.05, 0.1, 0.2])
    assert obj["velocity"] == [0.0] * 6 and obj["mass"] == 1.0
    # A scene message that names a part names it by its official id.
    page.execute("translate_objects", {"ids": ["part-0003"], "delta": [900, 0, 0]})
    err = page.execute("translate_objects", {"ids": ["part-0003"], "delta": [900, 0, 0]}).output["error"]
    assert "part-0003" in err and "z9" not in err
    # Recorded under the project's tool name and ids, exactly as the default surface records.
    ep.close()
    calls = read_trajectory(ep.run_dir / "trajectory.jsonl").calls
    assert [c.tool for c in calls][:3] == ["list_objects", "translate_objects", "get_object"]
    assert calls[1].args == {"ids": ["z9"], "delta": [0.5, 0, 0]} and calls[1].changed == ["z9"]
    assert calls[2].args == {"id": "z9"} and all(c.episode_active for c in calls)


def test_refusals_are_error_objects_and_recorded(page):
    ep = page.episode
    cases = [
        ("translate_objects", {"ids": ["a1"], "delta": [1, 0, 0]}, "unknown object or group id 'a1'"),
        ("translate_objects", {"ids": ["part-0001"], "delta": [1, 0]}, "delta must have exactly 3 items"),
        ("set_object_pose", {"id": "part-0001", "quaternion": [0, 0, 0, 0]}, "quaternion has zero length"),
        ("translate_objects", {"ids": ["part-0001"], "delta": [2000, 0, 0]}, "delta"),
        ("get_object", {"id": "group-t1-1"}, "unknown object id 'group-t1-1'"),
        ("ungroup_objects", {"ids": ["part-0001"]}, "unknown group id 'part-0001'"),
        ("group_objects", {"ids": ["part-0001"]}, "ids must name at least two objects"),
        ("rotate_objects", {"ids": ["part-0001"], "angles": [0, 0, 0], "extra": 1}, "unexpected argument 'extra'"),
    ]
    for tool, args, expected in cases:
        r = page.execute(tool, args)
        assert not r.ok and r.output["code"] == "invalid_argument", (tool, r.output)
        assert expected in r.output["error"], r.output
        # Project part ids never appear: the agent only knows the official ones.
        assert "'a1'" not in r.output["error"] or tool == "translate_objects"
    assert all(np.array_equal(p, [0, 0, 0, 1, 0, 0, 0]) for p in ep.scene.poses.values())
    with pytest.raises(NotRegistered, match="apply_force.*needs physics"):
        page.execute("apply_force", {"id": "part-0001", "force": [1, 0, 0]})
    with pytest.raises(NotRegistered, match="end_episode.*registered tools: list_objects"):
        page.execute("end_episode", {})
    ep.close()
    calls = read_trajectory(ep.run_dir / "trajectory.jsonl").calls
    assert len(calls) == len(cases) and not any(c.ok for c in calls)


def test_groups_follow_the_official_rule(page):
    g1 = page.execute("group_objects", {"ids": ["part-0001", "part-0002"]}).output
    assert g1 == {
        "status": "completed",
        "result": {"id": "group-t1-1", "name": "Group", "members": ["part-0001", "part-0002"]},
        "index": 1,
    }
    # A new group sharing a member replaces the old one.
    g2 = page.execute("group_objects", {"ids": ["part-0002", "part-0003"], "name": "pair"}).output
    assert g2["result"] == {"id": "group-t1-2", "name": "pair", "members": ["part-0002", "part-0003"]}
    assert page.execute("list_objects", {}).output["groups"] == [g2["result"]]
    page.execute("translate_objects", {"ids": ["group-t1-2"], "delta": [0, 0, 1]})
    assert [page.episode.scene.poses[p][2] for p in ("a1", "m5", "z9")] == [0.0, 1.0, 1.0]
    r = page.execute("ungroup_objects", {"ids": ["group-t1-1"]})
    assert r.output["code"] == "invalid_argument" and "unknown group id 'group-t1-1'" in r.output["error"]
    assert page.execute("ungroup_objects", {"ids": ["group-t1-2"]}).output == {"status": "completed", "index": 4}
    state = page.execute("get_state", {}).output
    assert state["index"] == 4 and state["groups"] == [] and state["contacts"] == []
    assert set(state["camera"]) == {"position", "target"}


def test_camera_pitch_follows_the_official_sign(page):
    cam = page.episode.scene.camera
    before = (cam.yaw, cam.pitch, cam.distance)
    page.execute("move_camera", {"yaw": 30, "pitch": 10, "zoom": 0.5})
    cam = page.episode.scene.camera
    # Official: a positive pitch lowers the camera (the orbit's polar angle grows).
    assert cam.yaw == pytest.approx(before[0] + 30) and cam.pitch == pytest.approx(before[1] - 10)
    assert cam.distance == pytest.approx(before[2] * 0.5)


def test_budget_end_gives_episode_ended(page):
    page.execute("start_episode", {})
    page.episode.clock.now += 61
    r = page.execute("translate_objects", {"ids": ["part-0001"], "delta": [1, 0, 0]})
    assert r.output["code"] == "episode_ended" and "exhausted" in r.output["error"]
    assert page.execute("get_scene", {}).output["runtime"]["enabledTools"] == list(ENABLED_TOOLS)
    page.episode.close()
    assert page.execute("list_objects", {}).output["code"] == "episode_ended"


def test_geom_sizes_do_not_depend_on_the_placement():
    """The baked task mesh gives the size the official episode reports for the unbaked part."""
    from scipy.spatial.transform import Rotation

    part = trimesh.creation.box([0.3, 0.12, 0.05])
    baked = part.copy()
    baked.apply_transform(
        np.vstack(
            [
                np.hstack(
                    [Rotation.from_euler("xyz", [20, -50, 75], degrees=True).as_matrix(), [[1.0], [-2.0], [0.5]]]
                ),
                [0, 0, 0, 1],
            ]
        )
    )
    a, b = mesh_geom_sizes([part, baked])
    assert a == pytest.approx([0.025, 0.06, 0.15], abs=1e-6) and b == pytest.approx(a, abs=1e-6)
    # A mesh MuJoCo refuses (a single triangle) still gets a size: half its bounding box.
    tri = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 2, 0]], [[0, 1, 2]], process=False)
    assert mesh_geom_sizes([tri]) == [[0.5, 1.0, 0.0]]


@pytest.mark.parametrize(
    "text, message",
    [
        ('{"a": ' + "[" * 40 + "]" * 40 + "}", "input is nested more than 32 levels deep"),
        ('{"a": ' + "[" * 5000 + "]" * 5000 + "}", "input is nested more than 32 levels deep"),
        ('{"name": "x\\ud800"}', "input holds a lone UTF-16 surrogate (\\ud800); strings must be valid Unicode text"),
        ('{"\\udfff": 1}', "input holds a lone UTF-16 surrogate (\\udfff)"),
        ('{"yaw": ' + "9" * 5000 + "}", "input holds a number with more than 4300 digits; numbers must be finite"),
        ('{"yaw": NaN}', "NaN is not a JSON number"),
        ("[1]", "input must encode a JSON object, got an array"),
        ("{", "input is not valid JSON"),
    ],
)
def test_tool_input_that_no_record_could_hold_is_refused_by_name(text, message):
    with pytest.raises(BadInput) as info:
        parse_tool_input(text)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_tool_input_within_limits_passes():
    assert parse_tool_input('{"a": ' + "[" * 30 + "]" * 30 + ', "b": "\\ud83d\\ude00"}')["b"] == "\U0001f600"
    # integers beyond float range pass the decoding and are refused by the argument check, by name
    big = parse_tool_input('{"ids": ["part-0001"], "delta": [%s, 0, 0]}' % ("9" * 400))
    problems = check_arguments(PAGE_TOOLS["translate_objects"].input_schema, big)
    assert problems == ["delta[0] must be a finite number"]
