"""From pairwise fits to one assembly: the anchor first, then, one at a time, the fragment whose
best fit to a fragment already placed scores highest once its sinking into every placed
fragment is charged; then rounds in which each fragment is refined against all the others.

Poses here are ``(R (3, 3), t (3,))`` mapping a fragment's mesh frame into the anchor's.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from aw.refine.classical.contact import Pose, Tolerance, objective, relative, sunk_share, tolerance
from aw.refine.classical.fit import contact_icp
from aw.refine.classical.pairs import Fit, register_pair
from aw.refine.classical.surface import Cloud, Fragment

__all__ = ["Pose", "assemble", "assembly_objective", "refine_jointly"]

TOP_FITS = 3  # fits of each pair considered when placing
JOINT_ROUNDS = 2


def _compose(outer: Pose, fit: Fit) -> Pose:
    return outer[0] @ fit.rot, outer[0] @ fit.shift + outer[1]


def _tols(fragments: list[Fragment]) -> dict[tuple[int, int], Tolerance]:
    n = len(fragments)
    return {(i, j): tolerance(fragments[i], fragments[j]) for i in range(n) for j in range(i + 1, n)}


def assembly_objective(fragments: list[Fragment], poses: list[Pose]) -> float:
    """:func:`contact.objective` of the fragments at ``poses``."""
    return objective(fragments, poses, _tols(fragments))


def assemble(fragments: list[Fragment], anchor: int, log: Callable[[str], None]) -> list[Pose]:
    """Poses of every fragment (the anchor's the identity) from the global search."""
    n = len(fragments)
    fits: dict[tuple[int, int], list[Fit]] = {}
    for i in range(n):
        for j in range(i + 1, n):
            found = register_pair(fragments[i], fragments[j], partial=n > 2)
            fits[(i, j)] = found
            fits[(j, i)] = [f.inverse() for f in found]
    poses: dict[int, Pose] = {anchor: (np.eye(3), np.zeros(3))}
    while len(poses) < n:
        best: tuple[float, int, int, Pose] | None = None
        for j in range(n):
            if j in poses:
                continue
            for i, pose_i in poses.items():
                for fit in fits[(i, j)][:TOP_FITS]:
                    pose = _compose(pose_i, fit)
                    value = fit.score - 2.0 * _sinking(fragments, poses, j, pose, skip=i)
                    if best is None or value > best[0]:
                        best = (value, i, j, pose)
        if best is None:  # no fit at all: the rest stay where the anchor's frame puts them
            for j in range(n):
                poses.setdefault(j, (np.eye(3), np.zeros(3)))
            log("classical: no candidate contact regions for some fragments; left in place")
            break
        value, i, j, pose = best
        poses[j] = pose
        log(f"classical: placed fragment {j} against {i} (score {value:.3f})")
    ordered = [poses[k] for k in range(n)]
    return refine_jointly(fragments, anchor, ordered) if n > 2 else ordered


def _sinking(fragments: list[Fragment], poses: dict[int, Pose], j: int, pose: Pose, skip: int) -> float:
    """How far fragment ``j`` at ``pose`` sinks into the placed fragments other than ``skip``."""
    worst = 0.0
    for k, placed in poses.items():
        if k == skip:
            continue
        tol = tolerance(fragments[j], fragments[k])
        into_k, into_j = relative(placed, pose), relative(pose, placed)
        body, other = fragments[j].body, fragments[k].body
        worst = max(worst, sunk_share(body, other, tol, into_k), sunk_share(other, body, tol, into_j))
    return worst


def _regions_cloud(fragment: Fragment, pose: Pose) -> Cloud:
    cloud = Cloud(
        np.vstack([r.fine.points for r in fragment.regions]), np.vstack([r.fine.normals for r in fragment.regions])
    )
    return cloud.moved(*pose)


def refine_jointly(
    fragments: list[Fragment], anchor: int, poses: list[Pose], rounds: int = JOINT_ROUNDS, radius: float | None = None
) -> list[Pose]:
    """Rounds of ICP of each fragment's candidate regions against all the other fragments'
    (restricted to the contact, pairs first within ``radius``, default four contact tolerances),
    a step kept only when the assembly's objective improves."""
    poses = list(poses)
    current = assembly_objective(fragments, poses)
    for _ in range(rounds):
        for j, frag in enumerate(fragments):
            if j == anchor or not frag.regions:
                continue
            others = [_regions_cloud(f, poses[k]) for k, f in enumerate(fragments) if k != j and f.regions]
            if not others:
                continue
            target = Cloud(np.vstack([c.points for c in others]), np.vstack([c.normals for c in others]))
            local = Cloud(
                np.vstack([r.fine.points for r in frag.regions]), np.vstack([r.fine.normals for r in frag.regions])
            )
            tol = max(tolerance(frag, f).eps for k, f in enumerate(fragments) if k != j)
            rot, shift = contact_icp(local, target, poses[j][0], poses[j][1], radius or 4 * tol, tol)
            trial = list(poses)
            trial[j] = (rot, shift)
            value = assembly_objective(fragments, trial)
            if value > current:
                poses, current = trial, value
    return poses
