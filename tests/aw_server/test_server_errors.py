"""Bad input through the real client: each call is a tool error that says what was wrong and what is
allowed, leaves the scene unchanged, is recorded, and the server keeps serving. And nothing an
agent can reach (results, errors, prompt, resources) contains a path, a vertex or a target."""

from __future__ import annotations

import json
import math
import re
import subprocess
import threading
from pathlib import Path

import numpy as np
import pytest
import trimesh
from aw_server_helpers import result_text, server_command, server_params
from mcp import Client

from aw.formats import read_trajectory

pytestmark = pytest.mark.anyio

IDENTITY = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]

# (tool, arguments, words the message must contain). "G" is replaced by a real group id.
BAD_CALLS = [
    ("get_object", {"id": "p99"}, ["unknown id 'p99'", "list_objects"]),
    ("get_object", {}, ["id: required argument is missing", "object id or group id"]),
    ("get_object", {"id": 5}, ["id:", "valid string"]),
    ("get_object", {"id": ""}, ["id:", "at least 1 character"]),
    ("translate_objects", {"ids": [], "delta": [0, 0, 0]}, ["ids:", "at least 1 item", "One or more unique"]),
    ("translate_objects", {"ids": ["p01", "p01"], "delta": [1, 0, 0]}, ["ids must be unique"]),
    ("translate_objects", {"ids": "p01", "delta": [1, 0, 0]}, ["ids:", "valid list"]),
    ("translate_objects", {"ids": [1], "delta": [1, 0, 0]}, ["ids[0]:", "valid string"]),
    ("translate_objects", {"ids": ["p01", "p77"], "delta": [1, 0, 0]}, ["unknown id 'p77'"]),
    ("translate_objects", {"ids": ["p01"], "delta": ["NaN", 0, 0]}, ["delta[0]:", "valid number", "'NaN'", "+-1000"]),
    ("translate_objects", {"ids": ["p01"], "delta": [math.nan, 0, 0]}, ["delta[0]:", "valid number"]),
    ("translate_objects", {"ids": ["p01"], "delta": [0, math.inf, 0]}, ["delta[1]:", "valid number"]),
    ("translate_objects", {"ids": ["p01"], "delta": [1e308, 0, 0]}, ["delta[0]:", "less than or equal to 1000"]),
    ("translate_objects", {"ids": ["p01"], "delta": [0, 0, -2e3]}, ["delta[2]:", "greater than or equal to -1000"]),
    ("translate_objects", {"ids": ["p01"], "delta": [1, 2]}, ["delta:", "at least 3 items"]),
    ("translate_objects", {"ids": ["p01"], "delta": [True, 0, 0]}, ["delta[0]:", "valid number"]),
    ("translate_objects", {"ids": ["p01"], "delta": "up"}, ["delta:", "valid list"]),
    # Arrays sent as JSON strings are what the schema refuses (no pre-parsing of strings).
    ("translate_objects", {"ids": '["p01"]', "delta": [1, 0, 0]}, ["ids:", "valid list"]),
    ("translate_objects", {"ids": ["p01"], "delta": "[1, 0, 0]"}, ["delta:", "valid list"]),
    ("move_camera", {"yaw": "10"}, ["yaw:", "valid number"]),
    ("translate_objects", {"ids": ["p01"], "delta": [1, 0, 0], "space": "local"}, ["space:", "'world' or 'camera'"]),
    (
        "translate_objects",
        {"ids": ["p01"], "delta": [1, 0, 0], "speed": 2},
        ["unexpected argument 'speed'", "ids, delta, space"],
    ),
    ("translate_objects", {"delta": [1, 0, 0]}, ["ids: required argument is missing"]),
    ("rotate_objects", {"ids": ["p01"], "angles": [1e5, 0, 0]}, ["angles[0]:", "less than or equal to 3600"]),
    ("rotate_objects", {"ids": ["p01"], "angles": [0, 0, 0], "pivot": [0, 0]}, ["pivot:", "at least 3 items"]),
    ("rotate_objects", {"ids": ["p01"], "angles": [0, 0, 0], "pivot": [0, "x", 0]}, ["pivot[1]:", "valid number"]),
    ("rotate_objects", {"ids": ["p01"], "angles": [0, 0, 90], "space": "object"}, ["space:", "'world' or 'camera'"]),
    ("rotate_objects", {"ids": [], "angles": [0, 0, 90]}, ["ids:", "at least 1 item"]),
    ("set_object_pose", {"id": "p01"}, ["give position and/or quaternion"]),
    ("set_object_pose", {"id": "p01", "quaternion": [0, 0, 0, 0]}, ["quaternion has zero length"]),
    ("set_object_pose", {"id": "p01", "quaternion": [1, 0, 0]}, ["quaternion:", "at least 4 items", "[w, x, y, z]"]),
    ("set_object_pose", {"id": "p01", "position": [1e308, 0, 0]}, ["position[0]:", "less than or equal to 1000"]),
    ("set_object_pose", {"id": "G", "position": [0, 0, 0]}, ["a group id", "single object id"]),
    ("set_object_pose", {"id": "p42", "position": [0, 0, 0]}, ["unknown object id 'p42'"]),
    ("group_objects", {"ids": ["p01"], "name": "x" * 201}, ["name:", "at most 200 characters"]),
    ("group_objects", {"ids": ["nope"]}, ["unknown id 'nope'"]),
    ("ungroup_objects", {"ids": ["p01"]}, ["not group ids", "p01"]),
    ("ungroup_objects", {"ids": []}, ["ids:", "at least 1 item"]),
    ("move_camera", {"yaw": 200}, ["yaw:", "less than or equal to 180"]),
    ("move_camera", {"pitch": -90}, ["pitch:", "greater than or equal to -85"]),
    ("move_camera", {"zoom": 0}, ["zoom:", "greater than or equal to 0.25"]),
    ("move_camera", {"zoom": 5}, ["zoom:", "less than or equal to 4"]),
    ("move_camera", {"pitch": "up"}, ["pitch:", "valid number"]),
    ("move_camera", {"roll": 10}, ["unexpected argument 'roll'", "yaw, pitch, zoom, right, up"]),
    ("capture_scene", {"x": 1}, ["unexpected argument 'x'", "none (call it with no arguments)"]),
    ("list_objects", {"verbose": True}, ["unexpected argument 'verbose'"]),
    ("start_episode", {"task": 5}, ["task:", "valid string"]),
]

