"""``fast`` registration: all starts on a coarse subset in JAX, the best few refined.

Contract (measured, not guaranteed; see ``docs/performance.md``): same starts and the same ICP
rule as ``exact``, but

1. **coarse**: every start runs the protocol's ICP rule (at most ``coarse_iters`` iterations,
   tolerance ``tol``) on the first ``coarse`` farthest-point samples of every part (a prefix of an FPS order is itself an FPS
   subset), all starts batched in one jitted JAX call with brute-force neighbours;
2. **medium**: the ``keep`` best *distinct* coarse results (rotations more than ``distinct_deg``
   degrees or translations more than ``distinct_t`` apart) are refined with the same ICP (at
   most ``medium_iters`` iterations) on the first ``medium`` samples per part (KD-trees);
3. **full**: the best medium result is refined at full resolution for at most ``full_iters``
   iterations (same tolerance); its best objective is the SCD.

Near-identical starts (same-ID starts of parts already placed consistently) are run once.

4. **escalation**: when a decision is close to its threshold (a part error within a factor
   ``margin`` of ``threshold``, or SCD within ``margin`` of ``sra_threshold``), the result is
   refined further at full resolution with the protocol's full iteration budget (certified
   exact neighbours) from the fast transform, and the better objective is kept. Far from the
   thresholds the small registration differences cannot flip a decision;
5. **exact fallback** (opt-in, ``exact_margin > 1``; off by default): when a decision is still
   within a factor ``exact_margin`` of its threshold, the checkpoint is registered as ``exact``
   does (every start at full resolution): such knife-edge decisions turn on the last digits of
   the registration. Measured (see ``docs/performance.md``): two of the four disagreements among
   1,008 paper-resolution checkpoints were knife edges, part errors 0.00999 (exact) vs 0.01008
   (fast) and 0.00991 vs 0.01012 under registrations whose SCD differed by 1e-4 and 2e-3
   relative; ``exact_margin=1.02`` resolves both, but where many parts sit near the threshold
   it costs a full ``exact`` registration for many checkpoints (10 parts, a batch of 100
   trajectory checkpoints: 2.4x slower; no measurable cost at 5 parts). Final states are
   scored in ``exact`` by default anyway (``aw-score --final exact``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from aw_eval.icp import ICPProblem, build_tree, graph_for
from aw_eval.jaxcfg import jax_modules
from aw_eval.results import Registration

__all__ = ["FastSettings", "register_fast", "coarse_icp"]


@dataclass(frozen=True)
class FastSettings:
    coarse: int = 8
    coarse_iters: int = 8
    medium: int = 50
    medium_iters: int = 15
    keep: int = 2
    full_iters: int = 2
    margin: float = 1.5
    exact_margin: float = 1.0  # off by default: see step 5 of the module docstring
    distinct_deg: float = 2.0
    distinct_t: float = 0.02
    same_start_tol: float = 1e-9


FAST = FastSettings()


@lru_cache(maxsize=None)
def _coarse_fn(max_iters: int):
    jax, jnp = jax_modules()
    big = jnp.iinfo(jnp.int32).max

    def nn(x, t_pts, vp, vt):
        # Per-component differences: XLA fuses these far better than a trailing size-3 reduction.
        dx = x[:, 0, None] - t_pts[None, :, 0]
        dy = x[:, 1, None] - t_pts[None, :, 1]
        dz = x[:, 2, None] - t_pts[None, :, 2]
        d = dx * dx + dy * dy + dz * dz  # (N, M)
        d = jnp.where(vt[None, :], d, jnp.inf)
        d = jnp.where(vp[:, None], d, jnp.inf)
        df = jnp.min(d, axis=1)
        db = jnp.min(d, axis=0)
        cols = jnp.arange(d.shape[1], dtype=jnp.int32)
        rows = jnp.arange(d.shape[0], dtype=jnp.int32)
        f = jnp.min(jnp.where(d == df[:, None], cols[None, :], big), axis=1)
        b = jnp.min(jnp.where(d == db[None, :], rows[:, None], big), axis=0)
        f = jnp.where(vp, f, 0)
        b = jnp.where(vt, b, 0)
        nvp, nvt = jnp.sum(vp), jnp.sum(vt)
        obj = jnp.sum(jnp.where(vp, df, 0.0)) / nvp + jnp.sum(jnp.where(vt, db, 0.0)) / nvt
        return obj, f, b

    def kabsch(p, t_pts, f, b, vp, vt):
        src = jnp.concatenate([p, p[b]])
        dst = jnp.concatenate([t_pts[f], t_pts])
        w = jnp.concatenate([vp, vt]).astype(p.dtype)
        n = jnp.sum(w)
        cs = jnp.sum(src * w[:, None], axis=0) / n
        cd = jnp.sum(dst * w[:, None], axis=0) / n
        h = ((src - cs) * w[:, None]).T @ (dst - cd)
        u, _, vt_ = jnp.linalg.svd(h)
        d = jnp.where(jnp.linalg.det(vt_.T @ u.T) >= 0, 1.0, -1.0)
        r = vt_.T @ jnp.diag(jnp.stack([jnp.ones_like(d), jnp.ones_like(d), d])) @ u.T
        return r, cd - r @ cs

    def one(p, t_pts, vp, vt, r0, t0, tol):
        obj0, f0, b0 = nn(p @ r0.T + t0, t_pts, vp, vt)

        def cond(s):
            return (s[0] < max_iters) & ~s[1]

        def body(s):
            k, done, r, t, f, b, prev, bo, br, bt = s
            r, t = kabsch(p, t_pts, f, b, vp, vt)
            new, f, b = nn(p @ r.T + t, t_pts, vp, vt)
            better = new < bo
            bo = jnp.where(better, new, bo)
            br = jnp.where(better, r, br)
            bt = jnp.where(better, t, bt)
            return (k + 1, prev - new < tol, r, t, f, b, new, bo, br, bt)

        init = (jnp.int32(0), jnp.bool_(False), r0, t0, f0, b0, obj0, obj0, r0, t0)
        out = jax.lax.while_loop(cond, body, init)
        return out[7], out[8], out[9]

    return jax.jit(jax.vmap(one, in_axes=(None, None, None, None, 0, 0, None)))


def coarse_icp(pred_parts: np.ndarray, target_parts: np.ndarray, r0: np.ndarray, t0: np.ndarray, m: int,
               max_iters: int, tol: float):
    """Protocol ICP of every start on the first ``m`` samples of every part (JAX, batched).

    ``pred_parts, target_parts (P, n, 3)``, ``r0 (S, 3, 3)``, ``t0 (S, 3)`` -> best objectives
    ``(S,)``, rotations ``(S, 3, 3)``, translations ``(S, 3)``. Parts are padded to a multiple of
    4 and starts to a multiple of 8 (padded points are masked out), so few shapes are compiled.
    """
    p, n, _ = pred_parts.shape
    m = min(m, n)
    pb = -(-p // 4) * 4  # parts to a multiple of 4, starts to a multiple of 8
    sb = -(-len(r0) // 8) * 8
    pts_p = np.zeros((pb, m, 3))
    pts_t = np.zeros((pb, m, 3))
    pts_p[:p] = pred_parts[:, :m]
    pts_t[:p] = target_parts[:, :m]
    valid = np.zeros((pb, m), dtype=bool)
    valid[:p] = True
    rr = np.concatenate([r0, np.repeat(r0[:1], sb - len(r0), axis=0)])
    tt = np.concatenate([t0, np.repeat(t0[:1], sb - len(t0), axis=0)])
    fn = _coarse_fn(int(max_iters))
    obj, r, t = fn(pts_p.reshape(-1, 3), pts_t.reshape(-1, 3), valid.reshape(-1), valid.reshape(-1), rr, tt, float(tol))
    k = len(r0)
    return np.asarray(obj)[:k], np.asarray(r)[:k], np.asarray(t)[:k]


def _dedupe_starts(r0: np.ndarray, t0: np.ndarray, tol: float) -> np.ndarray:
    """Indices of the first of every group of starts equal within ``tol`` (entrywise): a start is
    kept unless an earlier kept start is within ``tol`` of it."""
    flat = np.concatenate([r0.reshape(len(r0), -1), t0.reshape(len(t0), -1)], axis=1)
    close = np.abs(flat[:, None, :] - flat[None, :, :]).max(axis=2) <= tol  # (S, S)
    kept = np.zeros(len(r0), dtype=bool)
    for k in range(len(r0)):
        kept[k] = not np.any(close[k, :k] & kept[:k])
    return np.flatnonzero(kept).astype(np.int64)


def _distinct(order, r, t, keep: int, deg: float, dt: float) -> list[int]:
    chosen: list[int] = []
    cos_lim = np.cos(np.radians(deg))
    for k in order:
        ok = True
        for j in chosen:
            c = (np.trace(r[k].T @ r[j]) - 1.0) / 2.0
            if c > cos_lim and np.linalg.norm(t[k] - t[j]) <= dt:
                ok = False
                break
        if ok:
            chosen.append(int(k))
            if len(chosen) == keep:
                break
    return chosen


def register_fast(geom, ctx, poses: np.ndarray, pred_parts: np.ndarray, fast: FastSettings | None = None) -> Registration:
    """Coarse-to-fine registration of one checkpoint (see the module docstring; no escalation)."""
    from aw_eval.engine import starts_for

    fast = fast or FAST
    st = geom.settings
    pred = np.ascontiguousarray(pred_parts.reshape(-1, 3))
    r0, t0 = starts_for(pred, ctx.target_frame, poses, geom.target_poses, geom.divisor)
    uniq = _dedupe_starts(r0, t0, fast.same_start_tol)
    c_obj, c_r, c_t = coarse_icp(pred_parts, ctx.target_parts, r0[uniq], t0[uniq], fast.coarse,
                                 min(fast.coarse_iters, st.max_iters), st.tol)
    order = np.lexsort((uniq, c_obj))  # by objective, ties to the earlier start
    chosen = _distinct(order, c_r, c_t, fast.keep, fast.distinct_deg, fast.distinct_t)

    n = pred_parts.shape[1]
    mm = min(fast.medium, n)
    if mm < n:
        mp = np.ascontiguousarray(pred_parts[:, :mm].reshape(-1, 3))
        mt = _medium_target(geom, ctx, mm)
        prob = ICPProblem(mp, mt[0], tree_t=mt[1], graph_t=mt[2])
        med = [prob.run(c_r[k], c_t[k], min(fast.medium_iters, st.max_iters), st.tol) for k in chosen]
        objs = np.array([m.objective for m in med])
        best_k = min(range(len(chosen)), key=lambda i: (objs[i], uniq[chosen[i]]))
        r_s, t_s = med[best_k].rotation, med[best_k].translation
    else:
        best_k = 0
        r_s, t_s = c_r[chosen[0]], c_t[chosen[0]]
    full = ICPProblem(pred, ctx.target, tree_t=ctx.tree_t, graph_t=ctx.graph_t).run(r_s, t_s, min(fast.full_iters, st.max_iters), st.tol)
    return Registration(full.objective, full.rotation, full.translation, int(uniq[chosen[best_k]]), None)


def _medium_target(geom, ctx, mm: int):
    key = ("medium_target", mm)
    if key not in geom._derived:
        pts = np.ascontiguousarray(ctx.target_parts[:, :mm].reshape(-1, 3))
        tree = build_tree(pts)
        geom._derived[key] = (pts, tree, graph_for(tree))
    return geom._derived[key]


def near_threshold(result, settings, margin: float) -> bool:
    """True when a PA/SR or SR^a decision of ``result`` is within a factor ``margin`` of its threshold."""
    e = np.asarray(result.part_errors)
    thr, sra = settings.threshold, settings.sra_threshold
    near_part = np.any((e >= thr / margin) & (e <= thr * margin))
    near_scd = sra / margin <= result.scd <= sra * margin
    return bool(near_part or near_scd)


def escalate(geom, ctx, pred_parts: np.ndarray, reg: Registration) -> Registration:
    """Refine ``reg`` at full resolution with the protocol's iteration budget; keep the better."""
    st = geom.settings
    pred = np.ascontiguousarray(pred_parts.reshape(-1, 3))
    res = ICPProblem(pred, ctx.target, tree_t=ctx.tree_t, graph_t=ctx.graph_t).run(reg.rotation, reg.translation, st.max_iters, st.tol)
    if res.objective < reg.scd:
        return Registration(res.objective, res.rotation, res.translation, reg.start_index, None)
    return reg
