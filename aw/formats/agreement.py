"""Whether a run's records of its end agree: ``final.json``, the trajectory's end record and its
last recorded call are written from one scene state, so a difference beyond float noise is a
contradiction (edits that no call records, a final.json written by someone else). ``aw-score``
flags such a run and scores the calls' state; ``aw-prepare official-export`` refuses it."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from aw.formats.trajectory import Trajectory
from aw.pose import normalize_quaternion

__all__ = ["FINAL_MATCH_TOL", "contradicting_parts", "closing_contradiction"]

FINAL_MATCH_TOL = 1e-6  # per pose component; q and -q are one rotation


def contradicting_parts(
    final: Mapping[str, Sequence[float]],
    recorded: Mapping[str, Sequence[float]],
    part_ids: Sequence[str],
    tol: float = FINAL_MATCH_TOL,
) -> list[str]:
    """Parts whose pose in ``final`` differs from ``recorded`` (beyond ``tol`` per component;
    ``q`` and ``-q`` are the same rotation)."""
    out = []
    for pid in part_ids:
        a, b = np.asarray(final[pid], dtype=np.float64), np.asarray(recorded[pid], dtype=np.float64)
        qa, qb = normalize_quaternion(a[3:]), normalize_quaternion(b[3:])
        if np.abs(a[:3] - b[:3]).max() > tol or min(np.abs(qa - qb).max(), np.abs(qa + qb).max()) > tol:
            out.append(pid)
    return out


def closing_contradiction(traj: Trajectory, final_poses: Mapping[str, Sequence[float]] | None) -> list[str]:
    """Parts whose closing pose (``final_poses`` from final.json, else the end record's) contradicts
    the state the trajectory's calls leave; [] when they agree or nothing closes the run."""
    closing = final_poses if final_poses is not None else (traj.end.poses if traj.end is not None else None)
    if closing is None:
        return []
    return contradicting_parts(closing, traj.checkpoints()[-1].poses, traj.header.part_ids)
