"""Connected components of a "registers within the threshold" relation, registering few pairs.

Both equivalence rules define the groups as the connected components of the graph whose edges
are the pairs an expensive test (an ICP registration) accepts. The components do not depend on
the order edges are found in, so the search here (:func:`registration_groups`) registers, in
order of increasing lower bound (likely edges first):

- only the *candidates*: pairs whose proven lower bound over every rigid motion does not exceed
  the threshold; every other pair cannot be an edge. Two bounds, the second only where the first
  leaves the pair: one from quantities no rotation changes (:mod:`aw.shape_bounds`, all pairs at
  once), and one that searches the rotations (:mod:`aw.rotation_bound`, per pair);
- only a candidate whose parts are not connected yet: its edge could not change the components.

So the components equal those of testing every pair, also when several candidates are
registered at once in threads (``workers``; a candidate is started only while its parts are
not connected, and an edge found meanwhile only joins what it joins). Registrations are timed
as they go: when the ones left would take long on this machine (their mean time, the first one
left out as it may load compiled code, times the registrations expected among the candidates
left that are not yet connected, over the threads; see :func:`_registrations_left`), a
:class:`LongWorkWarning` says so with the estimate, and a progress display
(:func:`aw.progress.progress`) shows them.
"""

from __future__ import annotations

import multiprocessing
import os
import time
import warnings
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

import numpy as np

from aw.progress import WARN_AFTER_S, LongWorkWarning, progress
from aw.rotation_bound import box_frame, rules_out
from aw.shape_bounds import SAFETY, cloud_bounds, lower_bounds

__all__ = ["LongWorkWarning", "candidate_pairs", "components", "local_workers", "registration_groups", "WARN_AFTER_S"]

_SAMPLE_S = 10.0  # first estimate after this long (then after twice as long, and so on)
_BAR_FROM = 20  # fewer candidates than this need no progress display


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


def registration_groups(
    clouds: list[np.ndarray],
    threshold: float,
    registers: Callable[[int, int], bool],
    *,
    what: str,
    show_progress: bool = True,
    workers: int | None = None,
) -> list[list[int]]:
    """Components of ``range(len(clouds))`` under "``registers(i, j)``" (``i < j``: does ICP bring
    cloud ``i`` within ``threshold`` of cloud ``j``?), ``clouds`` each ``(n, 3)`` in any frame,
    in the units of ``threshold``; each component sorted, ordered by its lowest member.

    ``registers`` is asked only for the pairs that neither bound rules out and whose parts are
    not connected yet (:func:`components`, ``what``, ``show_progress``); ``workers``: threads
    testing pairs at once (default :func:`local_workers`). The components are those of asking
    it for every pair."""
    if not clouds:
        return []
    candidates = candidate_pairs(lower_bounds(cloud_bounds(np.stack(clouds))), threshold)
    frames: dict[int, object] = {}

    def frame(i: int):  # built once per part, only for parts in a candidate pair
        if i not in frames:  # two threads may both build one: the same, and the last kept
            frames[i] = box_frame(clouds[i])
        return frames[i]

    def is_edge(i: int, j: int) -> bool:
        return not rules_out(frame(i), frame(j), threshold) and registers(i, j)

    return components(
        len(clouds),
        candidates,
        is_edge,
        what=what,
        show_progress=show_progress,
        workers=local_workers() if workers is None else workers,
    )


