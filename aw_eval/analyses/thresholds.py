"""Correctness-threshold sweep with registration and matching held fixed (``fig:thresholds``).

Each run's saved matched part errors are re-thresholded: ``PA(tau) = mean(e <= tau)``,
``SR(tau) = all(e <= tau)``. The registration and Hungarian assignment that produced the errors
stay as they were, which isolates the cutoff from alignment and equivalence changes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from aw_eval.study.table import Study

__all__ = ["DEFAULT_THRESHOLDS", "sweep_errors", "threshold_sweep"]

# 25 log-spaced cutoffs from 1e-4 to 1e-1 (0.01, the protocol's, is one of them).
DEFAULT_THRESHOLDS = tuple(float(f"{x:.6g}") for x in np.geomspace(1e-4, 1e-1, 25))


def sweep_errors(errors: Sequence[np.ndarray | None], thresholds: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """PA and SR ``(T, len(thresholds))`` of per-run part errors (``None`` = unscored: 0)."""
    th = np.asarray(thresholds, dtype=np.float64)
    pa = np.zeros((len(errors), len(th)))
    sr = np.zeros((len(errors), len(th)))
    for i, e in enumerate(errors):
        if e is None or len(e) == 0:
            continue
        ok = np.asarray(e)[:, None] <= th[None, :]
        pa[i] = ok.mean(axis=0)
        sr[i] = ok.all(axis=0)
    return pa, sr


def threshold_sweep(study: Study, thresholds: Sequence[float] = DEFAULT_THRESHOLDS) -> dict[str, Any]:
    """Per system, eq.-3 PA and SR (percent) at every threshold."""
    d = study.design
    out: dict[str, Any] = {"thresholds": list(thresholds), "systems": {}}
    if d is None:
        return out
    for s in study.systems:
        errs = [study.score(s, t).part_errors if study.score(s, t).scored else None for t in d.task_ids]
        pa, sr = sweep_errors(errs, thresholds)
        out["systems"][s] = {"pa": (100 * d.weights @ pa).tolist(), "sr": (100 * d.weights @ sr).tolist()}
    return out
