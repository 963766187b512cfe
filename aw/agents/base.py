"""What every baseline agent shares: its context, its outcome, and the inspection helpers.

An agent is an ``async def run(tools: ToolSession, ctx: AgentContext) -> AgentOutcome``. It sees
the environment only through MCP tool calls (``tools``); the one exception is the oracle, which
is handed the hidden targets file explicitly (an upper-bound calibration agent, never a result).
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aw.agents.session import ToolSession


@dataclass
class AgentContext:
    """``seed``: all randomness of the agent; ``think_seconds``: pause before each edit (a stand-in
    for model latency, so time-based analyses have intervals to look at); ``options``: agent
    specific settings (``noise`` for the oracle); ``targets_path``: only the oracle gets it."""

    task_id: str
    seed: int = 0
    think_seconds: float = 0.0
    options: dict[str, Any] = field(default_factory=dict)
    targets_path: Path | None = None

    def rng(self, salt: str = "") -> np.random.Generator:
        """A generator that depends on the seed and the task (and ``salt``) only."""
        key = f"{self.seed}:{self.task_id}:{salt}".encode()
        return np.random.default_rng(list(key))

    async def think(self, scale: float = 1.0) -> None:
        if self.think_seconds > 0:
            await asyncio.sleep(self.think_seconds * scale)


@dataclass
class AgentOutcome:
    """What the agent says at the end (``run.json``'s ``report``/``declared_complete``)."""

    declared_complete: bool
    report: str
    stats: dict[str, Any] = field(default_factory=dict)


AgentFn = Callable[[ToolSession, AgentContext], Awaitable[AgentOutcome]]


@dataclass
class ObjectInfo:
    """One part as the tools report it: body pose and mesh-local bounding box."""

    id: str
    name: str
    position: np.ndarray  # (3,)
    quaternion: np.ndarray  # (4,) w, x, y, z
    bounds_min: np.ndarray  # (3,) mesh-local
    bounds_max: np.ndarray  # (3,) mesh-local

    @property
    def extents(self) -> np.ndarray:
        return self.bounds_max - self.bounds_min

    @property
    def local_centre(self) -> np.ndarray:
        return 0.5 * (self.bounds_min + self.bounds_max)

    @classmethod
    def from_record(cls, rec: dict[str, Any]) -> ObjectInfo:
        """From a ``get_object`` result: needs ``id``, ``position``, ``quaternion`` and either
        ``local_bounds`` {min, max} or ``extents`` (then the box is taken as centred)."""
        try:
            ext = np.asarray(rec.get("extents", [0, 0, 0]), float)
            lb = rec.get("local_bounds") or rec.get("bounds")
            if isinstance(lb, dict):
                lo, hi = np.asarray(lb["min"], float), np.asarray(lb["max"], float)
            else:
                lo, hi = -ext / 2, ext / 2
            return cls(
                id=str(rec["id"]),
                name=str(rec.get("name", rec["id"])),
                position=np.asarray(rec["position"], float),
                quaternion=np.asarray(rec["quaternion"], float),
                bounds_min=lo,
                bounds_max=hi,
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"get_object returned a record this agent cannot read: {exc}") from None


def object_ids(listing: Any) -> tuple[list[str], list[str]]:
    """(part ids, group ids) from a ``list_objects`` result."""
    if isinstance(listing, dict):
        objs = listing.get("objects", [])
        groups = listing.get("groups", [])
    elif isinstance(listing, list):
        objs, groups = listing, []
    else:
        raise ValueError("list_objects returned neither a list nor an object")

    def _id(x: Any) -> str:
        return str(x["id"]) if isinstance(x, dict) else str(x)

    return [_id(o) for o in objs], [_id(g) for g in groups]


async def begin(tools: ToolSession, ctx: AgentContext) -> None:
    """What any agent does first: read the instructions and start the episode."""
    prompts = await tools.list_prompts()
    if prompts:
        await tools.get_prompt(prompts[0])
    await tools.call("start_episode", {"task": ctx.task_id})


async def inspect_objects(tools: ToolSession) -> list[ObjectInfo]:
    """``list_objects``, then ``get_object`` for every part."""
    parts, _ = object_ids((await tools.call("list_objects")).data)
    out = []
    for pid in parts:
        out.append(ObjectInfo.from_record((await tools.call("get_object", {"id": pid})).data))
    return out


async def look_around(tools: ToolSession, views: list[dict[str, float]]) -> int:
    """Capture, then for each camera move capture again. Returns the number of captures."""
    n = 0
    await tools.call("capture_scene")
    n += 1
    for v in views:
        await tools.call("move_camera", v)
        await tools.call("capture_scene")
        n += 1
    return n


async def aim_camera(tools: ToolSession, point, radius: float | None = None) -> None:
    """Pan the camera so it looks at ``point (3,)`` and, given ``radius``, zoom so a sphere of
    that radius fills the view, as an agent re-framing its work would (``get_state`` then one
    ``move_camera``)."""
    cam = (await tools.call("get_state")).data["camera"]
    d = np.asarray(point, float) - np.asarray(cam["target"], float)
    args: dict[str, float] = {"right": float(d @ np.asarray(cam["right"])), "up": float(d @ np.asarray(cam["up"]))}
    if radius is not None and radius > 0:
        half_fov = np.radians(float(cam.get("vertical_fov_deg", 38.0))) / 2
        want = 1.2 * radius / np.sin(half_fov)
        args["zoom"] = float(np.clip(want / float(cam["distance"]), 0.25, 4.0))
    await tools.call("move_camera", args)
