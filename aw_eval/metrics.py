"""Metrics of a registered checkpoint (Section 4 and Appendix A.3 of the paper), from the part
errors of :mod:`aw_eval.matching` and the registration's objective:

- **PA** (part accuracy): the share of parts whose error is ``<= threshold`` (0.01, inclusive);
- **SR** (success rate): every part within the threshold;
- **SCD**: the registration's best objective, the symmetric Chamfer distance of the whole
  registered prediction to the target (normalized units; reported x1000 by the official tools);
- **SR^a**: SCD below ``sra_threshold``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from aw_eval.geometry import Checkpoint, TaskGeometry
from aw_eval.matching import match_parts, match_within_groups
from aw_eval.results import Registration, ScoreResult

__all__ = ["finalize", "finalize_costs", "rescore_thresholds"]


def finalize(geom: TaskGeometry, ck: Checkpoint, reg: Registration, mode: str) -> ScoreResult:
    """Metrics of checkpoint ``ck`` under registration ``reg``: part CDs, Hungarian within groups,
    PA/SR/SCD/SR^a."""
    moved = ck.parts @ reg.rotation.T + reg.translation
    # registered normalized y = R_reg (R_i c + t_i) / div + t_reg  <=>  c = A_i y + b_i
    a = geom.divisor * np.einsum("pji,kj->pik", ck.rotations, reg.rotation)  # div R_i^T R_reg^T
    b = -np.einsum("pji,pj->pi", ck.rotations, geom.divisor * (reg.rotation.T @ reg.translation) + ck.poses[:, :3])
    assign, errors = match_parts(geom.index(), moved, geom.groups, (a, b))
    return _result(geom, reg, assign, errors, mode)


def finalize_costs(geom: TaskGeometry, reg: Registration, part_cd: np.ndarray, mode: str) -> ScoreResult:
    """Metrics under registration ``reg`` from every pair's part CD ``part_cd (P, P)`` (registered
    pred part i, target part j; computed by the ``jax`` backend): Hungarian within groups on them."""
    cost = np.full_like(part_cd, np.inf)
    for g in geom.groups:
        cost[np.ix_(g, g)] = part_cd[np.ix_(g, g)]
    assign, errors = match_within_groups(cost, geom.groups)
    return _result(geom, reg, assign, errors, mode)


def _result(geom: TaskGeometry, reg: Registration, assign: np.ndarray, errors: np.ndarray, mode: str) -> ScoreResult:
    st = geom.settings
    ok = errors <= st.threshold
    return ScoreResult(
        pa=float(ok.mean()),
        sr=bool(ok.all()),
        scd=float(reg.scd),
        sra=bool(reg.scd < st.sra_threshold),
        part_errors=errors,
        assignment=assign,
        reg_rotation=np.asarray(reg.rotation, dtype=np.float64),
        reg_translation=np.asarray(reg.translation, dtype=np.float64),
        start_index=int(reg.start_index),
        mode=mode,
    )


def rescore_thresholds(part_errors: ArrayLike, thresholds: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """PA and SR at other thresholds with registration and matching held fixed.

    ``part_errors (..., P)``, ``thresholds (T,)`` -> ``(pa (..., T), sr (..., T))``; a part is
    correct when its error is ``<= threshold`` (inclusive, as the protocol).
    """
    e = np.asarray(part_errors, dtype=np.float64)
    thr = np.atleast_1d(np.asarray(thresholds, dtype=np.float64))
    if e.ndim < 1 or e.shape[-1] < 1:
        raise ValueError("part_errors must have shape (..., P) with P >= 1")
    if thr.ndim != 1 or not np.all(np.isfinite(thr)):
        raise ValueError("thresholds must be a 1-D array of finite numbers")
    ok = e[..., None, :] <= thr[:, None]
    return ok.mean(axis=-1), np.asarray(ok.all(axis=-1))
