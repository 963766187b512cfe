"""The protocol's ICP and part Chamfer distances in JAX, batched over checkpoints x starts.

The XLA counterpart of :class:`aw_eval.kernels.ICPProblem`: the same rule from every start (both
directions' nearest neighbours, one proper Kabsch fit of all pairs, at most ``max_iters`` fits,
stop when the objective improves by less than ``tol``, keep the best state visited), for many
checkpoints of one task at once. Nearest neighbours are brute force: each query tile's squared
distances to every reference point, then the first minimum; every distance is recomputed from
coordinates as the reference does. Everything is float64: the neighbour decisions and the
``tol = 1e-9`` improvements need it (float32 would move nearest neighbours at near ties and
lose the convergence test). One compiled program per ``(checkpoints, starts, points)`` shape.

Lanes (one checkpoint's one start) run in lock step; a lane that has stopped keeps its state
while the others iterate (the loop ends when every lane has stopped or after ``max_iters``).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from aw_eval.kernels.jaxcfg import jax_modules

__all__ = ["accelerator_present", "icp_batch", "part_cd_batch", "fit_tile", "DEFAULT_TILE"]

# Query rows per brute-force tile (at most): a tile holds tile x m squared distances per lane,
# and the tile shrinks so that all lanes' tiles together stay near TILE_ELEMENTS.
DEFAULT_TILE = 256
TILE_ELEMENTS = 1 << 26  # 512 MiB of float64 distances


def fit_tile(lanes: int, m: int, tile: int = DEFAULT_TILE) -> int:
    """The largest power of two <= ``tile`` (at least 8) with ``lanes * tile * m <= TILE_ELEMENTS``."""
    while tile > 8 and lanes * tile * m > TILE_ELEMENTS:
        tile //= 2
    return tile


@lru_cache(maxsize=1)
def accelerator_present() -> bool:
    """True when JAX sees a GPU or TPU (the ``auto`` backend then picks JAX); asked once per process."""
    try:
        jax, _ = jax_modules()
        return any(d.platform != "cpu" for d in jax.devices())
    except Exception:  # no JAX plugin for a device, or JAX_PLATFORMS=cpu: not present
        return False


def _nearest(jnp, lax, query, ref, tile: int):
    """Index ``(n,)`` and squared distance ``(n,)`` of the nearest row of ``ref (m, 3)`` to every
    row of ``query (n, 3)``, brute force in tiles of ``tile`` query rows (first minimum on ties)."""
    n = query.shape[0]
    pad = (-n) % tile
    q = jnp.concatenate([query, jnp.zeros((pad, 3), query.dtype)]) if pad else query

    def one_tile(qt):  # (tile, 3) -> (tile,)
        d = ((qt[:, None, 0] - ref[None, :, 0]) ** 2 + (qt[:, None, 1] - ref[None, :, 1]) ** 2
             + (qt[:, None, 2] - ref[None, :, 2]) ** 2)
        return jnp.argmin(d, axis=1)

    idx = lax.map(one_tile, q.reshape(-1, tile, 3)).reshape(-1)[:n]
    return idx, jnp.sum((query - ref[idx]) ** 2, axis=1)


def _kabsch(jnp, src, dst):
    """Proper rigid ``(R (3, 3), t (3,))`` of paired rows ``src, dst (k, 3)`` (equal weights)."""
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    h = (src - cs).T @ (dst - cd)
    u, _, vt = jnp.linalg.svd(h)
    d = jnp.where(jnp.linalg.det(vt.T @ u.T) >= 0, 1.0, -1.0)
    r = vt.T @ jnp.diag(jnp.stack([1.0, 1.0, d])) @ u.T
    return r, cd - r @ cs


@lru_cache(maxsize=None)
def _compiled_icp(max_iters: int, tol: float, tile: int):
    jax, jnp = jax_modules()
    lax = jax.lax

    def objective(p, tgt, r, t):
        x = p @ r.T + t
        fwd, dfwd = _nearest(jnp, lax, x, tgt, tile)
        bwd, dbwd = _nearest(jnp, lax, tgt, x, tile)
        return dfwd.mean() + dbwd.mean(), fwd, bwd

    def lane_step(p, tgt, fwd, bwd):
        r, t = _kabsch(jnp, jnp.concatenate([p, p[bwd]]), jnp.concatenate([tgt[fwd], tgt]))
        new, fwd, bwd = objective(p, tgt, r, t)
        return r, t, new, fwd, bwd

    # lanes: (C, S); p is per checkpoint, the target shared
    starts_objective = jax.vmap(jax.vmap(objective, (None, None, 0, 0)), (0, None, 0, 0))
    step = jax.vmap(jax.vmap(lane_step, (None, None, 0, 0)), (0, None, 0, 0))

    def run(preds, target, r0, t0):
        obj, fwd, bwd = starts_objective(preds, target, r0, t0)
        carry = (jnp.asarray(0), jnp.ones(obj.shape, bool), obj, fwd, bwd, obj, r0, t0)

        def cond(c):
            return (c[0] < max_iters) & c[1].any()

        def body(c):
            it, active, prev, fwd, bwd, best, br, bt = c
            r, t, new, nfwd, nbwd = step(preds, target, fwd, bwd)
            better = active & (new < best)
            best = jnp.where(better, new, best)
            br = jnp.where(better[..., None, None], r, br)
            bt = jnp.where(better[..., None], t, bt)
            keep = active[..., None]
            fwd, bwd = jnp.where(keep, nfwd, fwd), jnp.where(keep, nbwd, bwd)
            still = active & ~(prev - new < tol)
            prev = jnp.where(active, new, prev)
            return it + 1, still, prev, fwd, bwd, best, br, bt

        out = lax.while_loop(cond, body, carry)
        return out[5], out[6], out[7]

    return jax.jit(run)


def icp_batch(preds: np.ndarray, target: np.ndarray, r0: np.ndarray, t0: np.ndarray, max_iters: int, tol: float,
              tile: int = DEFAULT_TILE) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The protocol's ICP of every checkpoint from every start.

    ``preds (C, n, 3)`` normalized predictions of one task, ``target (m, 3)``, starts
    ``r0 (C, S, 3, 3)``, ``t0 (C, S, 3)``. Returns each lane's best state: ``objective (C, S)``,
    ``rotation (C, S, 3, 3)``, ``translation (C, S, 3)`` (NumPy float64).
    """
    _, jnp = jax_modules()
    run = _compiled_icp(int(max_iters), float(tol), fit_tile(r0.shape[0] * r0.shape[1], len(target), tile))
    obj, r, t = run(*(jnp.asarray(a, dtype=jnp.float64) for a in (preds, target, r0, t0)))
    return np.asarray(obj), np.asarray(r), np.asarray(t)


