"""Proven lower bounds on the Chamfer distance of two point clouds after any rigid motion.

Both equivalence rules (the native protocol's :func:`aw_eval.equivalence.equivalence_groups` and
the official preparation's :func:`aw.prepare.official_similarity.geometry_groups`) join two parts
when an ICP registration of one cloud onto the other reaches a squared Chamfer distance at or
below a threshold. The value they compare is the smallest objective any ICP state visited, and
every state is a rigid motion ``(R, t)``, so a number below ``CD(R X + t, Y)`` for *every* rigid
motion is below that value too: a pair whose bound exceeds the threshold cannot be an edge, and
is not registered. The bounds use only quantities that rigid motions do not change, so they are
computed once per cloud, and for all pairs at once.

The distance (both rules, in the clouds' normalized units, i.e. after the division by the scale
divisor, which the caller has applied to the clouds given here)::

    CD(X', Y) = F + B,   F = mean_i d(x'_i, Y)^2,   B = mean_k d(y_k, X')^2,   X' = R X + t

with ``d`` the Euclidean distance to the nearest point. ``B`` is the forward term of ``Y`` moved
by the inverse motion onto ``X``, so a bound on the forward term of the ordered pair ``(X, Y)``
plus one of ``(Y, X)`` bounds ``CD``. Two forward bounds, the larger of which is used:

1. **Thin subspaces (Ky Fan).** Let ``U`` be the span of ``Y``'s ``k`` thinnest principal axes and
   ``c`` a point with every ``|P_U(y - c)| <= rho_k`` (``rho_k``: :attr:`CloudBounds.reach`).
   For ``x'_i`` with nearest ``y``: ``|P_U(x'_i - c)| <= |P_U(y - c)| + |x'_i - y| <= rho_k + d_i``.
   By Minkowski, ``sqrt(F) >= rms_i |P_U(x'_i - c)| - rho_k``, and ``P_U(x'_i - c) = P_V(x_i -
   mu_X) + w`` for the ``k``-dimensional ``V = R^T U`` and a constant ``w``, whose mean square is at
   least ``trace(P_V C_X P_V) >= `` the sum of the ``k`` smallest eigenvalues of ``X``'s covariance
   ``C_X`` (Ky Fan). So ``F >= max_k (spread_X[k] - rho_Y[k])_+^2``.
2. **Antipodal pairs.** Pair the points of ``X`` two by two (a fixed matching ``M``; here the
   ``j``-th lowest with the ``j``-th highest along a principal axis, one matching per axis). For a
   pair ``(a, b)`` with nearest points ``y_a, y_b``: ``|x_a - x_b| = |x'_a - x'_b| <= d_a + |y_a -
   y_b| + d_b <= d_a + d_b + D_Y``, ``D_Y = 2 rho_Y[3]`` at least ``Y``'s diameter. With
   ``d_a^2 + d_b^2 >= (d_a + d_b)^2 / 2`` and the pairs disjoint,
   ``F >= (1 / 2n) sum_{(a, b) in M} (|x_a - x_b| - D_Y)_+^2``. Unlike 1 (a mean square against a
   maximum) this keeps the whole distribution of pair lengths: a longer part cannot hide its ends.

The bound is not tight (it cannot tell two samplings of the same surface apart, for example),
only safe: the callers register every pair it does not rule out, so their groups are exactly
those of registering every pair. Arrays: clouds ``(P, n, 3)`` in any frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CloudBounds", "cloud_bounds", "lower_bounds", "SAFETY"]

# Relative and absolute slack on a comparison with a threshold, far above the rounding of the
# sums here (~1e-14) and of an ICP state's rotation (orthonormal to ~1e-15, so its distances are
# the rigid ones to that precision): rounding can never rule out a true edge.
SAFETY = (1e-9, 1e-12)


@dataclass(frozen=True)
class CloudBounds:
    """Rigid-invariant summaries of ``P`` clouds of ``n`` points each.

    - ``spread (P, 3)``: ``spread[:, k-1]`` = sqrt of the sum of the ``k`` smallest covariance
      eigenvalues (mean over points);
    - ``reach (P, 3)``: ``reach[:, k-1]`` = largest distance of a point from the centre of the
      bounding box of the cloud projected on its ``k`` thinnest principal axes;
    - ``pair_lengths (P, 3, n // 2)``: sorted lengths of the antipodal pairs of the matching along
      each principal axis; ``tail1, tail2 (P, 3, n // 2 + 1)``: their suffix sums and suffix sums
      of squares (``tail[..., j]`` = sum from ``j`` on);
    - ``n_points (P,)``.
    """

    spread: np.ndarray
    reach: np.ndarray
    pair_lengths: np.ndarray
    tail1: np.ndarray
    tail2: np.ndarray
    n_points: np.ndarray

    @property
    def diameter(self) -> np.ndarray:
        """``(P,)`` an upper bound on each cloud's diameter (twice the largest reach)."""
        return 2.0 * self.reach[:, 2]


def _one(cloud: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    c = cloud - cloud.mean(axis=0)
    ev, axes = np.linalg.eigh(c.T @ c / len(c))  # ascending: column 0 is the thinnest axis
    z = c @ axes
    spread = np.sqrt(np.maximum(np.cumsum(ev), 0.0))
    reach = np.empty(3)
    for k in (1, 2, 3):
        sub = z[:, :k]
        centre = 0.5 * (sub.max(axis=0) + sub.min(axis=0))
        reach[k - 1] = float(np.sqrt(np.max(np.sum((sub - centre) ** 2, axis=1))))
    half = len(c) // 2
    lengths = np.empty((3, half))
    for a in range(3):
        order = np.argsort(z[:, a], kind="stable")
        lengths[a] = np.sort(np.linalg.norm(c[order[:half]] - c[order[::-1][:half]], axis=1))
    return spread, reach, lengths


def cloud_bounds(clouds: np.ndarray) -> CloudBounds:
    """The summaries of ``clouds (P, n, 3)`` (see :class:`CloudBounds`)."""
    clouds = np.asarray(clouds, dtype=np.float64)
    if clouds.ndim != 3 or clouds.shape[2] != 3 or clouds.shape[1] < 2:
        raise ValueError(f"clouds must have shape (P, n >= 2, 3), got {clouds.shape}")
    parts = [_one(c) for c in clouds]
    spread = np.stack([p[0] for p in parts]) if parts else np.zeros((0, 3))
    reach = np.stack([p[1] for p in parts]) if parts else np.zeros((0, 3))
    lengths = np.stack([p[2] for p in parts]) if parts else np.zeros((0, 3, clouds.shape[1] // 2))
    zero = np.zeros(lengths.shape[:2] + (1,))
    tail1 = np.concatenate([np.cumsum(lengths[..., ::-1], axis=-1)[..., ::-1], zero], axis=-1)
    tail2 = np.concatenate([np.cumsum((lengths**2)[..., ::-1], axis=-1)[..., ::-1], zero], axis=-1)
    return CloudBounds(spread, reach, lengths, tail1, tail2, np.full(len(clouds), clouds.shape[1]))


def _forward(b: CloudBounds) -> np.ndarray:
    """``(P, P)``: entry ``[i, j]`` bounds the forward term of cloud ``i`` moved onto cloud ``j``."""
    kyfan = np.max(np.maximum(b.spread[:, None, :] - b.reach[None, :, :], 0.0) ** 2, axis=2)
    diam = b.diameter
    pairs = np.zeros_like(kyfan)
    for i in range(len(diam)):
        for a in range(3):
            start = np.searchsorted(b.pair_lengths[i, a], diam, side="right")  # first length > D_j
            s1 = b.tail1[i, a, start]
            s2 = b.tail2[i, a, start]
            count = b.pair_lengths.shape[2] - start
            # sum over lengths l > D of (l - D)^2
            total = np.maximum(s2 - 2.0 * diam * s1 + diam**2 * count, 0.0)
            pairs[i] = np.maximum(pairs[i], total / (2.0 * b.n_points[i]))
    return np.maximum(kyfan, pairs)


def lower_bounds(b: CloudBounds) -> np.ndarray:
    """``(P, P)`` symmetric: ``[i, j] <= CD(R X_i + t, X_j)`` for every rigid motion ``(R, t)``."""
    fwd = _forward(b)
    return fwd + fwd.T
