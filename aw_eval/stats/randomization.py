"""Two-sided paired randomization tests and Holm's correction (Appendix B.1).

For systems A and B, the statistic is the eq.-3 Overall difference ``T = sum_t w_t (a_t - b_t)``.
Under the null the two systems' labels are exchangeable *within an object* (jointly for all of the
object's tasks, i.e. both PartNet conditions), so a relabelling flips the sign of the object's
contribution ``D_o = sum_{t in o} w_t (a_t - b_t)``: ``T* = sum_o s_o D_o`` with ``s_o = +-1``.
One ``(R, O)`` sign matrix is drawn from the seed and shared by every test, and all tests are one
matrix product. p-values use the add-one correction ``(1 + #{|T*| >= |T_obs|}) / (1 + R)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aw_eval.stats.design import Design

__all__ = ["object_contributions", "randomization_pvalues", "smallest_pvalue", "holm", "PairTest", "pairwise_tests"]

DEFAULT_PERMUTATIONS = 100_000
# |T*| >= |T_obs| is decided up to rounding: sums of the same terms in another order may differ
# in the last bits, and an exact tie (e.g. a relabelling that changes nothing) must count.
_REL_TOL = 1e-9
_ABS_TOL = 1e-15
_CHUNK = 20_000


def object_contributions(design: Design, diffs: np.ndarray) -> np.ndarray:
    """``(O, K)`` per-object sums of ``weights * diffs`` for ``diffs: (K, T)`` (K tests)."""
    diffs = np.atleast_2d(np.asarray(diffs, dtype=np.float64))
    onehot = np.eye(len(design.objects))[design.task_object]  # (T, O)
    return onehot.T @ (design.weights[:, None] * diffs.T)


def randomization_pvalues(
    contrib: np.ndarray, *, n_permutations: int = DEFAULT_PERMUTATIONS, seed: int = 0
) -> np.ndarray:
    """Two-sided add-one p-values ``(K,)`` of sign-flip tests on ``contrib: (O, K)``.

    Every test uses the same sign draws. Chunked so memory stays ``O(chunk * (O + K))``.
    """
    contrib = np.asarray(contrib, dtype=np.float64)
    if contrib.ndim != 2:
        raise ValueError(f"contrib must have shape (objects, tests), got {contrib.shape}")
    if n_permutations < 1:
        raise ValueError(f"n_permutations must be >= 1, got {n_permutations}")
    n_obj, k = contrib.shape
    observed = np.abs(contrib.sum(axis=0))
    threshold = observed * (1 - _REL_TOL) - _ABS_TOL
    rng = np.random.default_rng(seed)
    hits = np.zeros(k, dtype=np.int64)
    done = 0
    while done < n_permutations:
        m = min(_CHUNK, n_permutations - done)
        signs = rng.integers(0, 2, size=(m, n_obj), dtype=np.int8).astype(np.float64) * 2.0 - 1.0
        hits += (np.abs(signs @ contrib) >= threshold).sum(axis=0)
        done += m
    return (1.0 + hits) / (1.0 + n_permutations)


def smallest_pvalue(n_objects: int, n_permutations: int | None = None) -> float:
    """The smallest two-sided p-value a sign-flip test on ``n_objects`` objects can give, whatever
    the data: at best only the observed signs and their mirror reach ``|T_obs|``, one relabelling
    in ``2 ** (n_objects - 1)`` (exactly; in expectation for drawn relabellings), and the add-one
    correction keeps ``n_permutations`` drawn relabellings at or above ``1 / (1 + n_permutations)``."""
    p = 1.0 if n_objects < 1 else 2.0 ** (1 - n_objects)
    return p if n_permutations is None else max(p, 1.0 / (1.0 + n_permutations))


def holm(pvalues) -> np.ndarray:
    """Holm step-down adjusted p-values (same order as given), capped at 1.

    ``p_(i) -> max_{j <= i} min(1, (m - j + 1) p_(j))`` over the ascending order.
    """
    p = np.asarray(pvalues, dtype=np.float64)
    if p.ndim != 1:
        raise ValueError("pvalues must be one-dimensional")
    if np.any((p < 0) | (p > 1) | ~np.isfinite(p)):
        raise ValueError("p-values must lie in [0, 1]")
    m = len(p)
    order = np.argsort(p, kind="stable")
    adjusted = np.minimum(1.0, (m - np.arange(m)) * p[order])
    adjusted = np.maximum.accumulate(adjusted)
    out = np.empty(m)
    out[order] = adjusted
    return out


@dataclass(frozen=True)
class PairTest:
    """One system pair on one metric."""

    a: int
    b: int
    metric: str
    diff: float
    ci: tuple[float, float]
    p: float
    p_holm: float


def pairwise_tests(
    design: Design,
    metrics: dict[str, np.ndarray],
    draw_w: np.ndarray,
    *,
    pairs: list[tuple[int, int]],
    n_permutations: int = DEFAULT_PERMUTATIONS,
    seed: int = 0,
    level: float = 0.95,
) -> list[PairTest]:
    """Paired differences, bootstrap intervals and Holm-corrected randomization p-values.

    ``metrics``: name -> ``(S, T)`` per-task values; ``draw_w: (B, T)`` shared bootstrap weights;
    ``pairs``: ``(a, b)`` system indices (difference a minus b). Holm runs over the whole family
    ``len(pairs) * len(metrics)``.
    """
    from aw_eval.stats.bootstrap import percentile_interval

    names = list(metrics)
    diffs = []
    for name in names:
        v = np.asarray(metrics[name], dtype=np.float64)
        diffs += [v[a] - v[b] for a, b in pairs]
    diffs_arr = np.array(diffs).reshape(len(diffs), design.n_tasks)
    contrib = object_contributions(design, diffs_arr)
    p = randomization_pvalues(contrib, n_permutations=n_permutations, seed=seed)
    p_adj = holm(p) if len(p) else p
    point = diffs_arr @ design.weights
    boot = draw_w @ diffs_arr.T  # (B, K)
    ci = percentile_interval(boot, level)
    out = []
    i = 0
    for name in names:
        for a, b in pairs:
            out.append(
                PairTest(a, b, name, float(point[i]), (float(ci[0, i]), float(ci[1, i])), float(p[i]), float(p_adj[i]))
            )
            i += 1
    return out
