"""Helpers for the Inspect task's tests: a two-task suite, a scripted model that reads the tools
it is offered and the replies it got, and a look for server processes left behind.

The model is Inspect's ``mockllm/model`` with a callable as its outputs; every output carries its
token usage, so that Inspect never counts tokens itself (tiktoken would download its encoding).
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import psutil
from PIL import Image

from aw.cli.prepare import main as aw_prepare
from aw.formats import read_manifest, read_targets, read_task, write_manifest, write_targets, write_task
from aw.prompt import task_prompt
from aw_server.tools import TOOL_NAMES

NONE_TASK = "fantastic_breaks-cylinder_000-none"
MANUAL_TASK = "fantastic_breaks-cylinder_000-manual"
PAGE_COLOURS = [(220, 30, 30), (30, 30, 220)]  # the manual's two pages, in order
USAGE = {"input_tokens": 1000, "output_tokens": 20, "total_tokens": 1020}  # every scripted output's
SERVER_TOOLS = frozenset(TOOL_NAMES)  # what aw-serve offers (tests/aw_server pins the list itself)


def make_suite(root: Path) -> Path:
    """The synthetic suite's one fracture task (no reference), and the same object under the
    manual condition with two reference pages (plain colours, so their order can be checked)."""
    assert (
        aw_prepare(
            ["synthetic", "--out", str(root), "--per-source", "1", "--blocks", "fantastic_breaks"]
            + ["--jobs", "1", "--no-progress"]
        )
        == 0
    )
    src, dst = root / "tasks" / NONE_TASK, root / "tasks" / MANUAL_TASK
    shutil.copytree(src, dst)
    (dst / "references").mkdir(exist_ok=True)
    refs = []
    for i, colour in enumerate(PAGE_COLOURS, start=1):
        Image.new("RGB", (32, 24), colour).save(dst / "references" / f"{i:02d}.png")
        refs.append(f"references/{i:02d}.png")
    task = read_task(src)
    write_task(
        dst,
        task.model_copy(
            update={"task_id": MANUAL_TASK, "condition": "manual", "prompt": task_prompt("manual"), "references": refs}
        ),
    )
    targets = read_targets(root / "targets" / f"{NONE_TASK}.json")
    write_targets(root / "targets" / f"{MANUAL_TASK}.json", targets.model_copy(update={"task_id": MANUAL_TASK}))
    manifest = read_manifest(root)
    entry = manifest.entry(NONE_TASK).model_copy(update={"task_id": MANUAL_TASK, "condition": "manual"})
    write_manifest(root, manifest.model_copy(update={"tasks": [*manifest.tasks, entry]}))
    return root


def output(kind: str, *args: Any) -> Any:
    """A mockllm output with its usage: ``output("call", tool, arguments)`` or ``output("text", text)``."""
    from inspect_ai.model import ModelOutput, ModelUsage

    out = (
        ModelOutput.for_tool_call("mockllm/model", args[0], args[1])
        if kind == "call"
        else ModelOutput.from_content("mockllm/model", args[0])
    )
    out.usage = ModelUsage(**USAGE)
    return out


def last_tool_json(messages: list[Any]) -> Any:
    """The JSON of the last tool reply in a conversation."""
    for m in reversed(messages):
        if m.role == "tool":
            return json.loads(m.text)
    raise AssertionError("no tool reply yet")


class Script:
    """A scripted model: ``steps[k](messages)`` gives the output of the k-th model call of a
    sample (k = the assistant messages so far), so concurrent samples each follow the script.
    Records what each call was offered: tool names and the conversation's first messages."""

    def __init__(
        self, steps: list[Callable[[list[Any]], Any]], final: str = "Done: every part placed; the joint may be off."
    ):
        self.steps = steps
        self.final = final
        self.offered: list[set[str]] = []
        self.first_roles: list[list[str]] = []

    def __call__(self, messages, tools, tool_choice, config):
        self.offered.append({t.name for t in tools})
        self.first_roles.append([m.role for m in messages[:2]])
        k = sum(1 for m in messages if m.role == "assistant")
        return self.steps[k](messages) if k < len(self.steps) else output("text", self.final)

    def model(self):
        from inspect_ai.model import get_model

        return get_model("mockllm/model", custom_outputs=self, memoize=False)


def servers_of(fragment: str) -> list[psutil.Process]:
    """Live (not zombie) processes of this user whose command line mentions ``fragment``."""
    out = []
    for proc in psutil.process_iter(["cmdline", "uids"]):
        try:
            if proc.info["uids"].real != os.getuid() or proc.status() == psutil.STATUS_ZOMBIE:
                continue
            if any(fragment in part for part in proc.info["cmdline"] or []):
                out.append(proc)
        except (psutil.Error, AttributeError):
            continue
    return out
