"""Claude Code adapter: ``claude -p`` with a per-task ``--mcp-config`` and stream-json output.

Command (the prompt goes in on stdin, so no variadic option can swallow it)::

    claude -p --output-format stream-json --verbose \\
        --mcp-config RUN_DIR/mcp_config.json --strict-mcp-config \\
        --allowedTools mcp__assemblyworld [Read(//ABS/REFERENCES/DIR/**)] \\
        --disallowedTools Bash Edit Write NotebookEdit WebFetch WebSearch Task \\
        [--model M] [extra args]

It runs in a fresh empty working directory (no project instructions). Reference images are
attached as absolute paths in the prompt, readable with the Read tool restricted to the task's
``references/`` folder. Claude Code reports cost itself (``total_cost_usd`` of the ``result``
event); input tokens count cache reads and cache creation, as in the paper.
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

DISALLOWED = ["Bash", "Edit", "Write", "NotebookEdit", "WebFetch", "WebSearch", "Task"]


def attachment_text(images: list[Path]) -> str:
    if not images:
        return ""
    lines = ["", "", "Attached reference images, in order (open each with the Read tool):"]
    lines += [f"{i}. {p}" for i, p in enumerate(images, start=1)]
    return "\n".join(lines)


class ClaudeCode:
    name = "claude-code"
    transcript_name = "transcript.jsonl"

    def prepare(self, task_dir, serve_base, serve_args, env, marker, opts: HarnessOptions) -> PreparedRun:
        run_dir = Path(serve_args[serve_args.index("--record") + 1])
        prompt = task_prompt_from_server(serve_base, task_dir, env)
        images = reference_images(task_dir)
        prompt += attachment_text(images)
        config = {
            "mcpServers": {
                SERVER_NAME: {
                    "type": "stdio",
                    "command": serve_base[0],
                    "args": [*serve_base[1:], *serve_args],
                    "env": server_env(env, marker),
                }
            }
        }
        cfg_path = run_dir / "mcp_config.json"
        cfg_path.write_text(json.dumps(config, indent=2))
        (run_dir / "prompt.txt").write_text(prompt)
        allowed = [f"mcp__{SERVER_NAME}"]
        if images:
            allowed.append(f"Read(/{images[0].parent}/**)")  # '//' prefix: an absolute path rule
        cmd = [
            opts.binary or "claude",
            "-p",
            "--output-format",
            "stream-json",
            "--verbose",
            "--mcp-config",
            str(cfg_path),
            "--strict-mcp-config",
            "--allowedTools",
            *allowed,
            "--disallowedTools",
            *DISALLOWED,
        ]
        if opts.model:
            cmd += ["--model", opts.model]
        cmd += opts.extra_args
        cwd = Path(tempfile.mkdtemp(prefix="aw-claude-"))
        return PreparedRun(
            command=cmd,
            env=dict(env),
            cwd=cwd,
            stdin=prompt.encode(),
            display_command=shlex.join(cmd) + " < prompt.txt",
        )

    def parse(self, transcript: Path, opts: HarnessOptions) -> HarnessUsage:
        usage = HarnessUsage()
        result = None
        tool_uses: Counter[str] = Counter()
        by_message: dict[str, dict] = {}
        events, n_bad = read_json_events(transcript)
        for ev in events:
            kind = ev.get("type")
            if kind == "system" and ev.get("subtype") == "init":
                usage.model = ev.get("model") or usage.model
                usage.version = ev.get("claude_code_version") or usage.version
                usage.extra["mcp_servers"] = ev.get("mcp_servers")
            elif kind == "assistant":
                msg = ev.get("message") or {}
                for block in msg.get("content") or []:
                    if isinstance(block, dict) and block.get("type") == "tool_use":
                        tool_uses[str(block.get("name"))] += 1
                if msg.get("usage") and msg.get("id"):
                    by_message[msg["id"]] = msg["usage"]  # repeated per content block; keep one
            elif kind == "result":
                result = ev
        u = None
        if result is not None:
            usage.report = result.get("result") if isinstance(result.get("result"), str) else None
            usage.is_error = bool(result.get("is_error")) or result.get("subtype") not in (None, "success")
            if usage.is_error:
                # "success" with is_error (e.g. "Not logged in") is an error all the same: do not echo the subtype
                subtype = result.get("subtype")
                how = "reported an error" if subtype in (None, "success") else f"ended with {subtype}"
                usage.error = f"Claude Code {how}: {str(result.get('result') or '')[:500]}"
            cost = result.get("total_cost_usd")
            usage.cost_usd = float(cost) if isinstance(cost, (int, float)) else None
            u = result.get("usage")
            usage.extra.update(
                {k: result.get(k) for k in ("num_turns", "duration_ms", "duration_api_ms", "session_id") if k in result}
            )
        elif by_message:
            # No result event (killed at the limit): sum what the messages reported; no cost.
            u = {}
            for mu in by_message.values():
                for k, v in mu.items():
                    if isinstance(v, int):
                        u[k] = u.get(k, 0) + v
            usage.extra["usage_partial"] = True
        else:
            usage.is_error = True
            usage.error = "the transcript has no result event"
        if isinstance(u, dict):
            inp = sum(
                int(u.get(k) or 0) for k in ("input_tokens", "cache_read_input_tokens", "cache_creation_input_tokens")
            )
            out = int(u.get("output_tokens") or 0)
            usage.tokens = TokenUsage(input=inp, output=out, total=inp + out)
            usage.extra["usage_raw"] = u
        usage.extra["harness_tool_uses"] = dict(tool_uses)
        if n_bad:
            usage.extra["transcript_unparsed_lines"] = n_bad
        return usage

    def label(self, usage: HarnessUsage) -> str:
        return f"{self.name} {usage.version}" if usage.version else self.name
