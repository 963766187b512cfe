"""Components from candidate pairs: the same as testing every pair; progress and the slow-work warning."""

from __future__ import annotations

import io
import itertools
import threading
import warnings

import numpy as np
import pytest

from aw import pair_search
from aw.pair_search import LongWorkWarning, candidate_pairs, components


def _all_pairs(n, edge):
    parent = list(range(n))

    def root(i):
        while parent[i] != i:
            i = parent[i]
        return i

    for i, j in itertools.combinations(range(n), 2):
        if edge(i, j):
            a, b = root(i), root(j)
            parent[max(a, b)] = min(a, b)
    groups = {}
    for i in range(n):
        groups.setdefault(root(i), []).append(i)
    return sorted(groups.values(), key=lambda g: g[0])


def test_components_equal_every_pair_and_skip_connected_pairs():
    rng = np.random.default_rng(0)
    for trial in range(30):
        _check_serial_search(rng, trial)


def _check_serial_search(rng: np.random.Generator, trial: int) -> None:
    n = int(rng.integers(1, 25))
    edges = {(i, j) for i, j in itertools.combinations(range(n), 2) if rng.random() < 0.15}
    lower = rng.random((n, n)) * 2e-4
    lower = np.minimum(lower, lower.T)
    for i, j in edges:  # a true edge always has a bound under the threshold
        lower[i, j] = lower[j, i] = min(lower[i, j], 1e-4)
    asked = []

    def edge(i, j):
        asked.append((i, j))
        return (i, j) in edges

    got = components(n, candidate_pairs(lower, 1e-4), edge, what="test", show_progress=False)
    assert got == _all_pairs(n, lambda i, j: (i, j) in edges), trial
    assert len(asked) == len(set(asked)) and all(i < j and lower[i, j] <= 1e-4 for i, j in asked)
    assert len(asked) <= len(candidate_pairs(lower, 1e-4))


def test_threads_register_pairs_at_once_with_the_same_components():
    """With ``workers=2`` two registrations run at the same time (each waits for the other at a
    barrier, which a serial search would never pass), and the components are every pair's."""
    rng = np.random.default_rng(1)
    for trial in range(20):
        _check_threaded_search(rng, trial)


def _check_threaded_search(rng: np.random.Generator, trial: int) -> None:
    n = int(rng.integers(2, 25))
    edges = {(i, j) for i, j in itertools.combinations(range(n), 2) if rng.random() < 0.15}
    lower = np.zeros((n, n))
    # one candidate (n == 2): nothing to run beside it
    met = threading.Barrier(2 if n > 2 else 1, timeout=10)
    asked, threads = [], set()

    def edge(i, j):
        if not asked or len(asked) == 1:  # the first two registrations meet
            asked.append((i, j))
            met.wait()
        else:
            asked.append((i, j))
        threads.add(threading.current_thread().name)
        return (i, j) in edges

    got = components(n, candidate_pairs(lower, 1e-4), edge, what="test", show_progress=False, workers=2)
    assert got == _all_pairs(n, lambda i, j: (i, j) in edges), trial
    assert len(asked) == len(set(asked)) and all(t.startswith("aw-pairs") for t in threads)


def test_local_workers_are_the_cores_here_and_one_in_a_worker_process():
    import multiprocessing
    import os

    assert pair_search.local_workers() == len(os.sched_getaffinity(0))
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        assert pool.apply(pair_search.local_workers) == 1


def test_candidates_come_by_increasing_bound_and_keep_the_threshold_inclusive():
    lower = np.array([[0, 3e-5, 1e-4, 2e-4], [3e-5, 0, 0, 5e-5], [1e-4, 0, 0, 1e-4], [2e-4, 5e-5, 1e-4, 0]])
    assert candidate_pairs(lower, 1e-4).tolist() == [[1, 2], [0, 1], [1, 3], [0, 2], [2, 3]]


def test_slow_work_warns_with_an_estimate_and_shows_progress(monkeypatch):
    monkeypatch.setattr(pair_search, "_SAMPLE_S", 0.0)
    monkeypatch.setattr(pair_search, "WARN_AFTER_S", 0.0)
    monkeypatch.setattr(pair_search, "_BAR_FROM", 1)
    monkeypatch.setattr(pair_search, "progress", _recording_progress)
    lower = np.zeros((6, 6))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        got = components(6, candidate_pairs(lower, 1e-4), lambda i, j: False, what="groups of 6 parts")
    assert got == [[k] for k in range(6)]
    slow = [w for w in caught if issubclass(w.category, LongWorkWarning)]
    assert len(slow) == 1 and "groups of 6 parts: up to 13 of 15 candidate pairs left" in str(slow[0].message)
    assert "min on this machine" in str(slow[0].message)
    assert "groups of 6 parts: 15/15 pair" in _OUT.getvalue()


