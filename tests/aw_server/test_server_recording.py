"""Every call is recorded whatever its content, and nothing changes the scene unless its success
is recorded: hostile ``input`` on the official surface (deep nesting, lone surrogates, integers
beyond float range), through the real MCP client over stdio against a real ``aw-serve``."""

from __future__ import annotations

import json

import pytest
from mcp import Client

from aw.formats import read_final, read_trajectory
from aw_server_helpers import result_text, server_params

pytestmark = pytest.mark.anyio

PYTHON_WORDS = ("Traceback", "RecursionError", "OverflowError", "JSONEncodeError", "TypeError", "ValueError",
                "surrogates not allowed", "maximum recursion", "Error executing tool")


def official(task_dir, run):
    return server_params(task_dir, run, "--surface", "official")


def _nested(depth: int) -> str:
    return "[" * depth + "]" * depth


# (tool, input text, words the one-line reply must contain)
HOSTILE_INPUT = [
    ("translate_objects", '{"ids": ["part-0001"], "delta": %s}' % _nested(300), "nested"),
    ("translate_objects", '{"ids": ["part-0001"], "delta": %s}' % _nested(5000), "nested"),
    ("list_objects", '{"x": %s}' % _nested(253), "nested"),
    ("group_objects", '{"ids": ["part-0001", "part-0002"], "name": "a\\ud800b"}', "surrogate"),
    ("list_objects", '{"\\udc00": 1}', "surrogate"),
    ("translate_objects", '{"ids": ["part-0001"], "delta": [%s, 0, 0]}' % ("9" * 400), "finite"),
    ("move_camera", '{"yaw": -%s}' % ("1" * 320), "finite"),
    ("set_object_pose", '{"id": "part-0001", "position": [0, 0, %s]}' % ("7" * 5000), "finite"),
]


async def test_hostile_input_is_answered_in_one_line_and_recorded(box_task, tmp_path):
    task_dir, _, _ = box_task
    run = tmp_path / "run"
    async with Client(official(task_dir, run)) as c:
        state0 = await c.call_tool("execute_webmcp_tool", {"pageId": 1, "toolName": "get_state", "input": "{}"})
        for tool, raw, word in HOSTILE_INPUT:
            r = await c.call_tool("execute_webmcp_tool", {"pageId": 1, "toolName": tool, "input": raw})
            reply = result_text(r)
            if not r.is_error:  # a completed page call: the official error object
                reply = json.loads(json.loads(reply)["output"])["error"]
            assert word in reply and "\n" not in reply and len(reply) < 400, (tool, reply[:500])
            assert not any(w in reply for w in PYTHON_WORDS), (tool, reply[:500])
        state1 = await c.call_tool("execute_webmcp_tool", {"pageId": 1, "toolName": "get_state", "input": "{}"})
        assert result_text(state1) == result_text(state0)  # nothing changed: no group, no move
    traj = read_trajectory(run / "trajectory.jsonl")
    assert len(traj.calls) == len(HOSTILE_INPUT) + 2
    assert [c.ok for c in traj.calls] == [True] + [False] * len(HOSTILE_INPUT) + [True]
    assert all(c.poses is None and c.error for c in traj.calls[1:-1])
    assert traj.end is not None and traj.end.reason == "disconnect"
    assert all(p == [0, 0, 0, 1, 0, 0, 0] for p in read_final(run / "final.json").poses.values())
