"""``oracle``: reads the hidden targets and assembles through the tools.

This is an upper-bound calibration agent, never a result: it is the only agent handed the
targets file, and exists to check the pipeline end to end (zero noise must score PA = SR =
100%) and to give demos a controlled spread of systems.

It places about half the parts with ``set_object_pose`` and the other half with
``rotate_objects`` (world XYZ angles about the body origin) followed by ``translate_objects``.
``noise`` (a level >= 0, option ``noise``) leaves, per placed part, a residual translation of
mean ``0.05 * noise * s`` (exponentially distributed magnitude, uniform direction; ``s`` the
largest part's bounding-box diagonal as ``get_object`` reports it) and a residual rotation about
the part's centre of mean ``6 * noise`` degrees, and skips each part with probability
``min(0.9, 0.1 * noise)``. All draws are seeded by (seed, task).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from aw.agents.base import AgentContext, AgentOutcome, aim_camera, begin, inspect_objects
from aw.agents.session import ToolSession
from aw.formats import read_targets
from aw.pose import apply_pose, matrix_to_quat, quat_to_matrix

TRANSLATION_PER_LEVEL = 0.05  # times the largest part's bounding-box diagonal
ROTATION_DEG_PER_LEVEL = 6.0
SKIP_PER_LEVEL = 0.1


def _random_unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def noisy_pose(
    target: np.ndarray, local_centre: np.ndarray, level: float, size: float, rng: np.random.Generator
) -> np.ndarray:
    """``target (7,)`` perturbed by a rotation about the part's centre and a translation."""
    if level <= 0:
        return target.copy()
    rot = quat_to_matrix(target[3:])
    t = target[:3]
    angle = np.radians(rng.exponential(ROTATION_DEG_PER_LEVEL * level))
    r_noise = Rotation.from_rotvec(_random_unit(rng) * angle).as_matrix()
    rot2 = r_noise @ rot
    shift = _random_unit(rng) * rng.exponential(TRANSLATION_PER_LEVEL * level * size)
    # Keep the part's centre where it was (rotation about the centre), then shift it.
    t2 = t + rot @ local_centre - rot2 @ local_centre + shift
    return np.concatenate([t2, matrix_to_quat(rot2)])


async def run(tools: ToolSession, ctx: AgentContext) -> AgentOutcome:
    if ctx.targets_path is None:
        raise ValueError("the oracle needs the task's targets file")
    targets = read_targets(ctx.targets_path)
    level = float(ctx.options.get("noise", 0.0))
    if not np.isfinite(level) or level < 0:
        raise ValueError(f"noise must be a finite number >= 0, got {level}")
    rng = ctx.rng(f"oracle:{level}")

    await begin(tools, ctx)
    await tools.call("get_scene")
    objects = {o.id: o for o in await inspect_objects(tools)}
    size = float(max(np.linalg.norm(o.extents) for o in objects.values()))
    await tools.call("capture_scene")
    await tools.call("move_camera", {"yaw": 120.0, "pitch": 10.0})
    await tools.call("capture_scene")

    order = [pid for pid in objects if pid in targets.parts and not targets.parts[pid].distractor]
    rng.shuffle(order)
    skip_p = min(0.9, SKIP_PER_LEVEL * level)
    placed, skipped = [], []
    for k, pid in enumerate(order):
        if rng.random() < skip_p:
            skipped.append(pid)
            continue
        goal = noisy_pose(np.asarray(targets.parts[pid].pose, float), objects[pid].local_centre, level, size, rng)
        await ctx.think()
        if k % 2 == 0:
            await tools.call(
                "set_object_pose", {"id": pid, "position": goal[:3].tolist(), "quaternion": goal[3:].tolist()}
            )
        else:
            cur = objects[pid].from_record((await tools.call("get_object", {"id": pid})).data)
            delta = quat_to_matrix(goal[3:]) @ quat_to_matrix(cur.quaternion).T
            angles = Rotation.from_matrix(delta).as_euler("xyz", degrees=True)  # extrinsic: Rz Ry Rx
            await tools.call("rotate_objects", {"ids": [pid], "angles": [float(a) for a in angles], "space": "world"})
            moved = objects[pid].from_record((await tools.call("get_object", {"id": pid})).data)
            await tools.call(
                "translate_objects", {"ids": [pid], "delta": (goal[:3] - moved.position).tolist(), "space": "world"}
            )
        placed.append(pid)
        if len(placed) % 3 == 0:
            await tools.call("capture_scene")
    # Re-frame on the assembly (where the target poses put the parts' box centres).
    centres = np.array(
        [apply_pose(np.asarray(targets.parts[p].pose, float), objects[p].local_centre[None])[0] for p in order]
    )
    if len(centres):
        lo, hi = centres.min(axis=0), centres.max(axis=0)
        await aim_camera(tools, 0.5 * (lo + hi), radius=0.5 * float(np.linalg.norm(hi - lo)) + 0.5 * size)
    for view in ({"yaw": 90.0}, {"yaw": 90.0, "pitch": 25.0}):
        await tools.call("move_camera", view)
        await tools.call("capture_scene")
    await tools.call("get_state")
    report = f"Placed {len(placed)} of {len(order)} parts"
    if skipped:
        report += f"; left {', '.join(sorted(skipped))} where they were"
    return AgentOutcome(
        declared_complete=not skipped,
        report=report + ". (Oracle calibration agent: read the hidden targets.)",
        stats={"placed": len(placed), "skipped": len(skipped), "noise": level},
    )
