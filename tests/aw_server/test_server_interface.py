"""What a harness sees before it calls anything: tools and their closed schemas, the task prompt,
the reference images (MCP prompt, MCP resources, files), and the CLI's print modes."""

from __future__ import annotations

import base64
import subprocess
import sys

import anyio
import pytest
from aw_server_helpers import server_params
from mcp import Client

from aw.formats import read_task, read_trajectory
from aw.prompt import task_prompt

pytestmark = pytest.mark.anyio

TOOLS = {
    "list_objects",
    "get_object",
    "get_scene",
    "get_state",
    "translate_objects",
    "rotate_objects",
    "set_object_pose",
    "group_objects",
    "ungroup_objects",
    "capture_scene",
    "move_camera",
    "start_episode",
}


def _props(tool):
    return tool.input_schema["properties"]


async def test_tools_prompt_and_resources(manual_task, tmp_path):
    task_dir, _, _ = manual_task
    task = read_task(task_dir)
    async with Client(server_params(task_dir, tmp_path / "run")) as c:
        assert "+Z" in c.instructions and "[w, x, y, z]" in c.instructions
        listed = (await c.list_tools()).tools
        tools = {t.name: t for t in listed}
        assert set(tools) == TOOLS and len(listed) == len(TOOLS)
        for t in listed:
            s = t.input_schema
            assert s["type"] == "object" and s["additionalProperties"] is False, t.name
            # Flat, null-free schemas: nothing a harness could choke on.
            assert "anyOf" not in str(s) and "$ref" not in str(s), t.name
            assert len(t.description) > 80, t.name

        for name in ("list_objects", "get_scene", "get_state", "capture_scene"):
            assert _props(tools[name]) == {} and "required" not in tools[name].input_schema
        assert tools["get_object"].input_schema["required"] == ["id"]

        tr = tools["translate_objects"]
        assert tr.input_schema["required"] == ["ids", "delta"]
        ids = _props(tr)["ids"]
        assert ids["type"] == "array" and ids["minItems"] == 1 and ids["uniqueItems"] is True
        assert ids["items"]["type"] == "string"
        delta = _props(tr)["delta"]
        assert delta["minItems"] == delta["maxItems"] == 3 and delta["items"]["type"] == "number"
        assert delta["items"]["maximum"] == 1000 and delta["items"]["minimum"] == -1000
        assert _props(tr)["space"]["enum"] == ["world", "camera"] and _props(tr)["space"]["default"] == "world"

        rot = tools["rotate_objects"]
        assert rot.input_schema["required"] == ["ids", "angles"]
        assert set(_props(rot)) == {"ids", "angles", "space", "pivot"}
        assert _props(rot)["pivot"]["type"] == "array" and _props(rot)["pivot"]["minItems"] == 3
        assert "X axis first, then Y, then Z" in _props(rot)["angles"]["description"]
        assert "degrees" in _props(rot)["angles"]["description"]
        assert "mean of the selected objects' body origins" in rot.description
        assert "camera frame (X = right, Y = up, Z = forward)" in rot.description

        sp = tools["set_object_pose"]
        assert sp.input_schema["required"] == ["id"] and set(_props(sp)) == {"id", "position", "quaternion"}
        assert _props(sp)["quaternion"]["minItems"] == _props(sp)["quaternion"]["maxItems"] == 4
        assert "[w, x, y, z]" in _props(sp)["quaternion"]["description"]

        assert _props(tools["group_objects"])["name"]["maxLength"] == 200
        assert tools["group_objects"].input_schema["required"] == ["ids"]
        assert tools["ungroup_objects"].input_schema["required"] == ["ids"]

        mc = _props(tools["move_camera"])
        assert (
            set(mc) == {"yaw", "pitch", "zoom", "right", "up"} and "required" not in tools["move_camera"].input_schema
        )
        assert (mc["yaw"]["minimum"], mc["yaw"]["maximum"]) == (-180, 180)
        assert (mc["pitch"]["minimum"], mc["pitch"]["maximum"]) == (-85, 85)
        assert (mc["zoom"]["minimum"], mc["zoom"]["maximum"]) == (0.25, 4)
        assert set(_props(tools["start_episode"])) == {"task"}

        cap = tools["capture_scene"]
        assert "1024x768" in cap.description and "38 degree" in cap.description
        assert "+Z up" in tools["get_object"].description
        for name in ("translate_objects", "rotate_objects", "set_object_pose"):
            assert "status only" in tools[name].description
        assert tools["get_state"].annotations.read_only_hint is True
        assert tools["translate_objects"].annotations.read_only_hint is False
        assert tools["get_scene"].output_schema["type"] == "object" and cap.output_schema is None

        # The task prompt with the reference pages attached in order.
        prompts = (await c.list_prompts()).prompts
        assert [p.name for p in prompts] == ["assembly_task"]
        msgs = (await c.get_prompt("assembly_task")).messages
        assert msgs[0].content.type == "text" and msgs[0].content.text == task.prompt
        pages = [base64.b64decode(m.content.data) for m in msgs[1:]]
        assert pages == [p.read_bytes() for p in task.reference_paths()] and len(pages) == 3

        # The same pages as resources, in order, plus the task text.
        resources = (await c.list_resources()).resources
        assert [r.uri for r in resources] == [
            "aw://task/prompt",
            "aw://task/references/01",
            "aw://task/references/02",
            "aw://task/references/03",
        ]
        assert all(r.mime_type == "image/png" for r in resources[1:])
        text = (await c.read_resource("aw://task/prompt")).contents[0].text
        assert text == task.prompt
        for r, path in zip(resources[1:], task.reference_paths(), strict=True):
            blob = (await c.read_resource(r.uri)).contents[0].blob
            assert base64.b64decode(blob) == path.read_bytes()


