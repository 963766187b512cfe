"""Baseline-agent episodes, run outside the runner's process.

``python -m aw.runner.episode SPEC.json`` runs one episode; ``python -m aw.runner.episode
--worker`` runs one episode per spec line on stdin (the runner keeps one such worker per job, so
imports are paid once). For each episode the worker launches ``aw-serve`` over stdio with the
SDK's client, runs the agent against it, and writes a result JSON (how it ended, the agent's
report, client-side call counts). If the worker dies, the supervising runner finds no result
and records the episode as crashed.
"""

from __future__ import annotations

import asyncio
import json
import os
import sys
import time
import traceback
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field


class EpisodeSpec(BaseModel):
    """Everything the worker needs; written by the runner as JSON."""

    model_config = ConfigDict(extra="forbid")
    task_id: str
    agent: str
    server_command: list[str] = Field(min_length=1)
    server_env: dict[str, str] = Field(default_factory=dict)
    server_log: str
    seed: int = 0
    think_seconds: float = 0.0
    options: dict[str, Any] = Field(default_factory=dict)
    targets_path: str | None = None
    call_timeout: float = 120.0
    progress_path: str
    result_path: str
    agent_log: str | None = None


class EpisodeResult(BaseModel):
    model_config = ConfigDict(extra="forbid")
    ended: str  # finished | error | crashed | hung
    error: str | None = None
    report: str | None = None
    declared_complete: bool | None = None
    call_counts: dict[str, int] = Field(default_factory=dict)
    tool_errors: dict[str, int] = Field(default_factory=dict)
    images_seen: int = 0
    stats: dict[str, Any] = Field(default_factory=dict)
    agent_seconds: float = 0.0


def _tail(path: Path, n: int = 1500) -> str:
    try:
        return path.read_text(errors="replace")[-n:].strip()
    except OSError:
        return ""


async def run_episode(spec: EpisodeSpec) -> EpisodeResult:
    from mcp import Client
    from mcp.client.stdio import StdioServerParameters, stdio_client
    from mcp.shared.exceptions import MCPError

    from aw.agents import AGENTS
    from aw.agents.base import AgentContext
    from aw.agents.session import ServerHung, ToolFailed, ToolSession

    agent = AGENTS[spec.agent]
    ctx = AgentContext(
        task_id=spec.task_id,
        seed=spec.seed,
        think_seconds=spec.think_seconds,
        options=dict(spec.options),
        targets_path=Path(spec.targets_path) if spec.targets_path else None,
    )
    params = StdioServerParameters(command=spec.server_command[0], args=spec.server_command[1:], env=spec.server_env)
    log_path = Path(spec.server_log)
    t0 = time.monotonic()
    tools: ToolSession | None = None
    result: EpisodeResult
    outcome = None
    agent_exc: BaseException | None = None
    conn_exc: BaseException | None = None
    with open(log_path, "a") as errlog:
        try:
            # The server's stderr goes to the run's log, not ours.
            transport = stdio_client(params, errlog=errlog)
            async with Client(transport, read_timeout_seconds=spec.call_timeout) as client:
                tools = ToolSession(client, spec.call_timeout, Path(spec.progress_path))
                try:
                    outcome = await agent(tools, ctx)
                except Exception as exc:  # classified below, after the server is shut down
                    agent_exc = exc
        except Exception as exc:  # connecting or disconnecting (anyio may wrap it in a group)
            conn_exc = _unwrap(exc)
    exc = agent_exc or conn_exc
    if exc is None and outcome is not None:
        result = EpisodeResult(
            ended="finished", report=outcome.report, declared_complete=outcome.declared_complete, stats=outcome.stats
        )
    elif exc is None:
        result = EpisodeResult(ended="error", error="the episode ended without an outcome")
    elif isinstance(exc, ServerHung):
        result = EpisodeResult(ended="hung", error=str(exc))
    elif isinstance(exc, ToolFailed):
        result = EpisodeResult(ended="error", error=f"tool error the agent could not handle: {exc}")
    elif isinstance(exc, (MCPError, OSError, EOFError)) or exc is conn_exc:
        # Connection-level trouble: the server could not start, or went away mid-episode.
        log = _tail(log_path)
        msg = f"MCP connection failed: {type(exc).__name__}: {exc}"
        result = EpisodeResult(ended="error", error=msg + (f"\nserver log tail:\n{log}" if log else ""))
    else:  # a bug in the agent itself
        tb = traceback.format_exception(type(exc), exc, exc.__traceback__, limit=-4)
        result = EpisodeResult(ended="crashed", error=f"agent raised {type(exc).__name__}: {exc}\n{''.join(tb)}")
    if tools is not None:
        result.call_counts = dict(tools.counts)
        result.tool_errors = dict(tools.errors)
        result.images_seen = tools.images_seen
    result.agent_seconds = time.monotonic() - t0
    return result


def _unwrap(exc: BaseException) -> BaseException:
    """The first leaf of nested exception groups (anyio task groups wrap errors)."""
    while isinstance(exc, BaseExceptionGroup) and exc.exceptions:
        exc = exc.exceptions[0]
    return exc


def _write_result(spec: EpisodeSpec, result: EpisodeResult) -> None:
    out = Path(spec.result_path)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(result.model_dump_json(indent=2))
    os.replace(tmp, out)


def _run_one(spec: EpisodeSpec) -> EpisodeResult:
    try:
        return asyncio.run(run_episode(spec))
    except BaseExceptionGroup as group:  # raised out of the SDK's task groups
        exc = _unwrap(group)
        return EpisodeResult(ended="error", error=f"{type(exc).__name__}: {exc}")


def serve_worker() -> int:
    """Worker mode: one spec (JSON) per stdin line, one ``{"done": task_id}`` line per episode on
    the original stdout. Imports happen once per worker, not once per episode; everything an
    episode prints goes to its ``agent_log``."""
    proto = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)  # stray prints must not corrupt the protocol
    for line in sys.stdin:
        if not line.strip():
            continue
        spec = EpisodeSpec.model_validate_json(line)
        if spec.agent_log:
            fd = os.open(spec.agent_log, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
            sys.stderr.flush()
            os.dup2(fd, 2)
            os.dup2(fd, 1)
            os.close(fd)
        _write_result(spec, _run_one(spec))
        sys.stderr.flush()
        proto.write(json.dumps({"done": spec.task_id}) + "\n")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv == ["--worker"]:
        return serve_worker()
    if len(argv) != 1:
        print("usage: python -m aw.runner.episode SPEC.json | --worker", file=sys.stderr)
        return 2
    spec = EpisodeSpec.model_validate_json(Path(argv[0]).read_bytes())
    _write_result(spec, _run_one(spec))
    return 0


if __name__ == "__main__":
    sys.exit(main())
