"""Weighted means and medians with explicit handling of empty inputs."""

from __future__ import annotations

import numpy as np

__all__ = ["weighted_median", "weighted_mean"]


def weighted_median(values, weights) -> float:
    """Median of ``values: (n,)`` under ``weights: (n,)`` (non-negative; NaN values dropped).

    The smallest value whose cumulative weight reaches half the total; when the cumulative weight
    hits exactly half, the mean of that value and the next (so equal weights give ``np.median``).
    Returns NaN when nothing is left.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    w = np.asarray(weights, dtype=np.float64).ravel()
    if v.shape != w.shape:
        raise ValueError(f"values and weights differ in shape: {v.shape} vs {w.shape}")
    if np.any(w < 0) or not np.all(np.isfinite(w)):
        raise ValueError("weights must be finite and non-negative")
    keep = ~np.isnan(v) & (w > 0)
    v, w = v[keep], w[keep]
    if len(v) == 0:
        return float("nan")
    order = np.argsort(v, kind="stable")
    v, w = v[order], w[order]
    cum = np.cumsum(w)
    half = cum[-1] / 2.0
    i = int(np.searchsorted(cum, half - 1e-12 * cum[-1], side="left"))
    if abs(cum[i] - half) <= 1e-12 * cum[-1] and i + 1 < len(v):
        return float((v[i] + v[i + 1]) / 2.0)
    return float(v[i])


def weighted_mean(values, weights) -> float:
    """Mean of ``values`` under ``weights``, ignoring NaN values (weights renormalized); NaN if empty."""
    v = np.asarray(values, dtype=np.float64).ravel()
    w = np.asarray(weights, dtype=np.float64).ravel()
    keep = ~np.isnan(v) & (w > 0)
    if not keep.any():
        return float("nan")
    return float(np.sum(v[keep] * w[keep]) / np.sum(w[keep]))