FORBIDDEN_KEYS = {"vertices", "faces", "triangles", "mesh", "path", "file", "targets", "target_pose"}
ABS_PATH = re.compile(r"(?:^|[\s\"'(=:,\[])/[A-Za-z0-9_.~-]+/")
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


class LeakChecker:
    """Collects everything an agent can read and checks it against the hidden data."""

    def __init__(self, task_dir: Path, targets):
        self.task_dir = task_dir
        self.vertices = np.concatenate(
            [trimesh.load(p, force="mesh", process=False).vertices for p in sorted((task_dir / "parts").glob("*.obj"))]
        )
        poses = np.array([t.pose for t in targets.parts.values()])
        self.target_numbers = poses.ravel()
        self.checked = 0

    def _numbers(self, text: str) -> np.ndarray:
        return np.array([float(x) for x in NUMBER.findall(text)] or [np.nan])

    def check_text(self, text: str) -> None:
        self.checked += 1
        for needle in (
            str(self.task_dir),
            str(self.task_dir.parent.parent),
            "targets",
            ".obj",
            "parts/",
            "references/",
        ):
            assert needle not in text, (needle, text[:300])
        assert not ABS_PATH.search(text), text[:300]
        nums = self._numbers(text)
        # No target pose component, and no vertex given as three consecutive numbers.
        near = np.abs(nums[:, None] - self.target_numbers[None, :]) < 1e-9
        # Trivial values (0, +-1) can appear for other reasons (identity poses).
        trivial = np.isclose(np.abs(self.target_numbers), 0) | np.isclose(np.abs(self.target_numbers), 1)
        assert not (near & ~trivial[None, :]).any(), text[:300]
        if len(nums) >= 3:
            triples = np.lib.stride_tricks.sliding_window_view(nums, 3)
            d = np.abs(triples[:, None, :] - self.vertices[None, :, :]).max(axis=2)
            assert not (d < 1e-7).any(), text[:300]

    def check_keys(self, obj) -> None:
        if isinstance(obj, dict):
            assert not (set(obj) & FORBIDDEN_KEYS), set(obj)
            for v in obj.values():
                self.check_keys(v)
        elif isinstance(obj, list):
            for v in obj:
                self.check_keys(v)

    def check_result(self, result) -> None:
        self.check_text(result_text(result))
        if result.structured_content is not None:
            self.check_keys(result.structured_content)


