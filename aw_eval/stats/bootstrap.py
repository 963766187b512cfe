"""Percentile bootstrap over objects resampled within sources (Appendix B.1).

One draw resamples, independently in every source, as many objects as the source has, with
replacement. A task enters the draw as often as its object was drawn, so both PartNet conditions
of an object stay paired. Every system is evaluated on the same draws: the statistic of a draw is
a weighted sum of per-task values, ``stats = W @ values.T`` with one ``(B, T)`` weight matrix
``W`` shared by all systems, which also makes paired system differences exact per draw.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aw_eval.stats.design import Design

__all__ = [
    "object_counts",
    "draw_weights",
    "percentile_interval",
    "BootstrapResult",
    "bootstrap_overall",
    "paired_object_bootstrap",
]

DEFAULT_DRAWS = 10_000
DEFAULT_LEVEL = 0.95


def object_counts(design: Design, n_draws: int, rng: np.random.Generator) -> np.ndarray:
    """``(B, O)`` multiplicity of every object in every draw (sources resampled separately)."""
    if n_draws < 1:
        raise ValueError(f"n_draws must be >= 1, got {n_draws}")
    n_obj = len(design.objects)
    counts = np.zeros((n_draws, n_obj), dtype=np.int64)
    rows = np.arange(n_draws)[:, None]
    for k in range(len(design.sources)):
        members = np.flatnonzero(design.object_source == k)
        n = len(members)
        pick = rng.integers(0, n, size=(n_draws, n))
        flat = np.bincount((rows * n + pick).ravel(), minlength=n_draws * n).reshape(n_draws, n)
        counts[:, members] = flat
    return counts


def draw_weights(design: Design, counts: np.ndarray) -> np.ndarray:
    """``(B, T)`` eq.-3 weights of the tasks in each draw given object ``counts: (B, O)``.

    Within a cell, task weight times object multiplicity, normalized. A cell that a draw leaves
    empty (possible only when a source's conditions cover different objects) drops out and the
    source's other cells share its weight.
    """
    c_t = design.task_cell
    raw = counts[:, design.task_object] * design.task_weight[None, :]  # (B, T)
    task_in_cell = np.eye(len(design.cells))[c_t]  # (T, C) one-hot
    cell_in_source = np.eye(len(design.sources))[design.cell_source]  # (C, K) one-hot
    cell_total = raw @ task_in_cell  # (B, C)
    present = cell_total > 0
    present_per_source = present.astype(np.float64) @ cell_in_source  # (B, K)
    n_src = len(design.sources)
    with np.errstate(divide="ignore", invalid="ignore"):
        cell_w = np.where(present, 1.0 / (n_src * present_per_source[:, design.cell_source]), 0.0)
        w = raw * (cell_w / np.where(present, cell_total, 1.0))[:, c_t]
    return w


def percentile_interval(samples: np.ndarray, level: float = DEFAULT_LEVEL, axis: int = 0) -> np.ndarray:
    """Percentile interval ``[(1-level)/2, (1+level)/2]`` quantiles along ``axis`` (linear
    interpolation, NumPy's default); shape ``(2, ...)``."""
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    a = (1 - level) / 2
    return np.quantile(samples, [a, 1 - a], axis=axis)


@dataclass(frozen=True)
class BootstrapResult:
    """Overall estimates of ``S`` systems: ``point (S,)``, ``draws (B, S)``, ``ci (2, S)``."""

    point: np.ndarray
    draws: np.ndarray
    ci: np.ndarray

    def diff_ci(self, i: int, j: int, level: float = DEFAULT_LEVEL) -> np.ndarray:
        """Interval of system ``i`` minus system ``j`` on the shared draws, ``(2,)``."""
        return percentile_interval(self.draws[:, i] - self.draws[:, j], level)


def bootstrap_overall(
    design: Design,
    values: np.ndarray,
    *,
    n_draws: int = DEFAULT_DRAWS,
    seed: int = 0,
    level: float = DEFAULT_LEVEL,
    weights: np.ndarray | None = None,
) -> BootstrapResult:
    """Bootstrap of the eq.-3 Overall of ``values: (S, T)`` (one row per system).

    ``weights: (B, T)`` reuses draws already made (so that several metrics share resamples);
    otherwise they are drawn from ``seed``.
    """
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 2 or values.shape[1] != design.n_tasks:
        raise ValueError(f"values must have shape (systems, {design.n_tasks}), got {values.shape}")
    if not np.all(np.isfinite(values)):
        raise ValueError("values must be finite (score a missing outcome as 0 before bootstrapping)")
    if weights is None:
        weights = draw_weights(design, object_counts(design, n_draws, np.random.default_rng(seed)))
    draws = weights @ values.T
    return BootstrapResult(design.weights @ values.T, draws, percentile_interval(draws, level))


def paired_object_bootstrap(
    diffs: np.ndarray, *, n_draws: int = DEFAULT_DRAWS, seed: int = 0, level: float = DEFAULT_LEVEL
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and interval of per-object differences ``diffs: (S, O)`` (NaN = object not paired
    for that system is not allowed). Every system uses the same object resamples.

    Returns ``(mean (S,), ci (2, S))``.
    """
    diffs = np.asarray(diffs, dtype=np.float64)
    if diffs.ndim != 2 or diffs.shape[1] == 0:
        raise ValueError(f"diffs must have shape (systems, objects >= 1), got {diffs.shape}")
    if not np.all(np.isfinite(diffs)):
        raise ValueError("diffs must be finite")
    n = diffs.shape[1]
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, n, size=(n_draws, n))
    counts = np.bincount((np.arange(n_draws)[:, None] * n + pick).ravel(), minlength=n_draws * n).reshape(n_draws, n)
    draws = counts @ diffs.T / n  # (B, S)
    return diffs.mean(axis=1), percentile_interval(draws, level)
