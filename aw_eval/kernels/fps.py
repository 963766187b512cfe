"""Farthest-point sampling of many clouds at once, compiled (numba) for the CPU.

The rule is :func:`aw_eval.sampling.fps_numpy`'s (start at index 0; each step takes the point
with the largest squared distance ``dx*dx + dy*dy + dz*dz`` in float64 to the chosen set, ties
to the lowest index), computed in the same operations and order, so the indices are identical.
One pass over the cloud per step updates the distances and finds the next maximum together
(NumPy and XLA sweep the cloud twice and write a temporary); parts are independent and run on
``threads`` of numba's pool.

Arrays: ``points (B, n, 3)`` float64 -> indices ``(B, k)`` int64.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

__all__ = ["fps_batch"]


@njit(cache=True)
def _fps_one(xs: np.ndarray, ys: np.ndarray, zs: np.ndarray, k: int, out: np.ndarray, dist: np.ndarray) -> None:
    n = xs.shape[0]
    for j in range(n):
        dist[j] = np.inf
    i = 0
    for s in range(k):
        out[s] = i
        x0, y0, z0 = xs[i], ys[i], zs[i]
        best, arg = -1.0, 0
        for j in range(n):
            dx = xs[j] - x0
            dy = ys[j] - y0
            dz = zs[j] - z0
            d = dx * dx + dy * dy + dz * dz
            if d < dist[j]:
                dist[j] = d
            if dist[j] > best:  # strictly greater: the first maximum wins ties
                best, arg = dist[j], j
        i = arg


@njit(cache=True, parallel=True)
def _fps_many(cols: np.ndarray, k: int, out: np.ndarray) -> None:
    for b in prange(cols.shape[0]):
        _fps_one(cols[b, 0], cols[b, 1], cols[b, 2], k, out[b], np.empty(cols.shape[2]))


def fps_batch(points: np.ndarray, k: int, threads: int = 1) -> np.ndarray:
    """Indices ``(B, k)`` of farthest-point samples of each cloud of ``points (B, n, 3)``, on up
    to ``threads`` of numba's threads (the caller decides: inside a pool of worker processes, 1)."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 3 or pts.shape[2] != 3 or not 1 <= k <= pts.shape[1]:
        raise ValueError(f"need points (B, n, 3) and 1 <= k <= n, got {pts.shape} and k={k}")
    cols = np.ascontiguousarray(np.swapaxes(pts, 1, 2))  # (B, 3, n): three rows per cloud
    out = np.empty((pts.shape[0], k), np.int64)
    before = numba.get_num_threads()
    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))  # type: ignore[attr-defined]  # numba.config sets its options at import
    try:
        _fps_many(cols, int(k), out)
    finally:
        numba.set_num_threads(before)
    return out
