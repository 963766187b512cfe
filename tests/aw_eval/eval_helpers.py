"""Shared builders for the evaluator tests: small point-cloud tasks (no mesh files) and checks."""

from __future__ import annotations

from functools import cache

import numpy as np

from aw_eval.fixtures import make_points_geometry
from aw_eval.settings import ProtocolSettings


def small_settings(n_points: int, max_iters: int = 25) -> ProtocolSettings:
    return ProtocolSettings(n_surface=4 * n_points, n_fps=n_points, max_iters=max_iters)


@cache
def small_task(n_parts: int, n_points: int = 12, seed: int = 0, max_iters: int = 25):
    """``(geometry, object)`` of a synthetic table with ``n_parts`` parts (cached per session)."""
    return make_points_geometry(n_parts, n_points, seed, small_settings(n_points, max_iters))


def close(a, b, rel: float = 1e-5, abs_: float = 1e-9) -> bool:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return bool(np.all(np.abs(a - b) <= np.maximum(abs_, rel * np.maximum(np.abs(a), np.abs(b)))))
