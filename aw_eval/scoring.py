"""Scoring of checkpoints, top-down (Appendix A.3 of the paper):

1. the checkpoint's poses become rotations and normalized clouds, once
   (:meth:`aw_eval.geometry.TaskGeometry.checkpoint`);
2. the whole prediction is registered onto the whole target by symmetric ICP from the 24 PCA
   starts and one same-ID start per part (:mod:`aw_eval.starts`, :mod:`aw_eval.registration`);
3. registered parts are matched to target parts within equivalence groups (:mod:`aw_eval.matching`);
4. PA, SR, SCD and SR^a follow (:mod:`aw_eval.metrics`).

Scoring one checkpoint (:func:`score`) is a pure function of ``(geometry, poses, mode)``;
``backend`` only chooses where the arithmetic runs (``numba`` on the CPU, ``jax`` on any XLA
device, many checkpoints at once; the same numbers to rounding). A batch
(:func:`score_batch`) removes duplicate rows; in ``fast`` mode it also reads its rows as a
trajectory (a near-threshold refinement may start from the previous row's), so a batch is a pure
function of its rows in order: any worker layout gives identical numbers.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from aw import progress as _progress
from aw_eval.chamfer import chamfer_pairs
from aw_eval.geometry import Checkpoint, TaskGeometry
from aw_eval.kernels import fast_settings, part_cd_batch
from aw_eval.metrics import finalize, finalize_costs
from aw_eval.registration import (
    BACKENDS,
    MODES,
    check_mode,
    escalate,
    near_threshold,
    register_exact,
    register_exact_many,
    register_fast,
    resolve_backend,
)
from aw_eval.results import BatchScores, Registration, ScoreResult

__all__ = ["MODES", "BACKENDS", "JAX_CHUNK", "score", "score_batch", "part_diagnostics", "PartDiagnostics"]


# Checkpoints per call of the jax backend (calls are padded to a power of two up to it, so a
# study compiles a handful of shapes)
JAX_CHUNK = 32


def score(geom: TaskGeometry, poses: ArrayLike, mode: str = "exact", backend: str = "auto") -> ScoreResult:
    """Score one checkpoint ``poses (P, 7)`` (scored parts, in ``geom.part_ids`` order)."""
    check_mode(mode)
    backend = resolve_backend(backend, mode)
    arr = geom.check_poses(poses)
    if arr.ndim != 2:
        raise ValueError(f"score takes one checkpoint (P, 7); use score_batch for {arr.shape}")
    if backend == "jax":
        return _score_many_jax(geom, [geom.checkpoint(arr)], mode)[0]
    return _score_one(geom, geom.checkpoint(arr), mode, None)[0]


def _score_many_jax(
    geom: TaskGeometry, cks: list[Checkpoint], mode: str, stats: dict[str, Any] | None = None
) -> list[ScoreResult]:
    """``exact`` scores of ``cks`` on the jax backend: registration and the part CDs within
    equivalence groups batched over the checkpoints; the Hungarian step and the metrics on the
    host. ``stats``: adds seconds per stage (``structures``, ``icp``, ``part_cd``, ``host``) and
    the ICP's counters (:func:`aw_eval.kernels.icp_batch`)."""
    t0 = time.perf_counter()
    size = 1 << (len(cks) - 1).bit_length()  # padded with copies of the last checkpoint
    padded = cks + [cks[-1]] * (size - len(cks))
    geom.index().part_leaves(geom.divisor)  # built once per task
    t1 = time.perf_counter()
    icp_stats: dict[str, Any] = {}
    regs = register_exact_many(geom, padded, icp_stats)
    t2 = time.perf_counter()
    moved = np.stack([ck.parts @ r.rotation.T + r.translation for ck, r in zip(padded, regs, strict=True)])
    costs = part_cd_batch(moved, geom.target_parts(), [(i, j) for g in geom.groups for i in g for j in g])
    t3 = time.perf_counter()
    n = len(cks)  # the padding's results are dropped
    out = [finalize_costs(geom, r, c, mode) for r, c in zip(regs[:n], costs[:n], strict=True)]
    if stats is not None:
        t4 = time.perf_counter()
        for key, v in (
            ("structures", t1 - t0),
            ("icp", t2 - t1),
            ("part_cd", t3 - t2),
            ("host", t4 - t3),
            *icp_stats.items(),
        ):
            stats[key] = stats.get(key, 0) + v
    return out


