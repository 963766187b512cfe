"""Baseline agents that speak only MCP (the oracle also reads the hidden targets: calibration only).

``AGENTS`` maps a name to the agent's ``run(tools, ctx)`` coroutine function.
"""

from __future__ import annotations

from aw.agents import heuristic, idle, oracle, random_agent
from aw.agents.base import AgentContext, AgentFn, AgentOutcome

AGENTS: dict[str, AgentFn] = {
    "idle": idle.run,
    "random": random_agent.run,
    "oracle": oracle.run,
    "heuristic": heuristic.run,
}
# The --agent-option keys each agent reads (ctx.options); any other key is refused by aw-run.
AGENT_OPTIONS: dict[str, frozenset[str]] = {
    "idle": frozenset({"views"}),
    "random": frozenset({"edits"}),
    "oracle": frozenset({"noise"}),
    "heuristic": frozenset(),
}
# Agents that must be handed the hidden targets file (never a benchmark result).
NEEDS_TARGETS = frozenset({"oracle"})
# What each agent's runs are in a study's tables: "calibration" (reads the hidden targets: an
# upper bound of the scorer, never a result), "floor" (makes no attempt to assemble: idle never
# moves, random moves blindly) or "system" (a real attempt through the tools only).
ROLES: dict[str, str] = {"idle": "floor", "random": "floor", "oracle": "calibration", "heuristic": "system"}

__all__ = ["AGENTS", "AGENT_OPTIONS", "NEEDS_TARGETS", "ROLES", "AgentContext", "AgentOutcome", "AgentFn"]
