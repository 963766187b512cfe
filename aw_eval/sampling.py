"""Per-part point clouds: area-weighted surface samples, then farthest-point sampling (FPS).

FPS rule (every implementation picks identical indices: :func:`fps_numpy`, :func:`fps_jax` and
the compiled :func:`aw_eval.kernels.fps_batch`, which :func:`part_clouds` runs: about 5x less CPU
than XLA's): start at index 0; each step takes the candidate with the largest squared distance
(float64, ``dx*dx + dy*dy + dz*dz``) to the chosen set, ties going to the lowest index.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import trimesh

from aw_eval.kernels.jaxcfg import jax_modules
from aw_eval.settings import ProtocolSettings

__all__ = ["part_seed", "surface_samples", "fps_numpy", "fps_jax", "part_clouds"]


def part_seed(base_seed: int, part_index: int) -> int:
    """Seed of part ``part_index`` (index among the scored parts): ``SeedSequence([base, index])``."""
    return int(np.random.SeedSequence([int(base_seed), int(part_index)]).generate_state(1, np.uint32)[0])


def surface_samples(mesh: trimesh.Trimesh, count: int, seed: int) -> np.ndarray:
    """``(count, 3)`` area-weighted surface samples of ``mesh`` (``trimesh.sample.sample_surface``)."""
    if mesh.area <= 0 or not np.isfinite(mesh.area):
        raise ValueError("mesh has no surface area to sample")
    pts, _ = trimesh.sample.sample_surface(mesh, int(count), seed=int(seed))
    return np.ascontiguousarray(pts, dtype=np.float64)


def fps_numpy(points: np.ndarray, k: int) -> np.ndarray:
    """Indices ``(k,)`` of farthest-point samples of ``points: (n, 3)`` (start 0, ties -> lowest)."""
    pts = np.asarray(points, dtype=np.float64)
    n = pts.shape[0]
    if pts.ndim != 2 or pts.shape[1] != 3 or not 1 <= k <= n:
        raise ValueError(f"need points (n, 3) and 1 <= k <= n, got {pts.shape} and k={k}")
    xs, ys, zs = (np.ascontiguousarray(pts[:, c]) for c in range(3))  # three rows: faster sweeps
    out = np.empty(k, dtype=np.int64)
    dist = np.full(n, np.inf)
    i = 0
    for s in range(k):
        out[s] = i
        dx = xs - xs[i]
        dy = ys - ys[i]
        dz = zs - zs[i]
        np.minimum(dist, dx * dx + dy * dy + dz * dz, out=dist)
        i = int(np.argmax(dist))  # first maximum = lowest index on ties
    return out


@cache
def _fps_jax_fn(k: int):
    jax, jnp = jax_modules()

    def one(pts):  # pts: (n, 3)
        xs, ys, zs = pts[:, 0], pts[:, 1], pts[:, 2]
        n = pts.shape[0]

        def body(s, state):
            out, dist, i = state
            out = out.at[s].set(i)
            dx = xs - xs[i]
            dy = ys - ys[i]
            dz = zs - zs[i]
            dist = jnp.minimum(dist, dx * dx + dy * dy + dz * dz)
            return out, dist, jnp.argmax(dist).astype(jnp.int64)

        init = (jnp.zeros(k, jnp.int64), jnp.full(n, jnp.inf), jnp.int64(0))
        return jax.lax.fori_loop(0, k, body, init)[0]

    return jax.jit(jax.vmap(one))


def fps_jax(points: np.ndarray, k: int) -> np.ndarray:
    """Batched FPS: ``points: (B, n, 3)`` -> indices ``(B, k)``; same indices as :func:`fps_numpy`.

    The batch is padded to a power of two so that a study compiles few shapes.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 3 or pts.shape[2] != 3 or not 1 <= k <= pts.shape[1]:
        raise ValueError(f"need points (B, n, 3) and 1 <= k <= n, got {pts.shape} and k={k}")
    b = pts.shape[0]
    bucket = 1 << max(0, (b - 1).bit_length())
    if bucket != b:
        pts = np.concatenate([pts, np.zeros((bucket - b,) + pts.shape[1:])])
    return np.asarray(_fps_jax_fn(int(k))(pts))[:b]


def part_clouds(meshes: list[trimesh.Trimesh], settings: ProtocolSettings, use_jax: bool = False) -> np.ndarray:
    """``(P, n_fps, 3)`` evaluation clouds of the meshes (baked frame): surface samples of part
    ``i`` with :func:`part_seed` ``(settings.seed, i)``, then FPS (the compiled CPU kernel
    :func:`aw_eval.kernels.fps_batch`, on this process's share of the cores, or :func:`fps_jax`:
    the same indices)."""
    cands = np.stack(
        [surface_samples(m, settings.n_surface, part_seed(settings.seed, i)) for i, m in enumerate(meshes)]
    )
    if use_jax:
        idx = fps_jax(cands, settings.n_fps)
    else:
        from aw.pair_search import local_workers
        from aw_eval.kernels import fps_batch

        idx = fps_batch(cands, settings.n_fps, threads=local_workers())
    return np.take_along_axis(cands, idx[..., None], axis=1)