def local_workers() -> int:
    """Threads this process may use for per-task work: the cores it may run on in the main
    process; 1 in a worker process (aw-score's ``--jobs`` pool, Dask), whose parent already
    runs one such process per core, so that nothing is oversubscribed."""
    if multiprocessing.parent_process() is not None:
        return 1
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def components(
    n: int,
    candidates: np.ndarray,
    is_edge: Callable[[int, int], bool],
    *,
    what: str,
    show_progress: bool = True,
    workers: int = 1,
) -> list[list[int]]:
    """Components of ``range(n)`` under the edges ``is_edge(i, j)`` (``i < j``) among ``candidates
    (K, 2)``; each sorted, ordered by their lowest member. ``what`` names the work in the progress
    display and the warning (e.g. ``"equivalence groups of 500 parts"``). ``workers``: threads
    registering candidates at once (``is_edge`` must then be thread-safe and release the GIL in
    its heavy part, as the compiled ICP does); a candidate is started only while its parts are
    not connected, so the components are the same for any number."""
    parent = list(range(n))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def timed_edge(i: int, j: int) -> tuple[bool, float]:
        t = time.monotonic()
        return is_edge(i, j), time.monotonic() - t

    total = len(candidates)
    pairs = candidates.tolist()
    workers = max(1, min(int(workers), total))
    # in a worker process (aw-score's pool, Dask) the parent owns the display: no second bar over it
    shown = show_progress and total >= _BAR_FROM and multiprocessing.parent_process() is None
    bar = progress(total, what, unit="pair", enabled=shown, leave=False)
    started = time.monotonic()
    check_at, warned = _SAMPLE_S, False
    timed, timed_s = 0, 0.0  # registrations after the first (which may load compiled code) and their time
    edges, non_edges, joined = 0, 0, 0  # registrations that found an edge / none; merges of two components
    k, done_count = 0, 0  # next candidate to consider; registrations finished
    running: dict = {}  # future -> (i, j) registering now
    pool = ThreadPoolExecutor(workers, thread_name_prefix="aw-pairs") if workers > 1 else None

    def finish(i: int, j: int, edge: bool, secs: float) -> None:
        nonlocal done_count, timed, timed_s, edges, non_edges, joined
        edges, non_edges = edges + edge, non_edges + (not edge)
        if edge:
            a, b = root(i), root(j)
            joined += a != b  # (two threads may join the same components)
            parent[max(a, b)] = min(a, b)
        if done_count:
            timed, timed_s = timed + 1, timed_s + secs
        done_count += 1
        bar.update(1)

    try:
        with bar:
            while k < total or running:
                while k < total and len(running) < workers:
                    i, j = pairs[k]
                    k += 1
                    if root(i) == root(j):
                        bar.update(1)  # connected already: its edge could not change the components
                    elif pool is None:
                        finish(i, j, *timed_edge(i, j))
                        break  # one at a time: the estimate below is checked after each
                    else:
                        running[pool.submit(timed_edge, i, j)] = (i, j)
                if running:
                    for fut in wait(running, return_when=FIRST_COMPLETED).done:
                        finish(*running.pop(fut), *fut.result())
                if not warned and timed and time.monotonic() - started >= check_at:
                    check_at *= 2  # estimates at 10, 20, 40 ... s: the count below walks the candidates left
                    left = sum(1 for i2, j2 in pairs[k:] if root(i2) != root(j2))
                    estimate = timed_s / timed * _registrations_left(left, edges, non_edges, n - joined) / workers
                    if estimate > WARN_AFTER_S:
                        warned = True
                        warnings.warn(
                            f"{what}: up to {left} of {total} candidate pairs left to register, about "
                            f"{estimate / 60:.0f} min on this machine ({timed_s / timed:.2f} s a pair, "
                            f"{workers} at a time)",
                            LongWorkWarning,
                            stacklevel=2,
                        )
    finally:
        if pool is not None:
            for fut in running:
                fut.cancel()
            pool.shutdown(wait=True)
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(root(i), []).append(i)
    return sorted(groups.values(), key=lambda g: g[0])


def _registrations_left(left: int, edges: int, non_edges: int, n_components: int) -> float:
    """How many of the ``left`` candidates not yet connected will still be registered, expected
    from those registered so far: the share of them that found no edge is registered in full,
    while the ones that find an edge are at most one fewer than the components (each joins two,
    and skips every candidate between them: a group of many identical parts forms fast)."""
    done = edges + non_edges
    return min(left, left * non_edges / done + min(n_components - 1, left * edges / done))
