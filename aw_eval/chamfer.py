"""Batched squared bidirectional Chamfer distance (eq. 1) in JAX, float64, brute force.

Distances are direct squared differences ``dx*dx + dy*dy + dz*dz`` (no ``|x|^2 - 2 x.y + |y|^2``
expansion, whose cancellation would ruin CDs near zero), so a nearest distance equals the
reference's recomputed one. Batches are split into chunks of at most :data:`CHUNK` pairs and
padded to a power of two, so memory stays bounded and few shapes are compiled.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache
from typing import Any

import numpy as np

from aw_eval.kernels.jaxcfg import jax_modules

__all__ = ["chamfer", "chamfer_pairs", "CHUNK"]

# At most this many (n x m) distance blocks are live at once (8 x 1000 x 1000 doubles = 64 MB).
CHUNK = 8


@cache
def _pairs_fn() -> Callable[[np.ndarray, np.ndarray], Any]:
    """The jitted CDs ``(G,)`` of ``x (G, n, 3)`` and ``y (G, m, 3)`` (a JAX array)."""
    jax, jnp = jax_modules()

    def one(x: Any, y: Any) -> Any:  # jax arrays x: (n, 3), y: (m, 3)
        dx = x[:, 0, None] - y[None, :, 0]
        dy = x[:, 1, None] - y[None, :, 1]
        dz = x[:, 2, None] - y[None, :, 2]
        d = dx * dx + dy * dy + dz * dz
        return jnp.mean(jnp.min(d, axis=1)) + jnp.mean(jnp.min(d, axis=0))

    pairs: Callable[[np.ndarray, np.ndarray], Any] = jax.jit(jax.vmap(one))
    return pairs


def chamfer_pairs(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """CDs ``(G,)`` of ``x (G, n, 3)`` and ``y (G, m, 3)`` pair by pair."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.ndim != 3 or y.ndim != 3 or x.shape[0] != y.shape[0] or x.shape[2] != 3 or y.shape[2] != 3:
        raise ValueError(f"need x (G, n, 3) and y (G, m, 3), got {x.shape} and {y.shape}")
    g = x.shape[0]
    out = np.empty(g)
    fn = _pairs_fn()
    for lo in range(0, g, CHUNK):
        xs, ys = x[lo : lo + CHUNK], y[lo : lo + CHUNK]
        k = xs.shape[0]
        b = 1 << max(0, (k - 1).bit_length())
        if b != k:  # pad with copies of the first pair; their results are dropped
            xs = np.concatenate([xs, np.repeat(xs[:1], b - k, axis=0)])
            ys = np.concatenate([ys, np.repeat(ys[:1], b - k, axis=0)])
        out[lo : lo + k] = np.asarray(fn(xs, ys))[:k]
    return out


def chamfer(x: np.ndarray, y: np.ndarray) -> np.ndarray | float:
    """Squared bidirectional Chamfer distance of ``x (..., n, 3)`` and ``y (..., m, 3)``.

    Leading dimensions broadcast; returns a float for single clouds, else an array ``(...)``.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.ndim < 2 or y.ndim < 2 or x.shape[-1] != 3 or y.shape[-1] != 3:
        raise ValueError(f"need point arrays (..., n, 3), got {x.shape} and {y.shape}")
    if x.shape[-2] < 1 or y.shape[-2] < 1:
        raise ValueError("Chamfer distance needs non-empty point sets")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError("points contain non-finite values")
    lead = np.broadcast_shapes(x.shape[:-2], y.shape[:-2])
    xb = np.broadcast_to(x, lead + x.shape[-2:]).reshape((-1,) + x.shape[-2:])
    yb = np.broadcast_to(y, lead + y.shape[-2:]).reshape((-1,) + y.shape[-2:])
    res = chamfer_pairs(xb, yb).reshape(lead)
    return float(res) if res.ndim == 0 else res
