"""``random``: random legal edits (translations, rotations, absolute poses, groups), seeded.

Magnitudes follow the scene's size (from the parts' reported extents), so edits stay within the
allowed ranges on any task. It looks at the scene now and then, as an agent would.
"""

from __future__ import annotations

import numpy as np

from aw.agents.base import AgentContext, AgentOutcome, begin, inspect_objects, object_ids
from aw.agents.session import ToolSession
from aw.pose import matrix_from_xyz_sequence, matrix_to_quat


def _vec(rng: np.random.Generator, scale: float) -> list[float]:
    return [float(v) for v in rng.normal(0.0, scale, 3)]


async def run(tools: ToolSession, ctx: AgentContext) -> AgentOutcome:
    rng = ctx.rng("random")
    n_edits = int(ctx.options.get("edits", 12))
    await begin(tools, ctx)
    objects = await inspect_objects(tools)
    ids = [o.id for o in objects]
    size = float(max(np.linalg.norm(o.extents) for o in objects)) or 1.0
    await tools.call("capture_scene")
    edits = captures = 0
    for step in range(n_edits):
        await ctx.think()
        kind = rng.choice(["translate", "rotate", "set_pose", "group"], p=[0.35, 0.35, 0.2, 0.1])
        pick = [ids[i] for i in rng.choice(len(ids), size=int(rng.integers(1, min(3, len(ids)) + 1)), replace=False)]
        space = str(rng.choice(["world", "camera"]))
        if kind == "translate":
            await tools.call("translate_objects", {"ids": pick, "delta": _vec(rng, 0.3 * size), "space": space})
        elif kind == "rotate":
            angles = [float(a) for a in rng.uniform(-90, 90, 3)]
            pivot = _vec(rng, 0.5 * size) if rng.random() < 0.3 else None
            await tools.call("rotate_objects", {"ids": pick, "angles": angles, "space": space, "pivot": pivot})
        elif kind == "set_pose":
            q = matrix_to_quat(matrix_from_xyz_sequence(rng.uniform(-180, 180, 3)))
            args = {"id": pick[0]}
            if rng.random() < 0.7:
                args["position"] = _vec(rng, 0.5 * size)
            if "position" not in args or rng.random() < 0.5:
                args["quaternion"] = [float(v) for v in q]
            await tools.call("set_object_pose", args)
        else:
            if len(ids) < 2:
                continue
            pair = [ids[i] for i in rng.choice(len(ids), size=2, replace=False)]
            await tools.call("group_objects", {"ids": pair, "name": f"random group {step}"})
            _, groups = object_ids((await tools.call("list_objects")).data)
            if groups:
                await tools.call(
                    "translate_objects", {"ids": [groups[-1]], "delta": _vec(rng, 0.2 * size), "space": "world"}
                )
                await tools.call("ungroup_objects", {"ids": [groups[-1]]})
        edits += 1
        if step % 4 == 3:
            await tools.call("move_camera", {"yaw": float(rng.uniform(-60, 60)), "pitch": float(rng.uniform(-15, 15))})
            await tools.call("capture_scene")
            captures += 1
    await tools.call("capture_scene")
    await tools.call("get_state")
    return AgentOutcome(
        declared_complete=False,
        report=f"Made {edits} random edits; no claim about the result.",
        stats={"edits": edits, "captures": captures + 2},
    )
