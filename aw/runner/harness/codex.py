"""Codex adapter: ``codex exec --json`` with the MCP server given as ``-c`` config overrides.

Command (the prompt goes in on stdin as ``-``; images last, since ``--image`` takes several)::

    codex exec --json --skip-git-repo-check --sandbox read-only -C WORKDIR \\
        -c approval_policy="never" \\
        -c mcp_servers.assemblyworld.command="/path/aw-serve" \\
        -c mcp_servers.assemblyworld.args=["TASK_DIR", "--record", ...] \\
        -c mcp_servers.assemblyworld.env={PYOPENGL_PLATFORM="egl", ...} \\
        -c mcp_servers.assemblyworld.tool_timeout_sec=300 \\
        [-m MODEL] [extra args] - --image REF1.png --image REF2.png

Overrides leave ``CODEX_HOME`` (and its login) alone; the same table is written to
``RUN_DIR/codex_mcp.toml`` for the record. Codex reports tokens but not cost: cost is estimated
from :mod:`aw.runner.harness.prices` (``cost_estimated: true`` in ``run.json``).
"""

from __future__ import annotations

import json
import shlex
import tempfile
from collections import Counter
from pathlib import Path

from aw.formats import TokenUsage
from aw.runner.harness.base import (
    SERVER_NAME,
    HarnessOptions,
    HarnessUsage,
    PreparedRun,
    read_json_events,
    reference_images,
    server_env,
    task_prompt_from_server,
)
from aw.runner.harness.prices import estimate_cost, load_price_table

TOOL_TIMEOUT_SEC = 300
STARTUP_TIMEOUT_SEC = 120


def _toml(value) -> str:
    """A TOML value for strings, numbers, lists of strings and flat string tables."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a valid TOML basic string
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(str(k))} = {_toml(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"no TOML form for {type(value).__name__}")


class Codex:
    name = "codex"
    transcript_name = "transcript.jsonl"

    def prepare(self, task_dir, serve_base, serve_args, env, marker, opts: HarnessOptions) -> PreparedRun:
        run_dir = Path(serve_args[serve_args.index("--record") + 1])
        prompt = task_prompt_from_server(serve_base, task_dir, env)
        images = reference_images(task_dir)
        server = {
            "command": serve_base[0],
            "args": [*serve_base[1:], *serve_args],
            "env": server_env(env, marker),
            "startup_timeout_sec": STARTUP_TIMEOUT_SEC,
            "tool_timeout_sec": TOOL_TIMEOUT_SEC,
        }
        (run_dir / "codex_mcp.toml").write_text(
            f"[mcp_servers.{SERVER_NAME}]\n" + "".join(f"{k} = {_toml(v)}\n" for k, v in server.items())
        )
        (run_dir / "prompt.txt").write_text(prompt)
        cwd = Path(tempfile.mkdtemp(prefix="aw-codex-"))
        cmd = [
            opts.binary or "codex",
            "exec",
            "--json",
            "--skip-git-repo-check",
            "--sandbox",
            "read-only",
            "-C",
            str(cwd),
        ]
        cmd += ["-c", 'approval_policy="never"']
        for k, v in server.items():
            cmd += ["-c", f"mcp_servers.{SERVER_NAME}.{k}={_toml(v)}"]
        if opts.model:
            cmd += ["-m", opts.model]
        cmd += opts.extra_args
        cmd.append("-")
        for img in images:
            cmd += ["--image", str(img)]
        return PreparedRun(
            command=cmd,
            env=dict(env),
            cwd=cwd,
            stdin=prompt.encode(),
            display_command=shlex.join(cmd) + " < prompt.txt",
        )

    def parse(self, transcript: Path, opts: HarnessOptions) -> HarnessUsage:
        usage = HarnessUsage(model=opts.model)
        inp = cached = out = 0
        turns = 0
        tool_calls: Counter[str] = Counter()
        messages: list[str] = []
        errors: list[str] = []
        events, n_bad = read_json_events(transcript)
        for ev in events:
            kind = ev.get("type")
            if kind == "thread.started":
                usage.extra["thread_id"] = ev.get("thread_id")
            elif kind == "turn.completed":
                turns += 1
                u = ev.get("usage") or {}
                inp += int(u.get("input_tokens") or 0)
                cached += int(u.get("cached_input_tokens") or 0)
                out += int(u.get("output_tokens") or 0)
            elif kind == "turn.failed":
                errors.append(str((ev.get("error") or {}).get("message", "turn failed")))
            elif kind == "error":
                errors.append(str(ev.get("message", "error")))
            elif kind == "item.completed":
                item = ev.get("item") or {}
                if item.get("type") == "mcp_tool_call":
                    tool_calls[f"{item.get('server')}.{item.get('tool')}"] += 1
                elif item.get("type") == "agent_message" and isinstance(item.get("text"), str):
                    messages.append(item["text"])
        if turns:
            usage.tokens = TokenUsage(input=inp, output=out, total=inp + out)
            table, source = load_price_table(opts.price_table)
            usage.cost_usd = estimate_cost(usage.model, inp, cached, out, table)
            usage.extra.update({"cached_input_tokens": cached, "cost_estimated": True, "price_source": source})
            if usage.cost_usd is None:
                usage.extra["cost_note"] = f"no price for model {usage.model!r}; pass --price-table"
        if messages:
            usage.report = messages[-1]
        if errors or not turns:
            usage.is_error = True
            usage.error = "; ".join(errors)[:1000] if errors else "the transcript has no completed turn"
        usage.extra["turns"] = turns
        usage.extra["harness_tool_uses"] = dict(tool_calls)
        if n_bad:
            usage.extra["transcript_unparsed_lines"] = n_bad
        return usage

    def label(self, usage: HarnessUsage) -> str:
        return self.name
