"""``aw-serve --surface official`` over stdio with the real MCP client: the official meta-tools,
every page tool through execute_webmcp_tool, error replies, recording, read_manual_page, and the
first steps of an agent written for the official environment."""

from __future__ import annotations

import base64
import io
import json
import math
import re

import numpy as np
import pytest
from aw_server_helpers import server_params
from mcp import Client
from PIL import Image

from aw.formats import read_final, read_trajectory

pytestmark = pytest.mark.anyio

META = ["list_pages", "list_webmcp_tools", "execute_webmcp_tool", "read_manual_page"]
PAGE_TOOLS = [
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
]


def official(task_dir, run):
    return server_params(task_dir, run, "--surface", "official")


def text(result) -> str:
    return "\n".join(c.text for c in result.content if c.type == "text")


async def execute(c, tool, args, page_id=1):
    """One execute_webmcp_tool call: (reply dict, output dict, MCP result)."""
    raw = args if isinstance(args, str) else json.dumps(args)
    r = await c.call_tool("execute_webmcp_tool", {"pageId": page_id, "toolName": tool, "input": raw})
    assert not r.is_error, text(r)
    reply = json.loads(text(r))
    assert set(reply) == {"status", "output", "errorText"} and reply["status"] == "Completed"
    assert reply["errorText"] is None and isinstance(reply["output"], str)
    return reply, json.loads(reply["output"]), r


def page_id_from(listing: str, url_part: str) -> int:
    """How the official runner finds its page: lines ``<id>: <label>`` naming the page's URL."""
    ids = [int(m[1]) for line in listing.splitlines() if (m := re.match(r"^(\d+): (.+)", line)) and url_part in m[2]]
    assert len(ids) == 1, listing
    return ids[0]


def elevation(camera) -> float:
    d = np.subtract(camera["position"], camera["target"])
    return math.degrees(math.asin(d[2] / np.linalg.norm(d)))