def _score_one(
    geom: TaskGeometry, ck: Checkpoint, mode: str, warm: Registration | None
) -> tuple[ScoreResult, Registration | None]:
    """Score checkpoint ``ck``; returns the result and, in ``fast`` mode, the refined registration
    when the checkpoint was near a threshold (else ``None``): the next checkpoint of a
    trajectory passes it back as ``warm`` (see :func:`aw_eval.registration.escalate`)."""
    if mode == "exact":
        return finalize(geom, ck, register_exact(geom, ck), mode), None
    fast = fast_settings()
    reg = register_fast(geom, ck)
    res = finalize(geom, ck, reg, mode)
    refined = None
    if fast.margin > 1 and near_threshold(res, geom.settings, fast.margin):
        refined = escalate(geom, ck, reg, warm)
        res = finalize(geom, ck, refined, mode)
    if fast.exact_margin > 1 and near_threshold(res, geom.settings, fast.exact_margin):
        # a knife-edge decision: the last digits of the registration decide it, so only the
        # protocol's own registration (every start at full resolution) gives the protocol's answer
        res = finalize(geom, ck, register_exact(geom, ck), mode)
    return res, refined


def score_batch(
    geom: TaskGeometry,
    poses: ArrayLike,
    mode: str = "exact",
    progress: Callable[[int, int], object] | None = None,
    backend: str = "auto",
) -> BatchScores:
    """Score ``poses (N, P, 7)`` in row order (identical rows are scored once, at their first
    occurrence). ``exact`` rows equal :func:`score`'s. In ``fast`` mode the rows are taken as a
    trajectory: a row refined near a threshold starts its refinement from the previous row's
    refined registration when both lie in the same basin (consecutive checkpoints differ by one
    edit; :func:`aw_eval.registration.escalate`), so a fast row depends on the row before it: the same
    batch gives the same numbers in any process or worker layout, but splitting a trajectory
    into other batches may change the last digits of a refined row.

    ``progress``: optional callable ``(done, total)`` called after each unique row (on the
    ``jax`` backend, after each call of up to :data:`JAX_CHUNK` of them). The result's ``stats``
    hold ``seconds`` and, on the ``jax`` backend, ``jax``: seconds per stage and the ICP's
    counters (:func:`_score_many_jax`).
    """
    check_mode(mode)
    backend = resolve_backend(backend, mode)
    rows_poses = geom.check_poses(poses)
    if rows_poses.ndim != 3:
        raise ValueError(f"score_batch takes (N, P, 7) poses, got {rows_poses.shape}")
    n = rows_poses.shape[0]
    if n == 0:
        return BatchScores.empty(geom.n_parts, mode)
    flat = np.ascontiguousarray(rows_poses.reshape(n, -1))
    _, first, inverse = np.unique(flat, axis=0, return_index=True, return_inverse=True)
    t0 = time.perf_counter()
    results: dict[int, ScoreResult] = {}
    warm: Registration | None = None
    order = [int(k) for k in sorted(first)]
    stats: dict[str, Any] = {"seconds": 0.0}
    long_work = _LongWork(
        len(first), f"scoring {len(first)} states of a {geom.n_parts}-part task ({mode}, {backend})", t0
    )
    if backend == "jax":
        stats["jax"] = {}
        for lo in range(0, len(order), JAX_CHUNK):
            keys = order[lo : lo + JAX_CHUNK]
            results.update(
                zip(
                    keys,
                    _score_many_jax(geom, [geom.checkpoint(rows_poses[k]) for k in keys], mode, stats["jax"]),
                    strict=True,
                )
            )
            long_work.done(lo + len(keys))
            if progress is not None:
                progress(lo + len(keys), len(first))
    for done, k in enumerate(order if backend == "numba" else []):
        results[k], warm = _score_one(geom, geom.checkpoint(rows_poses[k]), mode, warm)
        long_work.done(done + 1)
        if progress is not None:
            progress(done + 1, len(first))
    by_unique = [results[k] for k in first]
    rows = [by_unique[u] for u in np.asarray(inverse).reshape(-1)]
    stats["seconds"] = time.perf_counter() - t0
    return BatchScores.stack(rows, mode, len(first), stats)