def test_fast_work_does_not_warn():
    lower = np.zeros((5, 5))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert components(5, candidate_pairs(lower, 1e-4), lambda i, j: True, what="t") == [[0, 1, 2, 3, 4]]


_OUT = io.StringIO()


def _recording_progress(total, desc, unit="it", *, enabled=True, leave=True):
    from aw.progress import progress

    return progress(total, desc, unit, enabled=enabled, file=_OUT, interval=0.0, leave=leave)


def _components_in_a_worker(n: int) -> list[list[int]]:
    pair_search._BAR_FROM = 1
    pair_search.progress = _recording_progress
    _OUT.truncate(0)
    groups = components(n, candidate_pairs(np.zeros((n, n)), 1.0), lambda i, j: True, what="groups")
    assert _OUT.getvalue() == ""  # nothing drawn: the parent process owns the display
    return groups


def test_a_worker_process_draws_no_progress_of_its_own():
    import multiprocessing

    with multiprocessing.get_context("spawn").Pool(1) as pool:
        assert pool.apply(_components_in_a_worker, (25,)) == [list(range(25))]


class _Clock:
    """A clock that only the registrations move: each takes one second."""

    def __init__(self) -> None:
        self.now = 0.0

    def monotonic(self) -> float:
        return self.now

    def register(self, edge: bool) -> bool:
        self.now += 1.0
        return edge


@pytest.mark.parametrize(("identical", "warns"), [(True, False), (False, True)])
def test_the_estimate_expects_a_group_of_identical_parts_to_form_fast(monkeypatch, identical, warns):
    """100 identical parts: 4,950 candidates, but at most 99 registrations find an edge and every
    other candidate is skipped, so one second a registration is no long work (99 s); 100 parts of
    which no two match: every candidate is registered, about 80 min."""
    clock = _Clock()
    monkeypatch.setattr(pair_search, "time", clock)
    n = 100
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        got = components(
            n,
            candidate_pairs(np.zeros((n, n)), 1e-4),
            lambda i, j: clock.register(identical),
            what=f"groups of {n} parts",
        )
    assert got == ([list(range(n))] if identical else [[k] for k in range(n)])
    slow = [str(w.message) for w in caught if issubclass(w.category, LongWorkWarning)]
    assert len(slow) == int(warns), slow
    if warns:
        assert "min on this machine (1.00 s a pair, 1 at a time)" in slow[0] and "about 82 min" in slow[0]


def test_registration_groups_ask_fewer_registrations_with_the_same_groups():
    # boxes of similar size and other proportions (the rigid-invariant bound leaves these pairs,
    # the rotation bound does not), and moved copies of three of the parts (edges)
    import trimesh
    from scipy.spatial.transform import Rotation

    from aw.prepare.official_similarity import register
    from aw.shape_bounds import cloud_bounds, lower_bounds

    rng = np.random.default_rng(2)
    parts = [
        np.asarray(trimesh.sample.sample_surface(trimesh.creation.box(extents=e), 300, seed=k)[0])
        for k, e in enumerate([(0.6, 0.4, 0.2), (0.5, 0.5, 0.2), (0.6, 0.3, 0.25), (0.45, 0.45, 0.3), (0.1, 0.1, 0.3)])
    ]
    clouds = [
        parts[k] @ Rotation.random(random_state=rng).as_matrix().T + rng.normal(size=3)
        for k in (0, 1, 2, 3, 0, 1, 4, 4)
    ]
    threshold = 1e-4
    asked = []

    def registers(i, j):
        asked.append((i, j))
        return register(clouds[i], clouds[j], enough=threshold) <= threshold

    got = pair_search.registration_groups(clouds, threshold, registers, what="test", show_progress=False, workers=2)
    assert got == _all_pairs(len(clouds), lambda i, j: register(clouds[i], clouds[j]) <= threshold)
    assert got == [[0, 4], [1, 5], [2], [3], [6, 7]]
    rigid = candidate_pairs(lower_bounds(cloud_bounds(np.stack(clouds))), threshold)
    assert len(asked) <= 5 < len(rigid)  # the copies' pairs (and any the rotation bound leaves)
