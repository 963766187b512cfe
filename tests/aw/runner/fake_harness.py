#!/usr/bin/env python3
"""A stand-in for the ``claude`` and ``codex`` CLIs, for testing the harness adapters offline.

It parses the command line the adapters build (``claude -p ...`` or ``codex exec ...``), reads the
generated MCP configuration (Claude: the ``--mcp-config`` JSON; Codex: the ``-c
mcp_servers.<name>.*`` TOML overrides), checks the prompt and the attached references, launches
the configured server itself over stdio with the real MCP SDK client, plays a short episode
(start_episode, look, a few edits, look again), and prints a transcript with usage in the real
harness's output format.

``FAKE_HARNESS_MODE``: ``play`` (default), ``hang`` (start the server, then sleep: tests the
runner's wall-clock limit and clean-up), ``fail`` (report an error result and exit 1),
``nologin`` (Claude Code's answer without a login: an error result "Not logged in", exit 1).

``--version`` prints a version line. The harness check's probe prompt (``aw.runner.check``) gets
the real answer to it: the server's tool names, listed over MCP without calling any.
"""

from __future__ import annotations

import asyncio
import json
import os
import sys
import time
import tomllib
from pathlib import Path


def emit(obj: dict) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def parse_claude(argv: list[str]) -> dict:
    """Returns {server: {command, args, env}, prompt, images, allowed, model}."""
    if "-p" not in argv and "--print" not in argv:
        sys.exit("fake claude: expected -p")
    for flag in ("--output-format", "--mcp-config"):
        if flag not in argv:
            sys.exit(f"fake claude: missing {flag}")
    if argv[argv.index("--output-format") + 1] != "stream-json" or "--verbose" not in argv:
        sys.exit("fake claude: stream-json output needs --verbose")
    config = json.loads(Path(argv[argv.index("--mcp-config") + 1]).read_text())
    servers = config["mcpServers"]
    if len(servers) != 1 or "--strict-mcp-config" not in argv:
        sys.exit("fake claude: expected exactly one strict MCP server")
    name, server = next(iter(servers.items()))
    allowed = []
    if "--allowedTools" in argv:
        for a in argv[argv.index("--allowedTools") + 1 :]:
            if a.startswith("--"):
                break
            allowed.append(a)
    if f"mcp__{name}" not in allowed:
        sys.exit(f"fake claude: the MCP server's tools are not allowed: {allowed}")
    prompt = sys.stdin.read()
    images = [line.split(". ", 1)[1] for line in prompt.splitlines() if line[:1].isdigit() and ". /" in line]
    model = argv[argv.index("--model") + 1] if "--model" in argv else "claude-fake-1"
    return {"name": name, "server": server, "prompt": prompt, "images": images, "model": model}


def parse_codex(argv: list[str]) -> dict:
    if argv[:1] != ["exec"] or "--json" not in argv:
        sys.exit("fake codex: expected 'exec --json'")
    overrides: dict[str, dict] = {}
    images: list[str] = []
    model = "gpt-5"
    i = 1
    prompt_arg = None
    while i < len(argv):
        a = argv[i]
        if a == "-c":
            key, value = argv[i + 1].split("=", 1)
            parsed = tomllib.loads(f"v = {value}")["v"]
            parts = key.split(".")
            if parts[0] == "mcp_servers":
                overrides.setdefault(parts[1], {})[parts[2]] = parsed
            i += 2
        elif a in ("--image", "-i"):
            images.append(argv[i + 1])
            i += 2
        elif a in ("-m", "--model"):
            model = argv[i + 1]
            i += 2
        elif a in ("-C", "--sandbox", "--cd"):
            i += 2
        elif a == "-":
            prompt_arg = "-"
            i += 1
        else:
            i += 1
    if prompt_arg != "-":
        sys.exit("fake codex: expected the prompt on stdin ('-')")
    if len(overrides) != 1:
        sys.exit(f"fake codex: expected one MCP server, got {list(overrides)}")
    name, server = next(iter(overrides.items()))
    return {"name": name, "server": server, "prompt": sys.stdin.read(), "images": images, "model": model}


async def list_tools(server: dict) -> list[str]:
    from mcp import Client
    from mcp.client.stdio import StdioServerParameters, stdio_client

    params = StdioServerParameters(command=server["command"], args=server.get("args", []), env=server.get("env"))
    async with Client(stdio_client(params, errlog=sys.stderr), read_timeout_seconds=120) as client:
        return [t.name for t in (await client.list_tools()).tools]


def answer_probe(spec: dict, codex: bool) -> int:
    names = asyncio.run(list_tools(spec["server"]))
    text = "TOOLS: " + " ".join(names)
    if codex:
        emit({"type": "thread.started", "thread_id": "fake-thread"})
        emit({"type": "item.completed", "item": {"id": "final", "type": "agent_message", "text": text}})
        emit({"type": "turn.completed", "usage": {"input_tokens": 10, "cached_input_tokens": 0, "output_tokens": 5}})
    else:
        emit(
            {
                "type": "result",
                "subtype": "success",
                "is_error": False,
                "result": text,
                "num_turns": 1,
                "total_cost_usd": 0.0001,
                "usage": {"input_tokens": 10, "output_tokens": 5},
                "session_id": "fake",
            }
        )
    return 0