async def test_meta_tools_and_every_page_tool(manual_task, tmp_path):
    task_dir, _, _ = manual_task
    run = tmp_path / "run"
    async with Client(official(task_dir, run)) as c:
        tools = {t.name: t for t in (await c.list_tools()).tools}
        assert list(tools) == META
        schemas = {n: t.input_schema for n, t in tools.items()}
        assert all(s["type"] == "object" and s["additionalProperties"] is False for s in schemas.values())
        assert schemas["execute_webmcp_tool"]["required"] == ["pageId", "toolName"]
        assert schemas["execute_webmcp_tool"]["properties"]["input"]["type"] == "string"
        assert schemas["list_webmcp_tools"]["properties"]["pageId"]["type"] == "number"
        assert schemas["read_manual_page"]["properties"]["page"] == {"type": "integer", "minimum": 1}

        listing = text(await c.call_tool("list_pages", {}))
        assert listing.splitlines()[0] == "## Pages"
        page = page_id_from(listing, "box3_manual")
        assert page == 1 and listing.endswith("[selected]")

        defs = json.loads(text(await c.call_tool("list_webmcp_tools", {"pageId": page})))
        assert [d["name"] for d in defs] == PAGE_TOOLS
        by_name = {d["name"]: d for d in defs}
        for d in defs:
            assert set(d) == {"name", "description", "inputSchema", "annotations"}
            assert d["inputSchema"]["additionalProperties"] is False
        assert by_name["capture_scene"]["annotations"] == {"readOnlyHint": True}
        assert by_name["translate_objects"]["annotations"] == {"readOnlyHint": False}
        cam = by_name["move_camera"]["inputSchema"]["properties"]
        assert (
            cam["yaw"]["minimum"],
            cam["yaw"]["maximum"],
            cam["pitch"]["minimum"],
            cam["pitch"]["maximum"],
            cam["zoom"]["minimum"],
            cam["zoom"]["maximum"],
        ) == (-180, 180, -85, 85, 0.25, 4)
        assert by_name["group_objects"]["inputSchema"]["properties"]["name"]["maxLength"] == 200
        assert by_name["set_object_pose"]["inputSchema"]["anyOf"] == [
            {"required": ["position"]},
            {"required": ["quaternion"]},
        ]

        _, out, _ = await execute(c, "start_episode", {"task": "assemble"})
        assert out == {"status": "active"}
        _, scene, _ = await execute(c, "get_scene", {})
        assert (scene["units"], scene["up"], scene["quaternion"]) == ("normalized", "Z", "wxyz")
        assert scene["runtime"]["physics"]["enabled"] is False
        enabled = scene["runtime"]["enabledTools"]
        assert "apply_force" not in enabled and "capture_scene" in enabled
        assert [o["id"] for o in scene["objects"]] == ["part-0001", "part-0002", "part-0003"]
        _, objs, _ = await execute(c, "list_objects", {})
        assert [o["name"] for o in objs["objects"]] == ["Part p01", "Part p02", "Part p03"] and objs["groups"] == []
        _, obj, _ = await execute(c, "get_object", {"id": "part-0002"})
        assert obj["position"] == [0.0, 0.0, 0.0] and obj["quaternion"] == [1.0, 0.0, 0.0, 0.0]
        assert obj["movable"] is True and len(obj["geometries"]) == 1

        _, out, _ = await execute(c, "translate_objects", {"ids": ["part-0002"], "delta": [0.0, -0.5, 0.3]})
        assert out == {"status": "completed", "physics": "disabled", "index": 1}
        _, out, _ = await execute(c, "rotate_objects", {"ids": ["part-0003"], "angles": [90, 0, 0], "pivot": [0, 0, 0]})
        assert out["index"] == 2
        _, out, _ = await execute(
            c, "set_object_pose", {"id": "part-0001", "position": [0.1, 0.2, 0.3], "quaternion": [0, 0, 0, 2]}
        )
        assert out["index"] == 3
        _, out, _ = await execute(c, "group_objects", {"ids": ["part-0001", "part-0002"], "name": "top"})
        gid = out["result"]["id"]
        assert out["result"] == {"id": gid, "name": "top", "members": ["part-0001", "part-0002"]}
        assert gid.startswith("group-") and out["index"] == 4
        _, out, _ = await execute(c, "translate_objects", {"ids": [gid], "delta": [0, 0, 1], "space": "world"})
        assert out["index"] == 5
        _, out, _ = await execute(c, "ungroup_objects", {"ids": [gid]})
        assert out == {"status": "completed", "index": 6}
        _, before, _ = await execute(c, "get_state", {})
        _, out, _ = await execute(c, "move_camera", {"yaw": 30, "pitch": 10, "zoom": 0.8})
        assert out == {"status": "completed", "index": 7}
        _, state, _ = await execute(c, "get_state", {})
        assert state["index"] == 7 and state["groups"] == [] and state["contacts"] == []
        assert elevation(state["camera"]) == pytest.approx(elevation(before["camera"]) - 10)
        dist = [np.linalg.norm(np.subtract(s["camera"]["position"], s["camera"]["target"])) for s in (before, state)]
        assert dist[1] == pytest.approx(0.8 * dist[0])
        poses = {o["id"]: o for o in state["objects"]}
        assert poses["part-0001"]["position"] == pytest.approx([0.1, 0.2, 1.3])
        assert poses["part-0001"]["quaternion"] == pytest.approx([0, 0, 0, 1])
        assert poses["part-0002"]["position"] == pytest.approx([0.0, -0.5, 1.3])
        h = math.sqrt(0.5)
        assert poses["part-0003"]["quaternion"] == pytest.approx([h, h, 0, 0])

        reply, cap, result = await execute(c, "capture_scene", {})
        images = [b for b in result.content if b.type == "image"]
        assert len(images) == 1 and images[0].mime_type == "image/png"
        png = Image.open(io.BytesIO(base64.b64decode(images[0].data)))
        assert png.size == (1024, 768)
        assert cap["content"] == [{"type": "text", "text": "Image attached as MCP image content."}]
        assert cap["render"] == {"width": 1024, "height": 768, "pixelRatio": 1, "fovy": 38, "near": 0.01, "far": 1000}
        assert cap["camera"] == state["camera"] and images[0].data not in text(result)

        refs = sorted((task_dir / "references").iterdir())
        for k, ref in enumerate(refs, start=1):
            r = await c.call_tool("read_manual_page", {"page": k})
            assert not r.is_error and [b.type for b in r.content] == ["image"]
            assert base64.b64decode(r.content[0].data) == ref.read_bytes() and r.content[0].mime_type == "image/png"
        for bad, expected in (
            (0, "page must be >= 1"),
            (4, "page 4 is out of range; this task has 3 reference pages"),
            ("1", "page must be an integer, got a string"),
            (1.0, "page must be an integer"),
        ):
            r = await c.call_tool("read_manual_page", {"page": bad})
            assert r.is_error and expected in text(r), text(r)

    # Recorded as the default surface records: project tool names and part ids, every state.
    traj = read_trajectory(run / "trajectory.jsonl")
    assert [x.tool for x in traj.calls] == [
        "start_episode",
        "get_scene",
        "list_objects",
        "get_object",
        "translate_objects",
        "rotate_objects",
        "set_object_pose",
        "group_objects",
        "translate_objects",
        "ungroup_objects",
        "get_state",
        "move_camera",
        "get_state",
        "capture_scene",
    ]
    assert all(x.ok and x.episode_active for x in traj.calls)
    assert traj.calls[4].args == {"ids": ["p02"], "delta": [0.0, -0.5, 0.3]} and traj.calls[4].changed == ["p02"]
    assert traj.calls[7].args == {"ids": ["p01", "p02"], "name": "top", "exclusive": True}
    assert traj.calls[8].args["ids"] == ["g1"] and traj.calls[11].args == {"yaw": 30, "pitch": -10, "zoom": 0.8}
    assert traj.calls[13].image and (run / traj.calls[13].image).is_file()
    final = read_final(run / "final.json")
    assert final.poses["p02"][:3] == pytest.approx([0.0, -0.5, 1.3])