async def test_bad_input_and_no_leaks(box_task, tmp_path):
    task_dir, _, targets = box_task
    run = tmp_path / "run"
    leaks = LeakChecker(task_dir, targets)
    async with Client(server_params(task_dir, run)) as c:
        # Valid calls on every tool: nothing hidden in the results either.
        for tool, args in [
            ("start_episode", {}),
            ("list_objects", {}),
            ("get_object", {"id": "p01"}),
            ("get_object", {"id": "p03"}),
            ("get_scene", {}),
            ("get_state", {}),
            ("capture_scene", {}),
            ("move_camera", {"yaw": 10}),
        ]:
            r = await c.call_tool(tool, args)
            assert not r.is_error, result_text(r)
            leaks.check_result(r)
        g = await c.call_tool("group_objects", {"ids": ["p02", "p03"]})
        gid = g.structured_content["group"]["id"]
        leaks.check_result(g)
        leaks.check_result(await c.call_tool("get_object", {"id": gid}))
        initial = (await c.call_tool("get_state", {})).structured_content

        messages = []
        for tool, args, words in BAD_CALLS:
            args = {k: (gid if v == "G" else v) for k, v in args.items()}
            r = await c.call_tool(tool, args)
            text = result_text(r)
            assert r.is_error, (tool, args, text)
            assert text.startswith(f"Error executing tool {tool}: "), text
            for w in words:
                assert w in text, (tool, args, w, text)
            leaks.check_result(r)
            messages.append(text)
            # The server keeps serving and the scene is unchanged.
            state = (await c.call_tool("get_state", {})).structured_content
            assert state["poses"] == initial["poses"] and state["groups"] == initial["groups"], (tool, args)
        # Edits that would leave the allowed range are refused as a whole.
        far = await c.call_tool("translate_objects", {"ids": [gid, "p01"], "delta": [999, 0, 0]})
        assert not far.is_error
        beyond = await c.call_tool("translate_objects", {"ids": ["p01", "p02"], "delta": [2, 0, 0]})
        assert beyond.is_error and "beyond" in result_text(beyond)
        leaks.check_result(beyond)
        state = (await c.call_tool("get_state", {})).structured_content
        assert all(state["poses"][p]["position"][0] == 999 for p in ("p01", "p02", "p03"))

        unknown = await c.call_tool("reset_scene", {})
        assert unknown.is_error and "reset_scene" in result_text(unknown)
        # The prompt and the resources are agent-visible too.
        prompt = await c.get_prompt("assembly_task")
        leaks.check_text(" ".join(m.content.text for m in prompt.messages if m.content.type == "text"))
        res = await c.list_resources()
        leaks.check_text(json.dumps([r.model_dump(mode="json") for r in res.resources]))
        tools = await c.list_tools()
        leaks.check_text(json.dumps([t.model_dump(mode="json") for t in tools.tools]))
    assert leaks.checked > len(BAD_CALLS)

    # Every rejected call is in the trajectory with the message the agent got.
    traj = read_trajectory(run / "trajectory.jsonl")
    errors = [c for c in traj.calls if not c.ok]
    assert len(errors) == len(BAD_CALLS) + 1  # the bad calls, then the edit beyond the range
    assert errors[-1].tool == "translate_objects" and "beyond" in (errors[-1].error or "")
    for rec, msg, (tool, _, _) in zip(errors[:-1], messages, BAD_CALLS, strict=True):
        assert rec.tool == tool and msg.endswith(rec.error) and rec.poses is None and rec.changed == []
    # Arguments are recorded as sent (NaN from the Python client arrives as null).
    nan_rec = errors[[i for i, b in enumerate(BAD_CALLS) if b[1].get("delta") == ["NaN", 0, 0]][0]]
    assert nan_rec.args["delta"] == ["NaN", 0, 0]
    assert traj.end.reason == "disconnect"


