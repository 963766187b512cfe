"""``fast`` registration: all starts on a coarse subset, the best few refined.

Contract (measured, not guaranteed; see ``docs/performance.md``): same starts and the same ICP
rule as ``exact``, but

1. **coarse**: every start runs the protocol's ICP rule (at most ``coarse_iters`` iterations,
   tolerance ``tol``) on the first ``coarse`` farthest-point samples of every part (a prefix of an FPS order is itself an FPS
   subset), with brute-force neighbours in one compiled call (:func:`coarse_icp`);
2. **medium**: the ``keep`` best *distinct* coarse results (rotations more than ``distinct_deg``
   degrees or translations more than ``distinct_t`` apart) are refined with the same ICP (at
   most ``medium_iters`` iterations) on the first ``medium`` samples per part (KD-trees);
3. **full**: the best medium result is refined at full resolution for at most ``full_iters``
   iterations (same tolerance); its best objective is the SCD.

Near-identical starts (same-ID starts of parts already placed consistently) are run once.
Steps 1-3 are :func:`coarse_to_fine`; the protocol side (:mod:`aw_eval.registration` and
:mod:`aw_eval.scoring`) applies steps 4 and 5 with the settings of :data:`FAST`.

4. **escalation**: when a decision is close to its threshold (a part error within a factor
   ``margin`` of ``threshold``, or SCD within ``margin`` of ``sra_threshold``), the result is
   refined further at full resolution with the protocol's full iteration budget (certified
   exact neighbours) from the fast transform, and the better objective is kept. Far from the
   thresholds the small registration differences cannot flip a decision. Along a trajectory
   (:func:`aw_eval.score_batch`) the refinement starts from the previous checkpoint's
   refined transform instead when both lie in the same basin (:func:`same_basin`);
5. **exact fallback** (opt-in, ``exact_margin > 1``; off by default): when a decision is still
   within a factor ``exact_margin`` of its threshold, the checkpoint is registered as ``exact``
   does (every start at full resolution): such knife-edge decisions turn on the last digits of
   the registration. Measured (see ``docs/performance.md``): with an 8-point coarse stage, two
   of the four disagreements among 1,008 paper-resolution checkpoints were knife edges, part
   errors 0.00999 (exact) vs 0.01008 (fast) and 0.00991 vs 0.01012 under registrations whose
   SCD differed by 1e-4 and 2e-3 relative; ``exact_margin=1.02`` resolves such cases, but where
   many parts sit near the threshold it costs a full ``exact`` registration for many
   checkpoints (10 parts, a batch of 100 trajectory checkpoints: several times slower). Final
   states are scored in ``exact`` by default anyway (``aw-score --final exact``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from aw.kernels.icp import ICPProblem, ICPResult, kabsch_pairs
from aw_eval.kernels.index import TaskIndex

__all__ = ["FastSettings", "FAST", "fast_settings", "coarse_to_fine", "coarse_icp", "same_basin"]


@dataclass(frozen=True)
class FastSettings:
    coarse: int = 16
    coarse_iters: int = 15
    medium: int = 50
    medium_iters: int = 15
    keep: int = 2
    full_iters: int = 2
    margin: float = 1.5
    exact_margin: float = 1.0  # off by default: see step 5 of the module docstring
    distinct_deg: float = 2.0
    distinct_t: float = 0.02
    warm_deg: float = 5.0  # escalation starts from the previous checkpoint's refined transform
    warm_t: float = 0.05  # when it is within these of this checkpoint's fast transform
    same_start_tol: float = 1e-9


FAST = FastSettings()


def fast_settings() -> FastSettings:
    """The settings ``fast`` mode runs with (:data:`FAST`, read at call time)."""
    return FAST


@njit(cache=True)
def _brute_evaluate(p, t, r, tr, xs, fc, bc, bd) -> float:
    """Objective at ``(r, tr)`` with brute-force neighbours of both directions (``fc (n,)``,
    ``bc (m,)``; ties to the lowest index, as a KD-tree-free reading of the protocol gives).
    ``p (n, 3)``, ``t (m, 3)``; ``xs (n, 3)`` and ``bd (m,)`` are scratch space."""
    n, m = p.shape[0], t.shape[0]
    for i in range(n):
        for k in range(3):
            xs[i, k] = r[k, 0] * p[i, 0] + r[k, 1] * p[i, 1] + r[k, 2] * p[i, 2] + tr[k]
    for j in range(m):
        bd[j] = np.inf
    sf = 0.0
    for i in range(n):
        x0, x1, x2 = xs[i, 0], xs[i, 1], xs[i, 2]
        best = np.inf
        bj = 0
        for j in range(m):
            a, b, c = x0 - t[j, 0], x1 - t[j, 1], x2 - t[j, 2]
            d = a * a + b * b + c * c
            if d < best:
                best = d
                bj = j
            if d < bd[j]:
                bd[j] = d
                bc[j] = i
        fc[i] = bj
        sf += best
    sb = 0.0
    for j in range(m):
        sb += bd[j]
    return sf / n + sb / m


@njit(cache=True)
def _coarse_starts(p, t, r0, t0, max_iters, tol):
    """The protocol's ICP rule from every start ``r0 (S, 3, 3)``, ``t0 (S, 3)`` on ``p (n, 3)``,
    ``t (m, 3)`` with brute-force neighbours: best objectives ``(S,)`` and their transforms."""
    n_starts, n, m = r0.shape[0], p.shape[0], t.shape[0]
    xs = np.empty((n, 3))
    fc = np.zeros(n, np.int64)
    bc = np.zeros(m, np.int64)
    bd = np.empty(m)
    objs = np.empty(n_starts)
    rs = np.empty((n_starts, 3, 3))
    ts = np.empty((n_starts, 3))
    for s in range(n_starts):
        r, tr = r0[s].copy(), t0[s].copy()
        prev = _brute_evaluate(p, t, r, tr, xs, fc, bc, bd)
        best, best_r, best_t = prev, r, tr
        for _ in range(max_iters):
            r, tr = kabsch_pairs(p, t, fc, bc)
            new = _brute_evaluate(p, t, r, tr, xs, fc, bc, bd)
            if new < best:
                best, best_r, best_t = new, r, tr
            if prev - new < tol:
                break
            prev = new
        objs[s] = best
        rs[s] = best_r
        ts[s] = best_t
    return objs, rs, ts


def coarse_icp(
    pred_parts: np.ndarray, target_parts: np.ndarray, r0: np.ndarray, t0: np.ndarray, m: int, max_iters: int, tol: float
):
    """Protocol ICP of every start on the first ``m`` samples of every part (compiled, brute-force
    neighbours: at ``8 P`` points a side that beats any tree).

    ``pred_parts, target_parts (P, n, 3)``, ``r0 (S, 3, 3)``, ``t0 (S, 3)`` -> best objectives
    ``(S,)``, rotations ``(S, 3, 3)``, translations ``(S, 3)``.
    """
    m = min(m, pred_parts.shape[1])
    p = np.ascontiguousarray(pred_parts[:, :m].reshape(-1, 3), dtype=np.float64)
    t = np.ascontiguousarray(target_parts[:, :m].reshape(-1, 3), dtype=np.float64)
    r0 = np.ascontiguousarray(r0, dtype=np.float64)
    t0 = np.ascontiguousarray(t0, dtype=np.float64)
    return _coarse_starts(p, t, r0, t0, int(max_iters), float(tol))


def _dedupe_starts(r0: np.ndarray, t0: np.ndarray, tol: float) -> np.ndarray:
    """Indices of the first of every group of starts equal within ``tol`` (entrywise): a start is
    kept unless an earlier kept start is within ``tol`` of it."""
    flat = np.concatenate([r0.reshape(len(r0), -1), t0.reshape(len(t0), -1)], axis=1)
    close = (np.abs(flat[:, None, :] - flat[None, :, :]).max(axis=2) <= tol).tolist()  # (S, S)
    kept: list[int] = []
    for k in range(len(r0)):  # a few dozen starts: plain Python beats small NumPy calls here
        if not any(close[k][j] for j in kept):
            kept.append(k)
    return np.asarray(kept, dtype=np.int64)


def _within(ra: np.ndarray, ta: np.ndarray, rb: np.ndarray, tb: np.ndarray, cos_lim: float, max_t: float) -> bool:
    """Rotations ``(3, 3)`` closer than the angle whose cosine is ``cos_lim`` and translations
    ``(3,)`` within ``max_t`` of each other."""
    c = (np.trace(ra.T @ rb) - 1.0) / 2.0
    return bool(c > cos_lim and np.linalg.norm(ta - tb) <= max_t)


def _distinct(order, r, t, keep: int, deg: float, dt: float) -> list[int]:
    chosen: list[int] = []
    cos_lim = np.cos(np.radians(deg))
    for k in order:
        if not any(_within(r[k], t[k], r[j], t[j], cos_lim, dt) for j in chosen):
            chosen.append(int(k))
            if len(chosen) == keep:
                break
    return chosen


def coarse_to_fine(
    index: TaskIndex,
    pred_parts: np.ndarray,
    full: ICPProblem,
    r0: np.ndarray,
    t0: np.ndarray,
    max_iters: int,
    tol: float,
    fast: FastSettings | None = None,
) -> tuple[ICPResult, int]:
    """Coarse-to-fine ICP of one checkpoint from the starts ``r0 (S, 3, 3)``, ``t0 (S, 3)`` (steps
    1-3 of the module docstring; no escalation): ``pred_parts (P, n, 3)`` normalized, ``full``
    its full-resolution problem, ``max_iters``/``tol`` the protocol's ICP budget and tolerance.
    Returns the full-resolution result and the index of the start it came from."""
    fast = fast or FAST
    uniq = _dedupe_starts(r0, t0, fast.same_start_tol)
    c_obj, c_r, c_t = coarse_icp(
        pred_parts, index.target_parts, r0[uniq], t0[uniq], fast.coarse, min(fast.coarse_iters, max_iters), tol
    )
    order = np.lexsort((uniq, c_obj))  # by objective, ties to the earlier start
    chosen = _distinct(order, c_r, c_t, fast.keep, fast.distinct_deg, fast.distinct_t)

    n = pred_parts.shape[1]
    mm = min(fast.medium, n)
    if mm < n:
        prob = index.medium_problem(pred_parts, mm)
        med = [prob.run(c_r[k], c_t[k], min(fast.medium_iters, max_iters), tol) for k in chosen]
        objs = np.array([m.objective for m in med])
        best_k = min(range(len(chosen)), key=lambda i: (objs[i], uniq[chosen[i]]))
        r_s, t_s = med[best_k].rotation, med[best_k].translation
    else:
        best_k = 0
        r_s, t_s = c_r[chosen[0]], c_t[chosen[0]]
    return full.run(r_s, t_s, min(fast.full_iters, max_iters), tol), int(uniq[chosen[best_k]])


def same_basin(ra: np.ndarray, ta: np.ndarray, rb: np.ndarray, tb: np.ndarray, max_deg: float, max_t: float) -> bool:
    """True when two transforms' rotations ``(3, 3)`` are within ``max_deg`` degrees and their
    translations ``(3,)`` within ``max_t`` (normalized units) of each other."""
    return _within(ra, ta, rb, tb, np.cos(np.radians(max_deg)), max_t)