async def test_error_replies(box_task, tmp_path):
    task_dir, targets_path, _ = box_task
    run = tmp_path / "run"
    secret = targets_path.read_text()
    async with Client(official(task_dir, run)) as c:
        # Meta-call errors: MCP tool errors naming the argument; nothing reaches the scene.
        meta_cases = [
            ("list_pages", {"x": 1}, "unexpected argument 'x'"),
            ("list_webmcp_tools", {}, "pageId is required"),
            ("list_webmcp_tools", {"pageId": 2}, "pageId 2 is not the episode page"),
            ("list_webmcp_tools", {"pageId": "1"}, "pageId must be a number, got a string"),
            ("execute_webmcp_tool", {"pageId": 1}, "toolName is required"),
            ("execute_webmcp_tool", {"pageId": 7, "toolName": "list_objects"}, "pageId 7 is not the episode page"),
            (
                "execute_webmcp_tool",
                {"pageId": 1, "toolName": "apply_force", "input": "{}"},
                "'apply_force' is not registered on the episode page (it needs physics",
            ),
            (
                "execute_webmcp_tool",
                {"pageId": 1, "toolName": "advance_simulation", "input": '{"duration": 1}'},
                "'advance_simulation' is not registered",
            ),
            ("execute_webmcp_tool", {"pageId": 1, "toolName": "end_episode"}, "'end_episode' is not registered"),
            (
                "execute_webmcp_tool",
                {"pageId": 1, "toolName": "list_objects", "input": "{ids: 1}"},
                "input is not valid JSON",
            ),
            (
                "execute_webmcp_tool",
                {"pageId": 1, "toolName": "list_objects", "input": "[1, 2]"},
                "input must encode a JSON object, got an array",
            ),
            (
                "execute_webmcp_tool",
                {"pageId": 1, "toolName": "move_camera", "input": '{"yaw": NaN}'},
                "NaN is not a JSON number",
            ),
            (
                "execute_webmcp_tool",
                {"pageId": 1, "toolName": "list_objects", "input": {}},
                "input must be a string, got an object",
            ),
            (
                "execute_webmcp_tool",
                {"pageId": 1, "toolName": "list_objects", "inputs": "{}"},
                "unexpected argument 'inputs'",
            ),
            ("read_manual_page", {"page": 1}, "page 1 is out of range; this task has no reference pages"),
        ]
        for tool, args, expected in meta_cases:
            r = await c.call_tool(tool, args)
            assert r.is_error and expected in text(r), (tool, args, text(r))

        # Page-tool errors: a completed call whose output is the official error object.
        page_cases = [
            ("list_objects", {"verbose": True}, "unexpected argument 'verbose'"),
            ("translate_objects", {"ids": ["part-0001"], "delta": [1, 0]}, "delta must have exactly 3 items"),
            ("translate_objects", {"ids": ["part-0001"], "delta": "[1, 0, 0]"}, "delta must be an array"),
            ("translate_objects", {"ids": [], "delta": [1, 0, 0]}, "ids must have at least 1 item"),
            ("translate_objects", {"ids": ["p01"], "delta": [1, 0, 0]}, "unknown object or group id 'p01'"),
            ("translate_objects", '{"ids": ["part-0001"], "delta": [1e999, 0, 0]}', "delta[0] must be a finite number"),
            ("rotate_objects", {"ids": ["part-0001"], "angles": [0, 0, 1], "space": "local"}, "space must be one of"),
            ("set_object_pose", {"id": "part-0001"}, "give at least one of position or quaternion"),
            ("set_object_pose", {"id": "part-0001", "quaternion": [0, 0, 0, 0]}, "quaternion has zero length"),
            ("group_objects", {"ids": ["part-0001"]}, "ids must name at least two objects"),
            ("group_objects", {"ids": ["part-0001", "part-0002"], "name": "x" * 201}, "name must have at most 200"),
            ("ungroup_objects", {"ids": ["part-0001"]}, "unknown group id 'part-0001'"),
            ("get_object", {"id": "part-0009"}, "unknown object id 'part-0009'"),
            ("move_camera", {"yaw": 200}, "yaw must be <= 180, got 200"),
            ("move_camera", {"pitch": -90}, "pitch must be >= -85, got -90"),
            ("move_camera", {"zoom": 0.1}, "zoom must be >= 0.25, got 0.1"),
        ]
        for tool, args, expected in page_cases:
            _, out, result = await execute(c, tool, args)
            assert set(out) == {"error", "code"} and out["code"] == "invalid_argument", out
            assert expected in out["error"], (tool, out)
            assert str(task_dir) not in text(result) and secret not in text(result)
        _, state, _ = await execute(c, "get_state", {})
        assert state["index"] == 0
        assert all(o["position"] == [0.0, 0.0, 0.0] for o in state["objects"])

    traj = read_trajectory(run / "trajectory.jsonl")
    rejected = [x for x in traj.calls if not x.ok]
    # Every refused execute_webmcp_tool and every refused page call is recorded; the state never moved.
    n_execute_refusals = sum(1 for tool, _, _ in meta_cases if tool == "execute_webmcp_tool")
    assert len(rejected) == n_execute_refusals + len(page_cases)
    assert [x.tool for x in rejected[n_execute_refusals:]] == [t for t, _, _ in page_cases]
    assert all(x.poses is None for x in traj.calls)
    assert all(p == [0, 0, 0, 1, 0, 0, 0] for p in read_final(run / "final.json").poses.values())


