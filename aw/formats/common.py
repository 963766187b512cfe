"""Field types shared by the schemas."""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import AfterValidator

PART_ID_PATTERN = r"^[A-Za-z0-9_-]{1,64}$"
# A category is a short name (chair, StorageFurniture); it is printed in summaries and reports.
MAX_CATEGORY_CHARS = 100
SOURCES = ("partnet", "ikea_manual", "assemblybench", "fantastic_breaks")
# What the agent is shown beside the parts: nothing, an image of the assembly, or manual pages.
Condition = Literal["none", "image", "manual"]
CONDITIONS: tuple[Condition, ...] = ("none", "image", "manual")
# A task as prepared, or one of the robustness variants of Appendix E.
VariantKind = Literal["original", "layout", "missing", "distractor"]
# Why an episode ended (a trajectory's end record and final.json).
EndReason = Literal["finished", "timeout", "error", "disconnect", "interrupted"]
# How a harness run ended (run.json).
RunEnded = Literal["finished", "timeout", "error", "crashed", "hung"]
# Sanity bounds of a recorded pose: far beyond any scene (edits stop at +-1000 units), well inside
# what the evaluator's float arithmetic handles (1e308 positions broke its eigen-solver).
MAX_POSE_POSITION = 1e6
MAX_POSE_QUAT_COMPONENT = 1e6


def as_condition(text: str) -> Condition:
    """``text`` as a :data:`Condition`; ``ValueError`` when it is none of :data:`CONDITIONS`."""
    for condition in CONDITIONS:
        if text == condition:
            return condition
    raise ValueError(f"condition must be one of {', '.join(CONDITIONS)}, got {text!r}")


def _check_pose(values: list[float]) -> list[float]:
    if len(values) != 7:
        raise ValueError(f"a pose is [x, y, z, qw, qx, qy, qz]: 7 numbers, got {len(values)}")
    if not all(math.isfinite(v) for v in values):
        raise ValueError("pose contains non-finite values")
    if any(abs(v) > MAX_POSE_POSITION for v in values[:3]):
        raise ValueError(f"pose position beyond +-{MAX_POSE_POSITION:g} scene units")
    if any(abs(v) > MAX_POSE_QUAT_COMPONENT for v in values[3:]):
        raise ValueError(f"pose quaternion component beyond +-{MAX_POSE_QUAT_COMPONENT:g}")
    if math.sqrt(sum(v * v for v in values[3:])) < 1e-9:
        raise ValueError("pose quaternion has zero length")
    return [float(v) for v in values]


def pose_problem(values: list[float]) -> str | None:
    """Why ``values`` is not a usable pose ``[x, y, z, qw, qx, qy, qz]`` (the rule every recorded
    pose follows), or None when it is one."""
    try:
        _check_pose(list(values))
    except ValueError as exc:
        return str(exc)
    return None


PoseList = Annotated[list[float], AfterValidator(_check_pose)]
