"""Part matching (Appendix A.3 of the paper): after registration, each predicted part is matched
to a target part by the Hungarian method *inside* its equivalence group (interchangeable parts
may trade places; others are matched to themselves), on raw, unclipped part Chamfer distances.
A part's error is the CD to its match."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

__all__ = ["match_within_groups", "match_parts"]


def match_within_groups(cost: np.ndarray, groups) -> tuple[np.ndarray, np.ndarray]:
    """Hungarian assignment inside each group (``scipy.optimize.linear_sum_assignment``) on raw,
    unclipped costs ``cost (P, P)`` (pred i, target j). Returns ``(assignment (P,), errors (P,))``."""
    p = cost.shape[0]
    assign = np.arange(p)
    for g in groups:
        g = np.asarray(g, dtype=np.int64)
        if g.size == 1:
            continue
        rows, cols = linear_sum_assignment(cost[np.ix_(g, g)])
        assign[g[rows]] = g[cols]
    return assign, cost[np.arange(p), assign]


def _box_gap_sq(point: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    d = np.maximum(0.0, np.maximum(lo - point, point - hi))
    return float(d @ d)


def match_parts(index, moved_parts: np.ndarray, groups, to_baked: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Hungarian assignment within groups on the part CDs: ``(assignment (P,), errors (P,))``.
    ``index``: the task's :class:`aw_eval.kernels.TaskIndex`; ``moved_parts (P, n, 3)``: the
    registered prediction; ``to_baked``: the maps of its points into each part's baked frame
    (see :meth:`aw_eval.kernels.TaskIndex.part_cd`).

    Inside a group, pairs start at a proven lower bound (``forward >= dist(mean X, box Y)^2``
    by Jensen's inequality, likewise backward) and only the pairs an optimal assignment uses
    are computed exactly, until it uses exact costs alone: that assignment is then optimal for
    the exact costs too, so far-apart pairs are never computed.
    """
    p = moved_parts.shape[0]
    assign = np.arange(p)
    errors = np.empty(p)
    bounds: tuple[np.ndarray, ...] | None = None  # only groups of equivalent parts need them
    for g in groups:
        g = list(g)
        if len(g) == 1:
            i = g[0]
            errors[i] = index.part_cd(moved_parts, to_baked, i, i)
            continue
        k = len(g)
        if bounds is None:
            means, (lows, highs) = index.part_bounds()
            bounds = (means, lows, highs, moved_parts.mean(axis=1), moved_parts.min(axis=1), moved_parts.max(axis=1))
        tm, tlo, thi, pm, plo, phi = bounds
        cost = np.array(
            [[_box_gap_sq(pm[i], tlo[j], thi[j]) + _box_gap_sq(tm[j], plo[i], phi[i]) for j in g] for i in g]
        )
        exact = np.zeros((k, k), dtype=bool)
        while True:
            cols = match_within_groups(cost, [list(range(k))])[0]
            todo = [(a, cols[a]) for a in range(k) if not exact[a, cols[a]]]
            if not todo:
                break
            for a, c in todo:
                cost[a, c] = index.part_cd(moved_parts, to_baked, g[a], g[c])
                exact[a, c] = True
        for a in range(k):
            assign[g[a]] = g[cols[a]]
            errors[g[a]] = cost[a, cols[a]]
    return assign, errors
