"""Connected components of a "registers within the threshold" relation, registering few pairs.

Both equivalence rules define the groups as the connected components of the graph whose edges
are the pairs an expensive test (an ICP registration) accepts. The components do not depend on
the order edges are found in, so the search here registers, in order of increasing lower bound
(likely edges first):

- only the *candidates*: pairs whose proven lower bound (:mod:`aw.shape_bounds`) does not exceed
  the threshold; every other pair cannot be an edge;
- only a candidate whose parts are not connected yet: its edge could not change the components.

So the components equal those of testing every pair. Registrations are timed as they go: when
the ones left would take long on this machine (the lower of: their mean time, the first one
left out as it may load compiled code, times the candidates left that are not yet connected;
the time so far per candidate passed, times the candidates left), a :class:`LongWorkWarning`
says so with the estimate, and a progress display (:func:`aw.progress.progress`) shows them.
"""

from __future__ import annotations

import multiprocessing
import time
import warnings
from collections.abc import Callable

import numpy as np

from aw.progress import progress
from aw.shape_bounds import SAFETY

__all__ = ["LongWorkWarning", "candidate_pairs", "components", "WARN_AFTER_S"]

WARN_AFTER_S = 300.0  # an estimate above this (seconds) is worth a warning
_SAMPLE_S = 10.0  # first estimate after this long (then after twice as long, and so on)
_BAR_FROM = 20  # fewer candidates than this need no progress display


class LongWorkWarning(UserWarning):
    """Per-task work that will take long on this machine (the message gives the estimate)."""


def candidate_pairs(lower: np.ndarray, threshold: float) -> np.ndarray:
    """``(K, 2)`` pairs ``i < j`` of the ``(P, P)`` bounds ``lower`` that may be within
    ``threshold`` (with the :data:`aw.shape_bounds.SAFETY` slack), by increasing bound, then index."""
    p = len(lower)
    i, j = np.triu_indices(p, 1)
    bound = lower[i, j]
    keep = bound <= threshold * (1 + SAFETY[0]) + SAFETY[1]
    i, j, bound = i[keep], j[keep], bound[keep]
    order = np.lexsort((j, i, bound))
    return np.stack([i[order], j[order]], axis=1).astype(np.int64)


def components(n: int, candidates: np.ndarray, is_edge: Callable[[int, int], bool], *, what: str,
               show_progress: bool = True) -> list[list[int]]:
    """Components of ``range(n)`` under the edges ``is_edge(i, j)`` (``i < j``) among ``candidates
    (K, 2)``; each sorted, ordered by their lowest member. ``what`` names the work in the progress
    display and the warning (e.g. ``"equivalence groups of 500 parts"``)."""
    parent = list(range(n))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    total = len(candidates)
    pairs = candidates.tolist()
    # in a worker process (aw-score's pool, Dask) the parent owns the display: no second bar over it
    shown = show_progress and total >= _BAR_FROM and multiprocessing.parent_process() is None
    bar = progress(total, what, unit="pair", enabled=shown, leave=False)
    started = time.monotonic()
    check_at, warned = _SAMPLE_S, False
    timed, timed_s = 0, 0.0  # registrations after the first (which may load compiled code) and their time
    with bar:
        for k, (i, j) in enumerate(pairs):
            a, b = root(i), root(j)
            if a != b:
                t = time.monotonic()
                if is_edge(i, j):
                    parent[max(a, b)] = min(a, b)
                if k:
                    timed, timed_s = timed + 1, timed_s + time.monotonic() - t
            bar.update(1)
            if not warned and timed and time.monotonic() - started >= check_at:
                check_at *= 2  # estimates at 10, 20, 40 ... s: the count below walks the candidates left
                left = sum(1 for i2, j2 in pairs[k + 1 :] if root(i2) != root(j2))
                # the lower of: each pair left not yet connected registered; the pace so far
                # (pairs joined meanwhile are skipped: a group of many identical parts forms fast)
                pace = (time.monotonic() - started) / (k + 1) * (total - k - 1)
                estimate = min(timed_s / timed * left, pace)
                if estimate > WARN_AFTER_S:
                    warned = True
                    warnings.warn(f"{what}: up to {left} of {total} candidate pairs left to register, about "
                                  f"{estimate / 60:.0f} min on this machine ({timed_s / timed:.2f} s a pair)",
                                  LongWorkWarning, stacklevel=2)
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(root(i), []).append(i)
    return sorted(groups.values(), key=lambda g: g[0])