class _LongWork:
    """Warns once (:class:`aw.progress.LongWorkWarning`) when the states left of a batch would
    take long at the pace of those scored so far: an object of many parts can take minutes a
    state under ``exact``, and a study of it hours, with nothing else to show for it."""

    def __init__(self, total: int, what: str, started: float) -> None:
        self.total, self.what, self.started, self.warned = total, what, started, False

    def done(self, count: int) -> None:
        if self.warned or count >= self.total:
            return
        pace = (time.perf_counter() - self.started) / count
        left = pace * (self.total - count)
        if left > _progress.WARN_AFTER_S:
            self.warned = True
            warnings.warn(
                f"{self.what}: {self.total - count} left, about {left / 60:.0f} min on this machine "
                f"({pace:.1f} s a state)",
                _progress.LongWorkWarning,
                stacklevel=3,
            )


@dataclass
class PartDiagnostics:
    """Per-part diagnostics of Appendix C.2 under the saved registration and matching (``(P,)``):

    - ``offset``: distance between the centroids of registered pred part ``i`` and of its matched
      target part (normalized units: the largest part's PCA box diagonal is 1);
    - ``centred_cd``: CD of the two clouds after moving each to zero mean (orientation and shape
      error without translation);
    - ``never_moved``: the pose equals the identity initial pose.
    """

    offset: np.ndarray
    centred_cd: np.ndarray
    never_moved: np.ndarray
    part_errors: np.ndarray
    assignment: np.ndarray

    @property
    def moved(self) -> np.ndarray:
        return ~self.never_moved


def _row(result: ScoreResult | BatchScores, row: int | None) -> ScoreResult:
    if isinstance(result, BatchScores):
        if row is None:
            if len(result) != 1:
                raise ValueError("part_diagnostics on a BatchScores needs the row index")
            row = 0
        return result.row(int(row))
    return result


def part_diagnostics(
    geom: TaskGeometry,
    poses: ArrayLike,
    result: ScoreResult | BatchScores,
    row: int | None = None,
    atol: float = 1e-9,
) -> PartDiagnostics:
    """Diagnostics of one checkpoint ``poses (P, 7)`` scored as ``result`` (a :class:`ScoreResult`,
    or a :class:`BatchScores` with ``row``)."""
    res = _row(result, row)
    arr = geom.check_poses(poses)
    if arr.ndim != 2:
        raise ValueError(f"part_diagnostics takes one checkpoint (P, 7), got {arr.shape}")
    moved = geom.checkpoint(arr).parts @ res.reg_rotation.T + res.reg_translation
    matched = geom.target_parts()[res.assignment]
    mc, tc = moved.mean(axis=1), matched.mean(axis=1)
    offset = np.linalg.norm(mc - tc, axis=1)
    centred = chamfer_pairs(moved - mc[:, None, :], matched - tc[:, None, :])
    q = arr[:, 3:] / np.linalg.norm(arr[:, 3:], axis=1, keepdims=True)
    never = (np.abs(arr[:, :3]).max(axis=1) <= atol) & (np.abs(np.abs(q[:, 0]) - 1.0) <= atol)
    return PartDiagnostics(offset, centred, never, np.asarray(res.part_errors), np.asarray(res.assignment))
