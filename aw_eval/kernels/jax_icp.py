"""The protocol's ICP and part Chamfer distances in JAX, batched over checkpoints x starts.

The XLA counterpart of :class:`aw_eval.kernels.ICPProblem`: the same rule from every start (both
directions' nearest neighbours, one proper Kabsch fit of all pairs, at most ``max_iters`` fits,
stop when the objective improves by less than ``tol``, keep the best state visited), for many
checkpoints of one task at once.

Nearest neighbours, in fixed shapes: every query reads the candidate list of its grid cell
(:mod:`aw_eval.kernels.cellgrid`; built once per task on the host), computes its squared
distances from coordinates as the protocol does and takes the first minimum. Forward, one grid
of the joined target; backward, one grid per part of the parts' baked clouds (a checkpoint
moves each rigidly: the target points are mapped into each part's frame, the parts' answers
combined by first minimum, and a part whose grid does not answer is skipped only when its box
is farther than the best found). Every query the grids cannot answer exactly (outside a grid, an
overflowing cell, an unskippable part) takes the brute-force path, all lanes' such queries
compacted into tiles of FALLBACK_ROWS. So every neighbour is the brute-force first minimum, and
every decision the numba backend's up to the rounding of near (not exact) ties.

Lanes (one checkpoint's one start) stop at different iterations: the loop runs ROUND_ITERS
iterations per round, then drops the lanes that stopped and packs the rest into the smallest
power-of-two bucket (a few compiled shapes). Everything is float64: the neighbour decisions and
the ``tol = 1e-9`` improvements need it.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from aw_eval.kernels.cellgrid import JOINED_K, JOINED_MARGIN_CELLS, PartGrids, build_part_grids
from aw_eval.kernels.jaxcfg import jax_modules

__all__ = ["accelerator_present", "icp_batch", "nearest_in_grids", "part_cd_batch", "fit_tile", "DEFAULT_TILE"]

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


# Slack of the lower-bound test that skips a part whose grid does not answer a query: the part
# is searched (brute force) unless its box is farther than the best candidate by more than this
# relative margin (and an absolute one far above the rounding of O(1) squared distances).
_LB_REL, _LB_ABS = 1e-9, 1e-15
# Flagged queries brute-forced per step of the fallback loop (all lanes together).
FALLBACK_ROWS = 256
# ICP iterations per round; between rounds the lanes that have stopped are dropped and the
# remaining ones packed into the smallest bucket (a power of two, at least MIN_LANES).
ROUND_ITERS = 8
MIN_LANES = 8
# Share of a grid round's queries answered by brute force above which the next rounds skip
# the grids, and how many rounds until they are tried again.
BRUTE_SHARE = 0.5
PROBE_ROUNDS = 3


def _grid_candidates(jnp, g, y, x, ref):
    """Grid lookup of one lane's queries in every part: ``y (P, q, 3)`` the queries in each
    part's grid frame, ``x (q, 3)`` the same queries in the reference frame, ``ref (M, 3)`` the
    joined clouds in that frame (distances are computed there, as the protocol computes them).
    Returns ``(index (q,), answered (q,))``: the first minimum over the parts' candidate lists, and
    whether it is certainly the brute-force first minimum (every part's grid answered, or its
    box is farther than the best found)."""
    lo, inv_h, dims, child, cand, over, box_lo, box_hi, depth = g
    scale = inv_h * float(1 << depth)
    f = jnp.floor((y - lo[:, None, :]) * scale[:, None, None])
    fine_dims = (dims * (1 << depth))[:, None, :]
    inside = jnp.all((f >= 0) & (f < fine_dims), axis=-1)  # (P, q)
    fine = jnp.clip(f, 0, fine_dims - 1).astype(jnp.int32)
    root = fine >> depth
    node = (root[..., 0] * dims[:, None, 1] + root[..., 1]) * dims[:, None, 2] + root[..., 2]
    parts = jnp.arange(lo.shape[0])[:, None]
    for lev in range(1, depth + 1):
        bits = (fine >> (depth - lev)) & 1
        c = child[parts, node]
        node = jnp.where(c >= 0, c + 4 * bits[..., 0] + 2 * bits[..., 1] + bits[..., 2], node)
    ok = inside & ~over[parts, node]  # (P, q)
    cands = cand[parts, node]  # (P, q, K)
    yc = ref[cands]  # (P, q, K, 3)
    d = ((x[None, :, None, 0] - yc[..., 0]) ** 2 + (x[None, :, None, 1] - yc[..., 1]) ** 2) + (x[None, :, None, 2] - yc[..., 2]) ** 2
    k = jnp.argmin(d, axis=-1)  # (P, q): first minimum within a part (ascending indices)
    best_d = jnp.where(ok, jnp.take_along_axis(d, k[..., None], -1)[..., 0], jnp.inf)
    best_i = jnp.take_along_axis(cands, k[..., None], -1)[..., 0]
    q = jnp.argmin(best_d, axis=0)  # first part: parts hold ascending index ranges
    dmin = jnp.min(best_d, axis=0)
    idx = jnp.take_along_axis(best_i, q[None], 0)[0]
    g2 = jnp.maximum(jnp.maximum(box_lo[:, None, :] - y, y - box_hi[:, None, :]), 0.0)
    lb = jnp.sum(g2 * g2, axis=-1)  # (P, q) squared distance to each part's box
    unsure = ~ok & (lb * (1 - _LB_REL) - _LB_ABS <= dmin[None])
    return idx, ~jnp.any(unsure, axis=0)


# Lanes whose grid lookups run together (lax.map over groups of them bounds the gathered
# candidates held at once: lanes x queries x K x 4 float64 per group).
LANE_GROUP = 32


def _lanes(jax, f, *args):
    """``vmap(f)(*args)`` over the leading (lanes) axis, LANE_GROUP lanes at a time."""
    lanes = args[0].shape[0]
    g = min(LANE_GROUP, lanes)
    if lanes % g:
        return jax.vmap(f)(*args)
    grouped = [a.reshape((lanes // g, g) + a.shape[1:]) for a in args]
    out = jax.lax.map(lambda xs: jax.vmap(f)(*xs), grouped)
    return tuple(o.reshape((lanes,) + o.shape[2:]) for o in out)


def _brute_fix(jnp, lax, idx, answered, x, refs, lane_ref):
    """Replace the unanswered entries of ``idx (L, q)`` by brute-force first minima: query
    ``x[l, i]`` against ``refs[lane_ref[l]] (M, 3)``, FALLBACK_ROWS flagged queries at a time."""
    lanes, q = idx.shape
    flat = ~answered.reshape(-1)
    count = jnp.sum(flat)
    rows = min(FALLBACK_ROWS, flat.shape[0])
    order = jnp.concatenate([jnp.nonzero(flat, size=flat.shape[0], fill_value=0)[0].astype(jnp.int32),
                             jnp.zeros(rows, jnp.int32)])
    xs = x.reshape(-1, 3)

    def body(c):
        s, out = c
        pick = lax.dynamic_slice(order, (s,), (rows,))
        valid = s + jnp.arange(rows) < count
        ref = refs[lane_ref[pick // q]]  # (rows, M, 3)
        xq = xs[pick]
        d = ((xq[:, None, 0] - ref[..., 0]) ** 2 + (xq[:, None, 1] - ref[..., 1]) ** 2) + (xq[:, None, 2] - ref[..., 2]) ** 2
        j = jnp.argmin(d, axis=1).astype(out.dtype)
        out = out.at[jnp.where(valid, pick, flat.shape[0])].set(j, mode="drop")
        return s + rows, out

    _, out = lax.while_loop(lambda c: c[0] < count, body, (jnp.asarray(0, order.dtype), idx.reshape(-1)))
    return out.reshape(lanes, q), count


@lru_cache(maxsize=None)
def _compiled_nearest(depth: int):
    jax, jnp = jax_modules()

    def run(x, ref, g):
        n_parts = g[0].shape[0]
        idx, ok = jax.vmap(lambda xl: _grid_candidates(jnp, tuple(g) + (depth,), jnp.broadcast_to(xl[None], (n_parts,) + xl.shape),
                                                       xl, ref))(x)
        return _brute_fix(jnp, jax.lax, idx, ok, x, ref[None], jnp.zeros(x.shape[0], jnp.int32))

    return jax.jit(run)


def nearest_in_grids(x: np.ndarray, ref: np.ndarray, grids: PartGrids) -> tuple[np.ndarray, int]:
    """``(index (L, q), brute-forced)``: the nearest row of ``ref (M, 3)`` (first minimum) for
    every query ``x (L, q, 3)``, by the grids of ``ref``'s parts (:class:`PartGrids`, their frame
    ``ref``'s) and the brute-force path where they do not answer: the lookup ICP does."""
    _, jnp = jax_modules()
    idx, count = _compiled_nearest(grids.depth)(jnp.asarray(x, dtype=jnp.float64), jnp.asarray(ref, dtype=jnp.float64),
                                                tuple(jnp.asarray(a) for a in grids[:8]))
    return np.asarray(idx), int(count)


