"""``idle``: starts the episode, looks around, never edits (the paper's "never moved" floor)."""

from __future__ import annotations

from aw.agents.base import AgentContext, AgentOutcome, begin, inspect_objects, look_around
from aw.agents.session import ToolSession


async def run(tools: ToolSession, ctx: AgentContext) -> AgentOutcome:
    await begin(tools, ctx)
    await tools.call("get_scene")
    objects = await inspect_objects(tools)
    await ctx.think()
    views = [{"yaw": 90.0}, {"yaw": 90.0, "pitch": 20.0}, {"zoom": 0.8}]
    n_views = int(ctx.options.get("views", len(views)))
    captures = await look_around(tools, views[: max(0, n_views)])
    await tools.call("get_state")
    return AgentOutcome(
        declared_complete=False,
        report=f"Inspected {len(objects)} parts from {captures} views; made no edits.",
        stats={"captures": captures},
    )
