"""Every call is recorded whatever its content, and nothing changes the scene unless its success
is recorded: hostile ``input`` on the official surface (deep nesting, lone surrogates, integers
beyond float range), through the real MCP client over stdio against a real ``aw-serve``."""

from __future__ import annotations

import json

import pytest
from aw_server_helpers import result_text, server_params
from mcp import Client

from aw.formats import read_final, read_trajectory

pytestmark = pytest.mark.anyio

PYTHON_WORDS = (
    "Traceback",
    "RecursionError",
    "OverflowError",
    "JSONEncodeError",
    "TypeError",
    "ValueError",
    "surrogates not allowed",
    "maximum recursion",
    "Error executing tool",
)


def official(task_dir, run):
    return server_params(task_dir, run, "--surface", "official")


def _nested(depth: int) -> str:
    return "[" * depth + "]" * depth


# (tool, input text, words the one-line reply must contain)
HOSTILE_INPUT = [
    ("translate_objects", '{"ids": ["part-0001"], "delta": ' + _nested(300) + "}", "nested"),
    ("translate_objects", '{"ids": ["part-0001"], "delta": ' + _nested(5000) + "}", "nested"),
    ("list_objects", '{"x": ' + _nested(253) + "}", "nested"),
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


# ----------------------------------------------------------------------------------------------
# A full disk: a real aw-serve whose run directory stops taking writes, driven by the real client.

# Starts aw-serve with its stderr in a file and, if given a byte limit, RLIMIT_FSIZE set: a file
# written past the limit fails with EFBIG (Python ignores SIGXFSZ), as a full disk fails with ENOSPC.
# Run it with -B: CPython installs a bytecode cache file cut short at the limit, which would break
# every later import of that module in the checkout.
_WRAPPER = """
import os, resource, sys
limit, errlog = int(sys.argv[1]), sys.argv[2]
if errlog != "-":
    os.dup2(os.open(errlog, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644), 2)
if limit:
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
from aw_server.cli import main
sys.exit(main(sys.argv[3:]))
"""


@pytest.fixture
def small_disk(tmp_path):
    """A 1 MiB tmpfs (root only: skipped where mount is not allowed)."""
    import subprocess

    mnt = tmp_path / "disk"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mnt)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here (needs root): {r.stderr.strip() or r.returncode}")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], check=False)


def _fill(directory) -> object:
    """Write a file until the file system is full; returns its path."""
    filler = directory / "filler"
    with open(filler, "wb", buffering=0) as fh:
        try:
            while True:
                fh.write(b"\0" * 4096)
        except OSError:
            pass
    return filler


async def _edit(c, surface: str, dx: float) -> tuple[bool, str]:
    """Move part p01 by dx along x; (succeeded, reply text)."""
    if surface == "default":
        r = await c.call_tool("translate_objects", {"ids": ["p01"], "delta": [dx, 0, 0]})
        return not r.is_error, result_text(r)
    return await _page(c, "translate_objects", {"ids": ["part-0001"], "delta": [dx, 0, 0]})


async def _page(c, tool: str, args: dict) -> tuple[bool, str]:
    r = await c.call_tool("execute_webmcp_tool", {"pageId": 1, "toolName": tool, "input": json.dumps(args)})
    if r.is_error:
        return False, result_text(r)
    out = json.loads(json.loads(result_text(r))["output"])
    return "error" not in out, out.get("error", "")


@pytest.mark.parametrize("surface", ["default", "official"])
@pytest.mark.parametrize("how", ["tmpfs", "fsize"])
async def test_full_disk_changes_nothing_and_never_contradicts_replies(box_task, tmp_path, surface, how, request):
    import sys

    from mcp import StdioServerParameters

    task_dir, _, _ = box_task
    if how == "tmpfs":
        disk, limit = request.getfixturevalue("small_disk"), 0
    else:
        disk, limit = tmp_path, 6000
    run, errlog = disk / "run", tmp_path / "stderr.txt"
    params = StdioServerParameters(
        command=sys.executable,
        args=["-B", "-c", _WRAPPER, str(limit), str(errlog), str(task_dir), "--record", str(run), "--surface", surface],
    )
    dx, filler, told_ok, failure = 0.01, None, 0, ""
    async with Client(params) as c:
        assert (await _edit(c, surface, dx))[0]
        told_ok += 1
        if how == "tmpfs":
            filler = _fill(disk)
        for _ in range(400):
            ok, reply = await _edit(c, surface, dx)
            if not ok:
                failure = reply
                break
            told_ok += 1
        assert failure, "the recording never failed"
        assert failure.startswith(("recording failed (", "Error executing tool translate_objects: recording failed ("))
        assert "\n" not in failure and "Errno" not in failure and "Traceback" not in failure
        if filler is not None:
            filler.unlink()  # space again: the server still takes no edit it could not record before
        for _ in range(2):
            ok, reply = await _edit(c, surface, dx)
            assert not ok and "recording failed" in reply
        ok, reply = (await _page(c, "get_state", {})) if surface == "official" else (False, "")
        assert not ok
    traj = read_trajectory(run / "trajectory.jsonl")
    # Exactly the calls the agent was told succeeded, all ok, and nothing else.
    assert [(x.tool, x.ok) for x in traj.calls] == [("translate_objects", True)] * told_ok
    recorded_x = traj.checkpoints()[-1].poses["p01"][0]
    assert recorded_x == pytest.approx(dx * told_ok)
    if traj.end is not None:
        assert traj.end.poses == traj.checkpoints()[-1].poses and "recording failed" in traj.end.message
    final = read_final(run / "final.json")  # final.json is small: written once space is back
    assert final.poses == traj.checkpoints()[-1].poses
    log = errlog.read_text()
    assert "Traceback" not in log and len([line for line in log.splitlines() if "recording" in line]) == 1, log


def test_a_run_directory_that_takes_no_header_is_refused_in_one_line(box_task, tmp_path):
    import subprocess
    import sys

    task_dir, _, _ = box_task
    r = subprocess.run(
        [sys.executable, "-B", "-c", _WRAPPER, "100", "-", str(task_dir), "--record", str(tmp_path / "run")],
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=120,
    )
    lines = r.stderr.splitlines()  # a pipe: not limited like the files
    assert r.returncode == 2 and len(lines) == 1, lines
    assert lines[0].startswith("aw-serve: error: cannot record in ") and "File too large" in lines[0]
    assert not (tmp_path / "run" / "trajectory.jsonl").exists()
