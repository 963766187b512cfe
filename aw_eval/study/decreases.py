"""PA decreases between consecutive checkpoints, and whether they persist with the previous
checkpoint's registration (and matching) held fixed (Appendix C, Quality and Time Budgets).

A drop in PA from checkpoint ``k`` to ``k + 1`` can come from the agent moving a part away, or
from a changed global registration or interchangeable-part assignment. Re-scoring state
``k + 1`` under checkpoint ``k``'s registration (re-matching within equivalence groups), and
under both its registration and its matching, separates the two.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Decreases", "pa_decreases"]

_EPS = 1e-12


@dataclass
class Decreases:
    """``(D,)`` arrays over the decreases: ``index`` k (PA drops from k to k + 1),
    ``assignment_changed``, ``persist_alignment`` (still lower with k's registration, re-matched),
    ``persist_both`` (still lower with k's registration and k's matching)."""

    index: np.ndarray
    assignment_changed: np.ndarray
    persist_alignment: np.ndarray
    persist_both: np.ndarray


def pa_decreases(
    geom,
    poses: np.ndarray,
    pa: np.ndarray,
    assignment: np.ndarray,
    reg_rotation: np.ndarray,
    reg_translation: np.ndarray,
) -> Decreases:
    """Decreases of ``pa (N,)`` for checkpoints ``poses (N, P, 7)`` scored with ``assignment
    (N, P)``, ``reg_rotation (N, 3, 3)``, ``reg_translation (N, 3)`` on ``geom``."""
    from aw_eval import chamfer
    from aw_eval.matching import match_within_groups

    idx = np.flatnonzero(np.diff(pa) < -_EPS)
    n = len(idx)
    out = Decreases(idx.astype(np.int64), np.zeros(n, bool), np.zeros(n, bool), np.zeros(n, bool))
    if n == 0:
        return out
    threshold = geom.settings.threshold
    target = geom.target_parts()  # (P, n, 3)
    pairs = [(i, j) for g in geom.groups for i in g for j in g]
    pi = np.array([i for i, _ in pairs])
    pj = np.array([j for _, j in pairs])
    p = geom.n_parts
    for d, k in enumerate(idx):
        moved = geom.pred_parts(poses[k + 1]) @ reg_rotation[k].T + reg_translation[k]
        cost = np.full((p, p), np.inf)
        cost[pi, pj] = np.asarray(chamfer(moved[pi], target[pj]), dtype=np.float64).reshape(-1)
        _, errors = match_within_groups(cost, geom.groups)
        fixed = cost[np.arange(p), assignment[k]]
        out.assignment_changed[d] = bool(np.any(assignment[k + 1] != assignment[k]))
        out.persist_alignment[d] = float(np.mean(errors <= threshold)) < pa[k] - _EPS
        out.persist_both[d] = float(np.mean(fixed <= threshold)) < pa[k] - _EPS
    return out