async def test_official_first_steps_work_unchanged(box_task, tmp_path):
    """The first steps of the official runner's own live check, word for word in their arguments:
    find the page by its URL, wait for the tools, then start, read, move the first object, capture."""
    task_dir, _, _ = box_task
    run = tmp_path / "run"
    async with Client(official(task_dir, run)) as c:
        page = page_id_from(text(await c.call_tool("list_pages", {})), "box3_none")
        discovery = await c.call_tool("list_webmcp_tools", {"pageId": page})
        assert "No WebMCP tools available" not in text(discovery) and "capture_scene" in text(discovery)

        # No start_episode first: the first page-tool call starts the episode, as on the official page.
        _, scene, _ = await execute(c, "get_scene", {}, page)
        first = scene["objects"][0]["id"]
        await execute(c, "start_episode", {}, page)
        _, out, _ = await execute(c, "translate_objects", {"ids": [first], "delta": [0.1, 0, 0]}, page)
        assert out["status"] == "completed"
        _, cap, result = await execute(c, "capture_scene", {}, page)
        assert [b.type for b in result.content] == ["text", "image"]

    traj = read_trajectory(run / "trajectory.jsonl")
    assert [x.tool for x in traj.calls] == ["get_scene", "start_episode", "translate_objects", "capture_scene"]
    assert all(x.episode_active for x in traj.calls)
    assert traj.calls[2].args == {"ids": ["p01"], "delta": [0.1, 0, 0]}


def test_surface_option_is_checked(box_task, tmp_path):
    import subprocess
    import sys

    task_dir, _, _ = box_task
    cmd = [sys.executable, "-m", "aw_server.cli", str(task_dir), "--record", str(tmp_path / "run"), "--surface", "web"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "--surface: invalid choice: 'web'" in done.stderr
    assert not (tmp_path / "run").exists()
