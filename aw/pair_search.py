"""Connected components of a "registers within the threshold" relation, registering few pairs.

Both equivalence rules define the groups as the connected components of the graph whose edges
are the pairs an expensive test (an ICP registration) accepts. The components do not depend on
the order edges are found in, so the search here registers, in order of increasing lower bound
(likely edges first):

- only the *candidates*: pairs whose proven lower bound (:mod:`aw.shape_bounds`) does not exceed
  the threshold; every other pair cannot be an edge;
- only a candidate whose parts are not connected yet: its edge could not change the components.

So the components equal those of testing every pair. Registrations are timed as they go: when
the ones left would take long on this machine, a :class:`LongWorkWarning` says so with the
estimate, and a progress display (:func:`aw.progress.progress`) shows them.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable

import numpy as np

from aw.progress import progress
from aw.shape_bounds import SAFETY

__all__ = ["LongWorkWarning", "candidate_pairs", "components", "WARN_AFTER_S"]

WARN_AFTER_S = 300.0  # an estimate above this (seconds) is worth a warning
_SAMPLE_S = 2.0  # time the first registrations this long before estimating
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
    bar = progress(total, what, unit="pair", enabled=show_progress and total >= _BAR_FROM, leave=False)
    started = time.monotonic()
    registered, warned = 0, False
    with bar:
        for k, (i, j) in enumerate(candidates.tolist()):
            a, b = root(i), root(j)
            if a != b:
                registered += 1
                if is_edge(i, j):
                    parent[max(a, b)] = min(a, b)
            bar.update(1)
            spent = time.monotonic() - started
            if not warned and registered and spent >= _SAMPLE_S:
                warned = True
                estimate = spent / registered * (total - k - 1)
                if estimate > WARN_AFTER_S:
                    warnings.warn(f"{what}: {total - k - 1} candidate pairs left to register, up to about "
                                  f"{estimate / 60:.0f} min on this machine ({spent / registered:.2f} s a pair)",
                                  LongWorkWarning, stacklevel=2)
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(root(i), []).append(i)
    return sorted(groups.values(), key=lambda g: g[0])
