"""``heuristic``: a genuine non-cheating baseline that uses only what the tools expose.

It knows each part's mesh-local bounding box (``get_object``) and its body pose, nothing else,
and applies a furniture prior:

1. the part with the largest footprint is the main panel; it lies flat, centred on the origin;
2. if two or more parts are clearly elongated sticks of similar length (box aspect > 2.5), they
   are read as legs: stood upright (rotated 90 degrees about the horizontal axis across them) at
   the corners of the panel's footprint, and the panel is raised to sit on top of them;
3. every other part is stacked above the panel, centred, largest first, bounding boxes touching.

It looks at the scene from a few views before and after, as an agent would. It scores low, and
that is the point: it is what bounding boxes alone buy.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from aw.agents.base import AgentContext, AgentOutcome, ObjectInfo, aim_camera, begin, inspect_objects, look_around
from aw.agents.session import ToolSession
from aw.pose import matrix_to_quat, quat_to_matrix

STICK_ASPECT = 2.5
SAME_LENGTH = 0.15


def _world_box(rot: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned world box of the local box ``[lo, hi]`` rotated by ``rot`` (about the origin)."""
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    w = corners @ rot.T
    return w.min(axis=0), w.max(axis=0)


def _stick_axis(o: ObjectInfo) -> int | None:
    """0 or 1 if the box is a horizontal stick along x or y, else None."""
    e = o.extents
    long_ax = int(np.argmax(e[:2]))
    if e[long_ax] > STICK_ASPECT * max(e[1 - long_ax], e[2], 1e-9):
        return long_ax
    return None


class _Placer:
    """Moves a part so that its rotated box has a given minimum corner, by one of two routes."""

    def __init__(self, tools: ToolSession):
        self.tools = tools
        self.n = 0

    async def place(self, o: ObjectInfo, rot: np.ndarray, box_min: np.ndarray) -> None:
        # Re-read the part first, as an agent checks the state it is about to change.
        o = ObjectInfo.from_record((await self.tools.call("get_object", {"id": o.id})).data)
        lo, _ = _world_box(rot, o.bounds_min, o.bounds_max)
        position = box_min - lo  # body origin so that the rotated box starts at box_min
        self.n += 1
        if self.n % 2 == 1:
            await self.tools.call(
                "set_object_pose",
                {"id": o.id, "position": position.tolist(), "quaternion": matrix_to_quat(rot).tolist()},
            )
            return
        cur = quat_to_matrix(o.quaternion)
        delta = rot @ cur.T
        if not np.allclose(delta, np.eye(3), atol=1e-12):
            angles = Rotation.from_matrix(delta).as_euler("xyz", degrees=True)
            await self.tools.call("rotate_objects", {"ids": [o.id], "angles": angles.tolist(), "space": "world"})
        await self.tools.call(
            "translate_objects", {"ids": [o.id], "delta": (position - o.position).tolist(), "space": "world"}
        )


async def run(tools: ToolSession, ctx: AgentContext) -> AgentOutcome:
    await begin(tools, ctx)
    await tools.call("get_scene")
    objects = await inspect_objects(tools)
    await look_around(tools, [{"yaw": 90.0, "pitch": 15.0}])
    if len(objects) == 1:
        return AgentOutcome(False, "Only one part; nothing to assemble.")

    footprint = {o.id: float(o.extents[0] * o.extents[1]) for o in objects}
    panel = max(objects, key=lambda o: footprint[o.id])
    rest = [o for o in objects if o.id != panel.id]

    # Legs: the largest set of sticks whose lengths agree within SAME_LENGTH.
    sticks = [(o, ax) for o in rest if (ax := _stick_axis(o)) is not None]
    legs: list[tuple[ObjectInfo, int]] = []
    for o, ax in sticks:
        length = o.extents[ax]
        same = [(p, a) for p, a in sticks if abs(p.extents[a] - length) <= SAME_LENGTH * length]
        if len(same) > len(legs):
            legs = same
    legs = legs[:4] if len(legs) >= 2 else []
    leg_ids = {o.id for o, _ in legs}

    placer = _Placer(tools)
    p_lo, p_hi = panel.bounds_min, panel.bounds_max
    half = 0.5 * (p_hi - p_lo)
    leg_height = max((float(o.extents[ax]) for o, ax in legs), default=0.0)

    await ctx.think()
    await placer.place(panel, np.eye(3), np.array([-half[0], -half[1], leg_height]))
    top = leg_height + float(p_hi[2] - p_lo[2])

    corners = [(-1, -1), (1, 1), (1, -1), (-1, 1)]
    for (o, ax), (sx, sy) in zip(legs, corners):
        await ctx.think()
        # Stand the stick up: 90 degrees about the horizontal axis across it.
        rot = Rotation.from_euler("xyz", [90.0, 0, 0] if ax == 1 else [0, 90.0, 0], degrees=True).as_matrix()
        lo, hi = _world_box(rot, o.bounds_min, o.bounds_max)
        size = hi - lo
        x = sx * half[0] - (size[0] if sx > 0 else 0.0)
        y = sy * half[1] - (size[1] if sy > 0 else 0.0)
        await placer.place(o, rot, np.array([x, y, 0.0]))
    if legs:
        await aim_camera(tools, [0.0, 0.0, 0.5 * top], radius=float(np.linalg.norm(half[:2])) + 0.5 * top)
        await tools.call("capture_scene")

    stack = sorted((o for o in rest if o.id not in leg_ids), key=lambda o: -footprint[o.id])
    for k, o in enumerate(stack):
        await ctx.think()
        e = o.extents
        await placer.place(o, np.eye(3), np.array([-e[0] / 2, -e[1] / 2, top]))
        top += float(e[2])
        if k % 3 == 2:
            await tools.call("capture_scene")

    await aim_camera(tools, [0.0, 0.0, 0.5 * top], radius=0.5 * float(np.linalg.norm([2 * half[0], 2 * half[1], top])))
    await look_around(tools, [{"yaw": 120.0, "pitch": -10.0}])
    await tools.call("get_state")
    return AgentOutcome(
        declared_complete=True,
        report=(
            f"Laid the largest part flat as the main panel, stood {len(legs)} stick-like parts under it as legs "
            f"and stacked {len(stack)} parts above it by bounding box. Placement is from bounding boxes only; "
            "orientations and contacts are unverified."
        ),
        stats={"legs": len(legs), "stacked": len(stack)},
    )