async def play(server: dict, log) -> list[tuple[str, dict, bool]]:
    """A short real episode; returns (tool, args, ok) per call."""
    from mcp import Client
    from mcp.client.stdio import StdioServerParameters, stdio_client

    params = StdioServerParameters(command=server["command"], args=server.get("args", []), env=server.get("env"))
    calls = []
    async with Client(stdio_client(params, errlog=sys.stderr), read_timeout_seconds=120) as client:

        async def call(tool: str, args: dict | None = None):
            res = await client.call_tool(tool, args or {})
            calls.append((tool, args or {}, not res.is_error))
            log(tool, args or {}, res)
            data = res.structured_content
            if isinstance(data, dict) and set(data) == {"result"}:
                data = data["result"]
            return data

        await call("start_episode")
        listing = await call("list_objects")
        objs = listing["objects"] if isinstance(listing, dict) else listing
        ids = [o["id"] if isinstance(o, dict) else o for o in objs]
        await call("get_object", {"id": ids[0]})
        await call("capture_scene")
        await call("translate_objects", {"ids": ids[:1], "delta": [0.05, 0.0, 0.02], "space": "world"})
        await call("rotate_objects", {"ids": ids[-1:], "angles": [0.0, 0.0, 15.0], "space": "world"})
        await call("set_object_pose", {"id": ids[0], "position": [0.0, 0.0, 0.1]})
        await call("move_camera", {"yaw": 45.0})
        await call("capture_scene")
        if os.environ.get("FAKE_HARNESS_MODE") == "hang":
            time.sleep(3600)
    return calls


def main() -> int:
    argv = sys.argv[1:]
    if argv == ["--version"]:
        print("0.0-fake (stand-in harness)")
        return 0
    codex = argv[:1] == ["exec"]
    spec = parse_codex(argv) if codex else parse_claude(argv)
    if os.environ.get("FAKE_HARNESS_MODE") == "nologin" and not codex:
        emit({"type": "result", "subtype": "success", "is_error": True, "result": "Not logged in · Please run /login"})
        return 1
    if spec["prompt"].startswith("AssemblyWorld connection check."):
        return answer_probe(spec, codex)
    if "Assemble the supplied parts into a coherent object." not in spec["prompt"]:
        sys.exit("fake harness: the prompt is not the AssemblyWorld task text")
    for img in spec["images"]:
        if not Path(img).is_file() or Path(img).read_bytes()[:8] != b"\x89PNG\r\n\x1a\n":
            sys.exit(f"fake harness: attached image {img} is not a PNG file")
    mode = os.environ.get("FAKE_HARNESS_MODE", "play")
    usage = {"in": 0, "out": 0, "cached": 0}

    if codex:
        emit({"type": "thread.started", "thread_id": "fake-thread"})
        emit({"type": "turn.started"})
    else:
        emit(
            {
                "type": "system",
                "subtype": "init",
                "model": spec["model"],
                "claude_code_version": "0.0-fake",
                "mcp_servers": [{"name": spec["name"], "status": "connected"}],
                "session_id": "fake",
            }
        )

    n = {"i": 0}

    def log(tool, args, res):
        n["i"] += 1
        usage["in"] += 1000
        usage["cached"] += 800
        usage["out"] += 50
        if codex:
            item = {
                "id": f"item_{n['i']}",
                "type": "mcp_tool_call",
                "server": spec["name"],
                "tool": tool,
                "arguments": args,
                "status": "failed" if res.is_error else "completed",
            }
            emit({"type": "item.started", "item": {**item, "status": "in_progress"}})
            emit({"type": "item.completed", "item": item})
        else:
            mid = f"msg_{n['i']}"
            emit(
                {
                    "type": "assistant",
                    "message": {
                        "id": mid,
                        "role": "assistant",
                        "model": spec["model"],
                        "content": [
                            {
                                "type": "tool_use",
                                "id": f"tu_{n['i']}",
                                "name": f"mcp__{spec['name']}__{tool}",
                                "input": args,
                            }
                        ],
                        "usage": {"input_tokens": 200, "cache_read_input_tokens": 800, "output_tokens": 50},
                    },
                }
            )
            emit(
                {
                    "type": "user",
                    "message": {
                        "role": "user",
                        "content": [
                            {"type": "tool_result", "tool_use_id": f"tu_{n['i']}", "is_error": bool(res.is_error)}
                        ],
                    },
                }
            )

    calls = asyncio.run(play(spec["server"], log))
    report = f"Made {sum(1 for c in calls if c[0] in ('translate_objects', 'rotate_objects', 'set_object_pose'))} edits; uncertain about contacts."
    failed = mode == "fail"
    if codex:
        emit({"type": "item.completed", "item": {"id": "final", "type": "agent_message", "text": report}})
        if failed:
            emit({"type": "turn.failed", "error": {"message": "fake failure"}})
        else:
            emit(
                {
                    "type": "turn.completed",
                    "usage": {
                        "input_tokens": usage["in"],
                        "cached_input_tokens": usage["cached"],
                        "output_tokens": usage["out"],
                    },
                }
            )
    else:
        emit(
            {
                "type": "result",
                "subtype": "error_during_execution" if failed else "success",
                "is_error": failed,
                "result": report,
                "num_turns": len(calls),
                "duration_ms": 1234,
                "total_cost_usd": 0.0123,
                "usage": {
                    "input_tokens": 200 * len(calls),
                    "cache_creation_input_tokens": 100,
                    "cache_read_input_tokens": 800 * len(calls),
                    "output_tokens": 50 * len(calls),
                },
                "session_id": "fake",
            }
        )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