@lru_cache(maxsize=None)
def _compiled_round(max_iters: int, tol: float, depth_t: int, depth_p: int, has_pred_grids: bool, brute: bool):
    """``(init, round)``: every lane evaluated at its start; one round of the ICP of ``L``
    lanes (at most ROUND_ITERS iterations of every active lane). ``brute``: the round takes the
    brute-force path for every query (where most queries would fall back to it anyway)."""
    jax, jnp = jax_modules()
    lax = jax.lax

    def nearest(preds, target, tg, pg, maps, ck, r, t):
        """Both directions' neighbours and the objective of every lane at ``(r (L, 3, 3), t (L, 3))``."""
        p = preds[ck]  # (L, n, 3)
        x = jnp.einsum("lnk,ljk->lnj", p, r) + t[:, None, :]  # moved predictions
        if brute:
            tile = fit_tile(x.shape[0], max(x.shape[1], target.shape[0]))
            fwd = jax.vmap(lambda xl: _nearest(jnp, lax, xl, target, tile)[0])(x).astype(jnp.int32)
            bwd = jax.vmap(lambda xl: _nearest(jnp, lax, target, xl, tile)[0])(x).astype(jnp.int32)
            return _objective(jnp, x, target, fwd, bwd), fwd, bwd, jnp.asarray(fwd.size + bwd.size, jnp.int64)
        tg_ = tuple(tg) + (depth_t,)
        n_tp = tg[0].shape[0]
        fwd, f_ok = _lanes(jax, lambda xl: _grid_candidates(jnp, tg_, jnp.broadcast_to(xl[None], (n_tp,) + xl.shape), xl,
                                                            target), x)
        fwd, nf = _brute_fix(jnp, lax, fwd, f_ok, x, target[None], jnp.zeros(x.shape[0], jnp.int32))
        if has_pred_grids:
            pg_ = tuple(pg) + (depth_p,)
            # target points into each part's grid frame: part maps after the inverse registration
            a, b = maps[ck, :, :, :3], maps[ck, :, :, 3]  # (L, P, 3, 3), (L, P, 3)
            z = jnp.einsum("mk,lkj->lmj", target, r) - jnp.einsum("lk,lkj->lj", t, r)[:, None, :]  # R^T (T - t)
            y = jnp.einsum("lmk,lpjk->lpmj", z, a) + b[:, :, None, :]
            bwd, b_ok = _lanes(jax, lambda yl, xl: _grid_candidates(jnp, pg_, yl, target, xl), y, x)
        else:
            bwd = jnp.zeros((x.shape[0], target.shape[0]), jnp.int32)
            b_ok = jnp.zeros(bwd.shape, bool)
        tq = jnp.broadcast_to(target[None], (x.shape[0],) + target.shape)
        bwd, nb = _brute_fix(jnp, lax, bwd, b_ok, tq, x, jnp.arange(x.shape[0]))
        return _objective(jnp, x, target, fwd, bwd), fwd, bwd, (nf + nb).astype(jnp.int64)

    def init(preds, target, tg, pg, maps, ck, r0, t0):
        obj, fwd, bwd, nflag = nearest(preds, target, tg, pg, maps, ck, r0, t0)
        return obj, fwd, bwd, nflag

    def round_(preds, target, tg, pg, maps, ck, state):
        def cond(c):
            return (c[0] < ROUND_ITERS) & c[1][0].any()

        def body(c):
            k, (active, its, prev, fwd, bwd, best, br, bt), nflag = c
            p = preds[ck]
            src = jnp.concatenate([p, jnp.take_along_axis(p, bwd[..., None], 1)], axis=1)
            dst = jnp.concatenate([target[fwd], jnp.broadcast_to(target[None], bwd.shape + (3,))], axis=1)
            r, t = jax.vmap(lambda a_, b_: _kabsch(jnp, a_, b_))(src, dst)
            new, nfwd, nbwd, nf = nearest(preds, target, tg, pg, maps, ck, r, t)
            better = active & (new < best)
            best = jnp.where(better, new, best)
            br = jnp.where(better[:, None, None], r, br)
            bt = jnp.where(better[:, None], t, bt)
            keep = active[:, None]
            fwd, bwd = jnp.where(keep, nfwd, fwd), jnp.where(keep, nbwd, bwd)
            its = its + active
            still = active & ~(prev - new < tol) & (its < max_iters)
            prev = jnp.where(active, new, prev)
            return k + 1, (still, its, prev, fwd, bwd, best, br, bt), nflag + nf

        _, state, nflag = lax.while_loop(cond, body, (jnp.asarray(0), state, jnp.asarray(0, jnp.int64)))
        return state, nflag

    return jax.jit(init), jax.jit(round_)


