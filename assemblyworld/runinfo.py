"""``run.json`` for an Inspect episode: what ``aw-run`` writes for its harnesses, from Inspect's
transcript and the server's recording, so that ``aw-score SUITE RUNS`` reads Inspect runs beside
any others.

- wall time: the sample's episode, from starting ``aw-serve`` to its exit;
- calls: the calls the server recorded, plus the calls Inspect refused before they reached the
  server (its own check of the arguments against the tools' schemas, an unknown tool, arguments
  that are not JSON). Claude Code and Codex pass such calls on and the server refuses and records
  them, so only the sum means the same in every runner; ``extra.refused_calls`` says how many;
- tokens and cost: Inspect's usage of the sample (input tokens include cache reads and writes);
  cost where Inspect knows the model's prices;
- the agent's report: its last message.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib.metadata import version
from pathlib import Path
from typing import Any, Literal

from inspect_ai.event import Event, ModelEvent
from inspect_ai.log import transcript
from inspect_ai.model import ChatMessage, ChatMessageAssistant, ChatMessageTool, ModelUsage

from aw.formats import RunInfo, write_run_info
from aw.formats.run import TokenUsage
from aw.runner.batch import recorded_episode

__all__ = ["EpisodeEnd", "refused_calls", "usage_by_model", "token_usage", "episode_run_info", "write_episode_run_info"]

Ending = Literal["finished", "timeout", "error", "crashed", "hung"]


@dataclass
class EpisodeEnd:
    """How an episode ended, filled in by the solver as it learns it."""

    ended: Ending = "finished"
    error: str | None = None
    server_ended: bool = False  # the server wrote final.json while the agent was still working (budget spent)
    wall_seconds: float = 0.0
    server_stderr: list[str] = field(default_factory=list)


def refused_calls(messages: list[ChatMessage]) -> list[dict[str, str]]:
    """The tool calls Inspect answered with a parsing error itself (they never reached the server):
    ``[{"tool", "error"}]`` in call order."""
    return [
        {"tool": m.function or "", "error": m.error.message}
        for m in messages
        if isinstance(m, ChatMessageTool) and m.error is not None and m.error.type == "parsing"
    ]


def usage_by_model(events: Sequence[Event]) -> dict[str, ModelUsage]:
    """Model usage summed per model over a transcript's completed model calls."""
    out: dict[str, ModelUsage] = {}
    for ev in events:
        if isinstance(ev, ModelEvent) and not ev.pending and ev.output.usage is not None:
            out[ev.model] = out.get(ev.model, ModelUsage()) + ev.output.usage
    return out


def token_usage(usage: dict[str, ModelUsage]) -> tuple[TokenUsage | None, float | None]:
    """``(tokens, cost in USD)`` of a sample's usage per model; input includes cache reads and
    writes (as ``run.json`` counts them); cost None unless Inspect priced every model."""
    if not usage:
        return None, None
    total = ModelUsage()
    for u in usage.values():
        total = total + u
    inp = total.input_tokens + (total.input_tokens_cache_read or 0) + (total.input_tokens_cache_write or 0)
    costs = [u.total_cost for u in usage.values()]
    cost = sum(c for c in costs if c is not None) if all(c is not None for c in costs) else None
    return TokenUsage(input=inp, output=total.output_tokens, total=inp + total.output_tokens), cost


def _report(messages: list[ChatMessage]) -> str | None:
    for m in reversed(messages):
        if isinstance(m, ChatMessageAssistant):
            return m.text or None
    return None


def episode_run_info(
    run_dir: Path,
    end: EpisodeEnd,
    *,
    system: str,
    task_id: str,
    model: str,
    started_at: str,
    messages: list[ChatMessage],
    usage: dict[str, ModelUsage],
    epoch: int,
    epochs: int,
    settings: dict[str, Any],
) -> RunInfo:
    """The ``run.json`` of an episode recorded in ``run_dir`` (see the module doc)."""
    facts, recorded_extra = recorded_episode(run_dir, task_id)
    refused = refused_calls(messages)
    tokens, cost = token_usage(usage)
    recorded = facts.get("n_calls")
    extra: dict[str, Any] = {
        **recorded_extra,
        "recorded_calls": recorded,
        "refused_calls": len(refused),
        "refused": refused,
        "epoch": epoch,
        "epochs": epochs,
        "settings": settings,
    }
    if end.server_stderr:
        extra["server_stderr_tail"] = end.server_stderr[-12:]
    return RunInfo(
        system=system,
        task_id=task_id,
        agent=model,
        harness=f"inspect-ai {version('inspect_ai')}",
        started_at=started_at,
        wall_seconds=round(end.wall_seconds, 3),
        mcp_calls=None if recorded is None else recorded + len(refused),
        ended=end.ended,
        error=end.error,
        tokens=tokens,
        cost_usd=cost,
        report=_report(messages),
        extra=extra,
    )


def write_episode_run_info(run_dir: Path, end: EpisodeEnd, **kwargs: Any) -> RunInfo:
    """Write ``run_dir/run.json`` (see :func:`episode_run_info`) with the sample's model usage."""
    info = episode_run_info(run_dir, end, usage=usage_by_model(transcript().events), **kwargs)
    write_run_info(run_dir / "run.json", info)
    return info
