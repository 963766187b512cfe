"""The refiner contract: what a refiner is given, and what its answer must satisfy."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aw.cli.common import plural
from aw.prepare.official_protocol import rotation_of

__all__ = [
    "ANCHOR_TOLERANCE",
    "SAME_AS_START",
    "RefineRequest",
    "RefinerError",
    "anchor_index",
    "check_poses",
    "identity_poses",
    "returned_start",
]

# How far the anchor may drift (position units; rotation-matrix entries) before it counts as moved:
# JSON round trips and quaternion normalisation stay far below it.
ANCHOR_TOLERANCE = 1e-6
# How close (per pose component) a refiner's answer must be to its start to count as the start
# returned unchanged: a refiner that found nothing better, not one that moved a part slightly.
SAME_AS_START = 1e-9


class RefinerError(Exception):
    """A refiner failed or answered wrongly; the message names the refiner and the problem."""


def identity_poses(n: int) -> np.ndarray:
    """``(n, 7)`` identity poses ``[0, 0, 0, 1, 0, 0, 0]``: the task's layout."""
    poses = np.zeros((n, 7))
    poses[:, 3] = 1.0
    return poses


def anchor_index(points: list[np.ndarray], part_ids: list[str] | None = None) -> int:
    """The anchor: the part with the most shared samples, on ties the first in sorted part-id
    order (the order in which the fracture protocol's evaluation picks it)."""
    order = sorted(range(len(points)), key=lambda i: part_ids[i]) if part_ids is not None else range(len(points))
    return max(order, key=lambda i: (len(points[i]), -list(order).index(i)))


@dataclass
class RefineRequest:
    """One task for a refiner.

    ``points``: per part ``(n_i, 3)``, the fracture protocol's shared samples in the part's mesh
    frame (:func:`aw.prepare.official_protocol.fracture_samples`); ``meshes``: per part
    ``(vertices (v_i, 3), faces (f_i, 3))`` in the same frame; ``mesh_paths``: the task's part
    files; ``initial_poses (P, 7)`` ``[x, y, z, qw, qx, qy, qz]`` map mesh frame to scene (the
    task's layout, identity, when none was given). The anchor keeps its initial pose.
    """

    task_id: str
    part_ids: list[str]
    points: list[np.ndarray]
    meshes: list[tuple[np.ndarray, np.ndarray]]
    mesh_paths: list[str]
    initial_poses: np.ndarray
    given_initial_poses: bool = False
    seed: int = 42
    steps: int = 20
    options: dict[str, Any] = field(default_factory=dict)

    @property
    def anchor(self) -> int:
        return anchor_index(self.points, self.part_ids)


def check_poses(name: str, request: RefineRequest, poses: Any) -> np.ndarray:
    """The refiner's answer as ``(P, 7)`` unit-quaternion poses, or :class:`RefinerError` naming
    ``name`` and what is wrong: a wrong number of poses, non-finite values, a zero quaternion, or
    an anchor that moved."""
    n = len(request.part_ids)
    try:
        arr = np.asarray(poses, dtype=np.float64)
    except (TypeError, ValueError):
        raise RefinerError(f"refiner {name}: poses are not numbers") from None
    if arr.ndim != 2 or arr.shape[1] != 7:
        got = arr.shape[0] if arr.ndim >= 1 else 0
        if arr.ndim == 2 and arr.shape[0] == n:
            raise RefinerError(
                f"refiner {name}: each pose needs 7 numbers [x, y, z, qw, qx, qy, qz], got {arr.shape[1]}"
            )
        raise RefinerError(f"refiner {name}: returned {plural(got, 'pose')} for {plural(n, 'part')}")
    if arr.shape[0] != n:
        raise RefinerError(f"refiner {name}: returned {plural(arr.shape[0], 'pose')} for {plural(n, 'part')}")
    bad = [request.part_ids[i] for i in np.flatnonzero(~np.isfinite(arr).all(axis=1))]
    if bad:
        raise RefinerError(f"refiner {name}: non-finite pose for {', '.join(bad)}")
    norms = np.linalg.norm(arr[:, 3:], axis=1)
    zero = [request.part_ids[i] for i in np.flatnonzero(norms < 1e-9)]
    if zero:
        raise RefinerError(f"refiner {name}: zero quaternion for {', '.join(zero)}")
    arr[:, 3:] /= norms[:, None]
    a = request.anchor
    start = request.initial_poses[a]
    moved = max(
        float(np.abs(arr[a, :3] - start[:3]).max()),
        float(np.abs(rotation_of(arr[a, 3:]) - rotation_of(start[3:])).max()),
    )
    if moved > ANCHOR_TOLERANCE:
        raise RefinerError(
            f"refiner {name}: moved the anchor {request.part_ids[a]} (by {moved:.3g}; it must keep its initial pose)"
        )
    return arr


def returned_start(start: np.ndarray, poses: np.ndarray, tol: float = SAME_AS_START) -> bool:
    """Whether a refiner's ``poses (P, 7)`` equal its ``start (P, 7)`` within ``tol`` in every
    component (a quaternion and its negative being the same rotation)."""
    start, poses = np.asarray(start, dtype=np.float64), np.asarray(poses, dtype=np.float64)
    if start.shape != poses.shape:
        return False
    q_off = np.minimum(np.abs(poses[:, 3:] - start[:, 3:]).max(axis=1), np.abs(poses[:, 3:] + start[:, 3:]).max(axis=1))
    return bool(np.abs(poses[:, :3] - start[:, :3]).max(initial=0.0) <= tol and q_off.max(initial=0.0) <= tol)