def _objective(jnp, x, target, fwd, bwd):
    """The protocol's objective ``(L,)`` of moved predictions ``x (L, n, 3)`` with neighbours
    ``fwd (L, n)`` into ``target (m, 3)`` and ``bwd (L, m)`` into ``x``."""
    dfwd = jnp.sum((x - target[fwd]) ** 2, axis=-1).mean(axis=1)
    xb = jnp.take_along_axis(x, bwd[..., None], 1)
    return dfwd + jnp.sum((target[None] - xb) ** 2, axis=-1).mean(axis=1)


def _bucket(n: int) -> int:
    return max(MIN_LANES, 1 << max(n - 1, 0).bit_length())


def icp_batch(preds: np.ndarray, target: np.ndarray, r0: np.ndarray, t0: np.ndarray, max_iters: int, tol: float,
              target_grids: PartGrids | None = None, pred_grids: PartGrids | None = None,
              pred_maps: np.ndarray | None = None, stats: dict | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The protocol's ICP of every checkpoint from every start.

    ``preds (C, n, 3)`` normalized predictions of one task, ``target (m, 3)``, starts
    ``r0 (C, S, 3, 3)``, ``t0 (C, S, 3)``. Neighbours: ``target_grids`` (:class:`PartGrids` of
    the target's parts, their points in ``target``'s order; default: one grid of the whole
    target) for the forward direction; for the backward one ``pred_grids`` of the clouds every
    prediction moves rigidly (``P`` clouds, ``preds[c]`` = cloud ``q`` mapped into the
    prediction frame, part after part) with ``pred_maps (C, P, 3, 4)``: ``[A | b]`` taking a
    point of prediction ``c``'s frame into cloud ``q``'s frame (default: brute force). Either
    way the neighbours are the brute-force first minima. Returns each lane's best state:
    ``objective (C, S)``, ``rotation (C, S, 3, 3)``, ``translation (C, S, 3)`` (NumPy float64).
    ``stats``: filled with ``lanes_iterated`` (sum over rounds of the lanes computed, padding
    included), ``lane_iterations`` (fits the protocol needed) and ``brute_queries``.
    """
    jax, jnp = jax_modules()
    target = np.ascontiguousarray(target, dtype=np.float64)
    if target_grids is None:
        target_grids = build_part_grids(target[None], k=JOINED_K, margin_cells=JOINED_MARGIN_CELLS)
    c, s = r0.shape[:2]
    has_pg = pred_grids is not None
    shape = (int(max_iters), float(tol), target_grids.depth, pred_grids.depth if has_pg else 0, has_pg)
    init, round_grid = _compiled_round(*shape, False)
    brute, since_grid = False, 0
    dev = lambda a: jnp.asarray(a)  # noqa: E731
    tg = tuple(dev(a) for a in target_grids[:8])
    pg = tuple(dev(a) for a in pred_grids[:8]) if has_pg else ()
    maps = dev(pred_maps if has_pg else np.zeros((c, 1, 3, 4)))
    pr, tgt = dev(np.asarray(preds, np.float64)), dev(target)
    lanes = c * s
    ck_all = np.repeat(np.arange(c), s)
    r_all, t_all = np.asarray(r0, np.float64).reshape(-1, 3, 3), np.asarray(t0, np.float64).reshape(-1, 3)
    best_obj, best_r, best_t = np.empty(lanes), r_all.copy(), t_all.copy()
    counters = {"lanes_iterated": 0, "lane_iterations": 0, "brute_queries": 0, "rounds": 0, "brute_rounds": 0}
    # the starts' objectives, in buckets; then rounds over the lanes still running
    live: list[tuple] = []
    for lo in range(0, lanes, 1 << 12):
        ids = np.arange(lo, min(lanes, lo + (1 << 12)))
        pad = _pad(ids)
        obj, fwd, bwd, nflag = init(pr, tgt, tg, pg, maps, dev(ck_all[pad]), dev(r_all[pad]), dev(t_all[pad]))
        counters["brute_queries"] += int(nflag)
        obj = np.asarray(obj)[: len(ids)]
        best_obj[ids] = obj
        live.append((ids, np.ones(len(ids), bool), np.zeros(len(ids), np.int64), obj, np.asarray(fwd)[: len(ids)],
                     np.asarray(bwd)[: len(ids)], obj.copy(), r_all[ids], t_all[ids]))
    ids, active, its, prev, fwd, bwd, best, br, bt = (np.concatenate(z) for z in zip(*live))
    active &= max_iters > 0
    while active.any():
        keep = np.flatnonzero(active)
        ids, active, its, prev, fwd, bwd, best, br, bt = (a[keep] for a in (ids, active, its, prev, fwd, bwd, best, br, bt))
        pad = _pad(np.arange(len(ids)))
        state = (active[pad] & (pad < len(ids)), its[pad], prev[pad], fwd[pad], bwd[pad], best[pad], br[pad], bt[pad])
        state = tuple(dev(a) for a in state)
        round_ = _compiled_round(*shape, True)[1] if brute else round_grid
        out, nflag = round_(pr, tgt, tg, pg, maps, dev(ck_all[ids][pad]), state)
        n = len(ids)
        new_its = np.asarray(out[1])[:n]
        iters = int((new_its - its).max())
        counters["lanes_iterated"] += len(pad) * iters
        # where most queries of a grid round fell back to brute force, the next rounds take the
        # plain brute-force path (cheaper than the lookups plus the fallback), trying the grids
        # again every PROBE_ROUNDS rounds (lanes near convergence query near the surfaces)
        share = int(nflag) / max(len(pad) * iters * (preds.shape[1] + len(target)), 1)
        brute, since_grid = (share > BRUTE_SHARE, 0) if not brute else (since_grid + 1 < PROBE_ROUNDS, since_grid + 1)
        counters["rounds"] += 1
        counters["brute_rounds"] += int(round_ is not round_grid)
        counters["lane_iterations"] += int((new_its - its).sum())
        counters["brute_queries"] += int(nflag)
        active, its, prev, fwd, bwd, best, br, bt = (np.asarray(a)[:n] for a in out)
        best_obj[ids], best_r[ids], best_t[ids] = best, br, bt
    if stats is not None:
        stats.update(counters)
    return best_obj.reshape(c, s), best_r.reshape(c, s, 3, 3), best_t.reshape(c, s, 3)


def _pad(ids: np.ndarray) -> np.ndarray:
    """``ids`` padded to its bucket with copies of its last entry."""
    size = _bucket(len(ids))
    return np.concatenate([ids, np.full(size - len(ids), ids[-1] if len(ids) else 0, ids.dtype)])


@lru_cache(maxsize=None)
def _compiled_part_cd(tile: int):
    jax, jnp = jax_modules()
    lax = jax.lax

    def pair(x, y):  # (n, 3), (n, 3) -> CD
        return _nearest(jnp, lax, x, y, tile)[1].mean() + _nearest(jnp, lax, y, x, tile)[1].mean()

    def listed(moved, target, i, j):  # (P, n, 3), (P, n, 3), (Q,), (Q,) -> (Q,)
        return jax.vmap(pair)(moved[i], target[j])

    return jax.jit(jax.vmap(listed, (0, None, None, None)))


def part_cd_batch(moved_parts: np.ndarray, target_parts: np.ndarray, pairs: np.ndarray | None = None,
                  tile: int = DEFAULT_TILE) -> np.ndarray:
    """``C (C, P, P)``: ``C[c, i, j]`` = CD(registered pred part ``i`` of checkpoint ``c``, target
    part ``j``) for ``moved_parts (C, P, n, 3)`` and ``target_parts (P, n, 3)``, for the pairs
    ``(i, j)`` of ``pairs (Q, 2)`` (default: all; ``inf`` elsewhere). Brute force: a checkpoint
    needs only the pairs within equivalence groups, a few per part."""
    _, jnp = jax_modules()
    c, p, n = moved_parts.shape[:3]
    if pairs is None:
        pairs = np.array([(i, j) for i in range(p) for j in range(p)])
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    got = _compiled_part_cd(fit_tile(c * len(pairs), n, tile))(jnp.asarray(moved_parts, dtype=jnp.float64),
                                                              jnp.asarray(target_parts, dtype=jnp.float64),
                                                              jnp.asarray(pairs[:, 0]), jnp.asarray(pairs[:, 1]))
    out = np.full((c, p, p), np.inf)
    out[:, pairs[:, 0], pairs[:, 1]] = np.asarray(got)
    return out