@lru_cache(maxsize=None)
def _compiled_part_cd(tile: int):
    jax, jnp = jax_modules()
    lax = jax.lax

    def pair(x, y):  # (n, 3), (n, 3) -> CD
        return _nearest(jnp, lax, x, y, tile)[1].mean() + _nearest(jnp, lax, y, x, tile)[1].mean()

    every_pair = jax.vmap(jax.vmap(pair, (None, 0)), (0, None))  # (P, n, 3), (P, n, 3) -> (P, P)
    return jax.jit(jax.vmap(every_pair, (0, None)))


def part_cd_batch(moved_parts: np.ndarray, target_parts: np.ndarray, tile: int = DEFAULT_TILE) -> np.ndarray:
    """``C (C, P, P)``: ``C[c, i, j]`` = CD(registered pred part ``i`` of checkpoint ``c``, target
    part ``j``) for ``moved_parts (C, P, n, 3)`` and ``target_parts (P, n, 3)``."""
    _, jnp = jax_modules()
    c, p, n = moved_parts.shape[:3]
    out = _compiled_part_cd(fit_tile(c * p * p, n, tile))(jnp.asarray(moved_parts, dtype=jnp.float64),
                                       jnp.asarray(target_parts, dtype=jnp.float64))
    return np.asarray(out)