async def test_strings_stay_strings(box_task, tmp_path):
    """Valid strings that look like JSON are taken as the strings they are."""
    task_dir, _, _ = box_task
    async with Client(server_params(task_dir, tmp_path / "run")) as c:
        r = await c.call_tool("start_episode", {"task": "[1,2,3]"})
        assert not r.is_error, result_text(r)
        for name in ("null", "[1]", "{}", "12", "true"):
            g = await c.call_tool("group_objects", {"ids": ["p01"], "name": name})
            assert not g.is_error and g.structured_content["group"]["name"] == name, result_text(g)
    traj = read_trajectory(tmp_path / "run" / "trajectory.jsonl")
    assert traj.calls[0].args == {"task": "[1,2,3]"} and traj.calls[1].args["name"] == "null"


def _rpc(id_: int, method: str, params: dict) -> str:
    return json.dumps({"jsonrpc": "2.0", "id": id_, "method": method, "params": params})


def test_raw_json_numbers(box_task, tmp_path):
    """Numbers only a raw JSON client can send (1e999, NaN, Infinity tokens), and a broken line."""
    task_dir, _, _ = box_task
    run = tmp_path / "run"
    init = {"protocolVersion": "2025-06-18", "capabilities": {}, "clientInfo": {"name": "raw", "version": "0"}}
    call = '{"jsonrpc":"2.0","id":%d,"method":"tools/call","params":{"name":"translate_objects","arguments":{"ids":["p01"],"delta":%s}}}'
    proc = subprocess.Popen(
        server_command(task_dir, run), stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    watchdog = threading.Timer(90, proc.kill)
    watchdog.start()

    def ask(line: str, id_: int | None) -> dict | None:
        proc.stdin.write(line + "\n")
        proc.stdin.flush()
        if id_ is None:
            return None
        while True:  # stdin stays open until the reply arrives: EOF would cancel calls in flight
            out = proc.stdout.readline()
            assert out, proc.stderr.read()[-2000:]
            msg = json.loads(out)
            if msg.get("id") == id_:
                return msg

    try:
        assert "result" in ask(_rpc(1, "initialize", init), 1)
        ask(json.dumps({"jsonrpc": "2.0", "method": "notifications/initialized"}), None)
        for i, delta in [(2, "[1e999, 0, 0]"), (3, "[NaN, 0, 0]"), (4, "[0, -Infinity, 0]")]:
            res = ask(call % (i, delta), i)["result"]
            assert res["isError"] is True
            assert "finite number" in res["content"][0]["text"], res
        # Lines the transport cannot decode get a JSON-RPC error reply (with the id when it can be
        # read off the line), never silence.
        broken = ask('{"jsonrpc":"2.0","id":5,"method":"tools/call","params":{"name":"translate_o', 5)
        assert broken["error"]["code"] == -32700
        huge_int = ask(call % (7, "[" + "1" * 5001 + ", 0, 0]"), 7)
        assert huge_int["error"]["code"] == -32700 and "number out of range" in huge_int["error"]["message"]
        deep = ask(call % (8, "[" * 5000 + "]" * 5000), 8)
        assert deep["error"]["code"] == -32700 and "recursion limit" in deep["error"]["message"]
        assert ask('{"jsonrpc":"2.0","id":"s9","params":{}}', "s9")["error"]["code"] == -32600
        assert ask("[1, 2]", None) is None
        not_rpc = json.loads(proc.stdout.readline())
        assert not_rpc["id"] is None and not_rpc["error"]["code"] == -32600
        ok = ask(call % (6, "[0.25, 0, 0]"), 6)["result"]
        assert ok["isError"] is False
        proc.stdin.close()
        assert proc.wait(timeout=60) == 0
    finally:
        watchdog.cancel()
        proc.kill()
        proc.wait()
        proc.stdout.close()
        proc.stderr.close()
    traj = read_trajectory(run / "trajectory.jsonl")
    assert [c.ok for c in traj.calls] == [False, False, False, True]
    assert traj.calls[0].args["delta"] == ["inf", 0, 0]
    assert traj.end.poses["p01"] == [0.25, 0, 0, 1, 0, 0, 0]
    assert traj.end.poses["p02"] == IDENTITY