async def test_legacy_handshake(box_task, tmp_path):
    """Harnesses such as Claude Code and Codex use the initialize handshake."""
    task_dir, _, _ = box_task
    async with Client(server_params(task_dir, tmp_path / "run"), mode="legacy") as c:
        assert c.protocol_version < "2026"
        assert len((await c.list_tools()).tools) == len(TOOLS)
        r = await c.call_tool("translate_objects", {"ids": ["p01"], "delta": [0, 0, 1]})
        assert not r.is_error and r.structured_content == {"status": "ok", "changed": ["p01"]}

        # Concurrent calls are served one at a time: none is lost, each is recorded once.
        async def nudge():
            assert not (await c.call_tool("translate_objects", {"ids": ["p02"], "delta": [0.25, 0, 0]})).is_error

        async with anyio.create_task_group() as tg:
            for _ in range(12):
                tg.start_soon(nudge)
                tg.start_soon(c.call_tool, "get_state", {})
        st = (await c.call_tool("get_state", {})).structured_content
        assert st["poses"]["p02"]["position"] == [3.0, 0.0, 0.0]
    traj = read_trajectory(tmp_path / "run" / "trajectory.jsonl")
    assert len(traj.calls) == 26 and sum(c.tool == "translate_objects" for c in traj.calls) == 13
    xs = [c.poses["p02"][0] for c in traj.calls if c.poses is not None][1:]
    assert xs == [0.25 * k for k in range(1, 13)]


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "aw_server.cli", *args], capture_output=True, text=True, timeout=60)


def test_print_prompt_and_references(manual_task, box_task):
    task_dir, _, _ = manual_task
    out = _cli(str(task_dir), "--print-prompt")
    assert out.returncode == 0 and out.stdout == task_prompt("manual") + "\n"
    refs = _cli(str(task_dir), "--print-references")
    assert refs.returncode == 0
    assert refs.stdout.splitlines() == [str(p.resolve()) for p in read_task(task_dir).reference_paths()]
    none = _cli(str(box_task[0]), "--print-references")
    assert none.returncode == 0 and none.stdout == ""
