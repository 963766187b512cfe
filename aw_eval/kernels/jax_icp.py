"""The protocol's ICP and part Chamfer distances in JAX, batched over checkpoints x starts.

The XLA counterpart of :class:`aw_eval.kernels.ICPProblem`: the same rule from every start (both
directions' nearest neighbours, one proper Kabsch fit of all pairs, at most ``max_iters`` fits,
stop when the objective improves by less than ``tol``, keep the best state visited), for many
checkpoints of one task at once.

Nearest neighbours, in fixed shapes: exact per-query leaf-box certificates
(:mod:`aw_eval.kernels.leafbox`; built once per task on the host, in milliseconds). A query
takes the squared distances to every leaf box of its clouds, reads the points of the
``candidates`` nearest boxes, computes their squared distances from coordinates as the protocol
does (in the reference frame) and takes the first minimum; the next box's distance certifies
that no other point is nearer or tied (the boxes are picked by a float32 top-k, XLA's fast
one on a CPU; the certificate allows for float32's rounding). Forward, the joined target's leaves; backward, the
leaves of every part's baked cloud as one list (a checkpoint moves each rigidly: the target
points are mapped into each part's frame for the box distances). Every query without a
certificate takes the brute-force path, all lanes' such queries compacted into tiles of
FALLBACK_ROWS. So every neighbour is the brute-force first minimum, and every decision the
numba backend's up to the rounding of near (not exact) ties.

Lanes (one checkpoint's one start) stop at different iterations: the loop runs ROUND_ITERS
iterations per round, then drops the lanes that stopped and packs the rest into the smallest
power-of-two bucket (a few compiled shapes). Everything is float64: the neighbour decisions and
the ``tol = 1e-9`` improvements need it.
"""

from __future__ import annotations

from functools import cache, lru_cache

import numpy as np
from numpy.typing import ArrayLike

from aw_eval.kernels.jaxcfg import jax_modules
from aw_eval.kernels.leafbox import ABS as LEAF_ABS
from aw_eval.kernels.leafbox import DEFAULT_CANDIDATES, LeafBoxes, build_leaf_boxes
from aw_eval.kernels.leafbox import REL as LEAF_REL

__all__ = ["accelerator_present", "icp_batch", "nearest_in_leaves", "part_cd_batch", "fit_tile", "DEFAULT_TILE"]

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
        d = (
            (qt[:, None, 0] - ref[None, :, 0]) ** 2
            + (qt[:, None, 1] - ref[None, :, 1]) ** 2
            + (qt[:, None, 2] - ref[None, :, 2]) ** 2
        )
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


# Flagged queries brute-forced per step of the fallback loop (all lanes together).
FALLBACK_ROWS = 256
# ICP iterations per round; between rounds the lanes that have stopped are dropped and the
# remaining ones packed into the smallest bucket (a power of two, at least MIN_LANES).
ROUND_ITERS = 8
MIN_LANES = 8
# Box distances held at once by the leaf lookups (lanes x queries x leaves, float64): lanes
# are looked up in groups that fit it (lax.map over the groups). Groups run one after the
# other, so an accelerator, which needs many lanes at once to be busy, gets a larger budget
# (:func:`leaf_elements`).
LEAF_ELEMENTS = 1 << 25
ACCELERATOR_LEAF_ELEMENTS = 1 << 28
# Lanes per device call (at most): a lane holds about LANE_FLOATS x (n + m) float64 at once
# (the moved predictions, both directions' pairs for the fit, the fallback's queries), and a
# call holds at most LANE_ELEMENTS of them; more lanes are run in several calls.
LANE_ELEMENTS = 1 << 28
LANE_FLOATS = 24
# Relative slack for the boxes picked in float32 (rounding to float32 moves a value by at most
# 2^-24 relative; below float32's normal range by more, where the absolute slack fails the
# certificate anyway).
_F32_SLACK = 1e-6
# Leaves a query reads where the caller does not say (tests lower it to exercise the fallback).
CANDIDATES = DEFAULT_CANDIDATES


def _leaf_candidates(jnp, lax, leaves, y, x, ref, c: int):
    """Leaf lookup of one lane's queries in ``P`` clouds: ``y (P, q, 3)`` the queries in each
    cloud's frame (its leaf boxes'), ``x (q, 3)`` the same queries in the reference frame,
    ``ref (M, 3)`` the joined clouds there (distances are computed there, as the protocol
    computes them). Returns ``(index (q,), answered (q,))``: the first minimum over the points of
    the ``c`` nearest leaf boxes (all parts' leaves as one list), and whether the next box is
    farther than it (then it is the brute-force first minimum; :mod:`aw_eval.kernels.leafbox`);
    ``answered`` is ``None`` where every leaf is read (all certain)."""
    lo, hi, index = leaves
    p, b, s = index.shape
    q = x.shape[0]
    if c >= p * b:  # every leaf read: plain brute force over ``ref`` (all certain; None known when tracing)
        d = ((x[:, None, 0] - ref[None, :, 0]) ** 2 + (x[:, None, 1] - ref[None, :, 1]) ** 2) + (
            x[:, None, 2] - ref[None, :, 2]
        ) ** 2
        return jnp.argmin(d, axis=1).astype(jnp.int32), None
    g = jnp.maximum(jnp.maximum(lo[:, None] - y[:, :, None], y[:, :, None] - hi[:, None]), 0.0)  # (P, q, B, 3)
    lb = (g[..., 0] * g[..., 0] + g[..., 1] * g[..., 1]) + g[..., 2] * g[..., 2]
    lb = jnp.moveaxis(lb, 0, 1).reshape(q, p * b)
    # the c nearest boxes picked in float32 (XLA's float64 top-k is far slower on a CPU), and
    # materialized (fused into its several consumers, XLA recomputes it in each: 8x slower). The
    # certificate: every box not picked has a float32 distance at least the (c+1)-th box's, so a
    # float64 one at least (1 - 2^-24)^2 times that box's float64 distance, capped at float32's
    # largest value (past it every float32 distance is inf alike)
    order = lax.optimization_barrier(lax.top_k(-lb.astype(jnp.float32), c + 1)[1])
    nxt = order[:, c]
    part = nxt // b
    yn = y[part, jnp.arange(q)]  # (q, 3) each query in that box's frame
    gap = jnp.maximum(jnp.maximum(lo.reshape(-1, 3)[nxt] - yn, yn - hi.reshape(-1, 3)[nxt]), 0.0)
    nxt_d2 = (gap[:, 0] * gap[:, 0] + gap[:, 1] * gap[:, 1]) + gap[:, 2] * gap[:, 2]
    bound = jnp.minimum(nxt_d2, float(np.finfo(np.float32).max)) * (1 - _F32_SLACK)
    flat = index.reshape(p * b, s)
    # whole leaves gathered (contiguous blocks), coordinates leaf-major: (P B, 3, S)
    sel = order[:, :c]
    yc, cand = jnp.swapaxes(ref[flat], 1, 2)[sel], flat[sel].reshape(q, c * s)  # (q, c, 3, S), (q, c S)
    d = ((x[:, None, 0, None] - yc[:, :, 0]) ** 2 + (x[:, None, 1, None] - yc[:, :, 1]) ** 2) + (
        x[:, None, 2, None] - yc[:, :, 2]
    ) ** 2
    d = d.reshape(q, c * s)
    dmin = jnp.min(d, axis=1)
    idx = jnp.min(jnp.where(d == dmin[:, None], cand, jnp.iinfo(jnp.int32).max), axis=1)  # lowest index of the ties
    return idx, bound * (1 - LEAF_REL) - LEAF_ABS > dmin


def _lanes(jax, f, group: int, *args):
    """``vmap(f)(*args)`` over the leading (lanes) axis, ``group`` lanes at a time."""
    lanes = args[0].shape[0]
    g = max(1, min(group, lanes))
    if lanes % g:
        return jax.vmap(f)(*args)
    grouped = [a.reshape((lanes // g, g) + a.shape[1:]) for a in args]
    out = jax.lax.map(lambda xs: jax.vmap(f)(*xs), grouped)
    return tuple(None if o is None else o.reshape((lanes,) + o.shape[2:]) for o in out)


def leaf_elements() -> int:
    """The leaf lookups' budget of box distances held at once: LEAF_ELEMENTS on a CPU,
    ACCELERATOR_LEAF_ELEMENTS where JAX sees a GPU or TPU."""
    return ACCELERATOR_LEAF_ELEMENTS if accelerator_present() else LEAF_ELEMENTS


def _group(queries: int, leaves: LeafBoxes, candidates: int) -> int:
    """Lanes per leaf-lookup group: the largest power of two whose box and candidate distances
    fit :func:`leaf_elements`."""
    p, b, s = leaves[2].shape
    per_query = max(p * b, min(candidates, p * b) * s)
    budget = leaf_elements()
    g = 1
    while 2 * g * queries * per_query <= budget:
        g *= 2
    return g


def max_lanes(n: int, m: int) -> int:
    """Lanes per device call for ``n`` prediction and ``m`` target points: the largest power of
    two (at least MIN_LANES) whose lanes hold at most LANE_ELEMENTS float64 (LANE_FLOATS per
    point of either cloud)."""
    lanes = MIN_LANES
    while 2 * lanes * LANE_FLOATS * (n + m) <= LANE_ELEMENTS:
        lanes *= 2
    return lanes


def _brute_fix(jnp, lax, idx, answered, x, refs, lane_ref):
    """Replace the unanswered entries of ``idx (L, q)`` by brute-force first minima: query
    ``x[l, i]`` against ``refs[lane_ref[l]] (M, 3)``, FALLBACK_ROWS flagged queries at a time
    (``answered`` ``None``: all answered). Returns ``(index (L, q), brute-forced count)``."""
    if answered is None:
        return idx, jnp.asarray(0, jnp.int64)
    lanes, q = idx.shape
    flat = ~answered.reshape(-1)
    count = jnp.sum(flat)
    rows = min(FALLBACK_ROWS, flat.shape[0])
    order = jnp.concatenate(
        [jnp.nonzero(flat, size=flat.shape[0], fill_value=0)[0].astype(jnp.int32), jnp.zeros(rows, jnp.int32)]
    )
    xs = x.reshape(-1, 3)

    def body(c):
        s, out = c
        pick = lax.dynamic_slice(order, (s,), (rows,))
        valid = s + jnp.arange(rows) < count
        ref = refs[lane_ref[pick // q]]  # (rows, M, 3)
        xq = xs[pick]
        d = ((xq[:, None, 0] - ref[..., 0]) ** 2 + (xq[:, None, 1] - ref[..., 1]) ** 2) + (
            xq[:, None, 2] - ref[..., 2]
        ) ** 2
        j = jnp.argmin(d, axis=1).astype(out.dtype)
        out = out.at[jnp.where(valid, pick, flat.shape[0])].set(j, mode="drop")
        return s + rows, out

    _, out = lax.while_loop(lambda c: c[0] < count, body, (jnp.asarray(0, order.dtype), idx.reshape(-1)))
    return out.reshape(lanes, q), count


@cache
def _compiled_nearest(candidates: int):
    jax, jnp = jax_modules()

    def run(x, ref, leaves):
        n_parts = leaves[0].shape[0]
        idx, ok = jax.vmap(
            lambda xl: _leaf_candidates(
                jnp, jax.lax, leaves, jnp.broadcast_to(xl[None], (n_parts,) + xl.shape), xl, ref, candidates
            )
        )(x)
        return _brute_fix(jnp, jax.lax, idx, ok, x, ref[None], jnp.zeros(x.shape[0], jnp.int32))

    return jax.jit(run)


def nearest_in_leaves(
    x: np.ndarray, ref: np.ndarray, leaves: LeafBoxes, candidates: int | None = None
) -> tuple[np.ndarray, int]:
    """``(index (L, q), brute-forced)``: the nearest row of ``ref (M, 3)`` (first minimum) for
    every query ``x (L, q, 3)``, by the leaf boxes of ``ref``'s parts (:class:`LeafBoxes`, their
    frame ``ref``'s) and the brute-force path where they do not certify: the lookup ICP does."""
    _, jnp = jax_modules()
    idx, count = _compiled_nearest(int(CANDIDATES if candidates is None else candidates))(
        jnp.asarray(x, dtype=jnp.float64), jnp.asarray(ref, dtype=jnp.float64), tuple(jnp.asarray(a) for a in leaves)
    )
    return np.asarray(idx), int(count)


@cache
def _compiled_round(max_iters: int, tol: float, candidates: int, has_pred_leaves: bool):
    """``(init, round)``: every lane evaluated at its start; one round of the ICP of ``L``
    lanes (at most ROUND_ITERS iterations of every active lane)."""
    jax, jnp = jax_modules()
    lax = jax.lax

    def nearest(preds, target, tl, pl, maps, ck, r, t):
        """Both directions' neighbours and the objective of every lane at ``(r (L, 3, 3), t (L, 3))``."""
        p = preds[ck]  # (L, n, 3)
        x = jnp.einsum("lnk,ljk->lnj", p, r) + t[:, None, :]  # moved predictions
        fwd, f_ok = _lanes(
            jax,
            lambda xl: _leaf_candidates(jnp, lax, tl, xl[None], xl, target, candidates),
            _group(x.shape[1], tl, candidates),
            x,
        )
        fwd, nf = _brute_fix(jnp, lax, fwd, f_ok, x, target[None], jnp.zeros(x.shape[0], jnp.int32))
        if has_pred_leaves:

            def backward(rl, tl_, al, bl, xl):  # one lane: target points into each part's leaf frame
                z = jnp.einsum("mk,kj->mj", target, rl) - (tl_ @ rl)[None, :]  # R^T (T - t), (m, 3)
                y = jnp.einsum("mk,pjk->pmj", z, al) + bl[:, None, :]  # part maps after it, (P, m, 3)
                return _leaf_candidates(jnp, lax, pl, y, target, xl, candidates)

            # (P, m, 3) per lane: formed inside the lane groups, never for every lane at once
            a, b = maps[ck, :, :, :3], maps[ck, :, :, 3]  # (L, P, 3, 3), (L, P, 3)
            bwd, b_ok = _lanes(jax, backward, _group(target.shape[0], pl, candidates), r, t, a, b, x)
        else:
            bwd = jnp.zeros((x.shape[0], target.shape[0]), jnp.int32)
            b_ok = jnp.zeros(bwd.shape, bool)
        tq = jnp.broadcast_to(target[None], (x.shape[0],) + target.shape)
        bwd, nb = _brute_fix(jnp, lax, bwd, b_ok, tq, x, jnp.arange(x.shape[0]))
        return _objective(jnp, x, target, fwd, bwd), fwd, bwd, (nf + nb).astype(jnp.int64)

    def init(preds, target, tl, pl, maps, ck, r0, t0):
        return nearest(preds, target, tl, pl, maps, ck, r0, t0)

    def round_(preds, target, tl, pl, maps, ck, state):
        def cond(c):
            return (c[0] < ROUND_ITERS) & c[1][0].any()

        def body(c):
            k, (active, its, prev, fwd, bwd, best, br, bt), nflag = c
            p = preds[ck]
            src = jnp.concatenate([p, jnp.take_along_axis(p, bwd[..., None], 1)], axis=1)
            dst = jnp.concatenate([target[fwd], jnp.broadcast_to(target[None], bwd.shape + (3,))], axis=1)
            r, t = jax.vmap(lambda a_, b_: _kabsch(jnp, a_, b_))(src, dst)
            new, nfwd, nbwd, nf = nearest(preds, target, tl, pl, maps, ck, r, t)
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


def icp_batch(
    preds: np.ndarray,
    target: np.ndarray,
    r0: np.ndarray,
    t0: np.ndarray,
    max_iters: int,
    tol: float,
    target_leaves: LeafBoxes | None = None,
    pred_leaves: LeafBoxes | None = None,
    pred_maps: np.ndarray | None = None,
    stats: dict | None = None,
    candidates: int | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The protocol's ICP of every checkpoint from every start.

    ``preds (C, n, 3)`` normalized predictions of one task, ``target (m, 3)``, starts
    ``r0 (C, S, 3, 3)``, ``t0 (C, S, 3)``. Neighbours: ``target_leaves`` (:class:`LeafBoxes` of
    ``target``, one cloud; default: built here) for the forward direction; for the backward one
    ``pred_leaves`` of the ``P`` clouds every prediction moves rigidly (``preds[c]`` = cloud
    ``q`` mapped into the prediction frame, part after part) with ``pred_maps (C, P, 3, 4)``:
    ``[A | b]`` taking a point of prediction ``c``'s frame into cloud ``q``'s frame (default:
    brute force). ``candidates``: leaves a query reads (default CANDIDATES). Either way the neighbours are the
    brute-force first minima. Returns each lane's best state: ``objective (C, S)``, ``rotation
    (C, S, 3, 3)``, ``translation (C, S, 3)`` (NumPy float64). ``stats``: filled with
    ``lanes_iterated`` (sum over rounds of the lanes computed, padding included),
    ``lane_iterations`` (fits the protocol needed), ``rounds``, ``queries`` (neighbour queries
    computed, padding included) and ``brute_queries`` (of those, the ones the leaves did not
    certify).
    """
    jax, jnp = jax_modules()
    target = np.ascontiguousarray(target, dtype=np.float64)
    if target_leaves is None:
        target_leaves = build_leaf_boxes(target)
    c, s = r0.shape[:2]
    has_pl = pred_leaves is not None
    init, round_ = _compiled_round(
        int(max_iters), float(tol), int(CANDIDATES if candidates is None else candidates), has_pl
    )
    dev = jnp.asarray
    tl = tuple(dev(a) for a in target_leaves)
    pl = tuple(dev(a) for a in pred_leaves) if pred_leaves is not None else ()
    maps = dev(pred_maps if has_pl else np.zeros((c, 1, 3, 4)))
    pr, tgt = dev(np.asarray(preds, np.float64)), dev(target)
    lanes = c * s
    ck_all = np.repeat(np.arange(c), s)
    r_all, t_all = np.asarray(r0, np.float64).reshape(-1, 3, 3), np.asarray(t0, np.float64).reshape(-1, 3)
    best_obj, best_r, best_t = np.empty(lanes), r_all.copy(), t_all.copy()
    counters = {"lanes_iterated": 0, "lane_iterations": 0, "queries": 0, "brute_queries": 0, "rounds": 0}
    per_lane = preds.shape[1] + len(target)  # neighbour queries of one evaluation, both directions
    # the starts' objectives, in buckets; then rounds over the lanes still running
    cap = max_lanes(preds.shape[1], len(target))
    live: list[tuple] = []
    for lo in range(0, lanes, cap):
        ids = np.arange(lo, min(lanes, lo + cap))
        pad = _pad(ids)
        obj, fwd, bwd, nflag = init(pr, tgt, tl, pl, maps, dev(ck_all[pad]), dev(r_all[pad]), dev(t_all[pad]))
        counters["brute_queries"] += int(nflag)
        counters["queries"] += len(pad) * per_lane
        obj = np.asarray(obj)[: len(ids)]
        best_obj[ids] = obj
        live.append(
            (
                ids,
                np.ones(len(ids), bool),
                np.zeros(len(ids), np.int64),
                obj,
                np.asarray(fwd)[: len(ids)],
                np.asarray(bwd)[: len(ids)],
                obj.copy(),
                r_all[ids],
                t_all[ids],
            )
        )
    ids, active, its, prev, fwd, bwd, best, br, bt = (np.concatenate(z) for z in zip(*live, strict=True))
    active &= max_iters > 0
    while active.any():
        keep = np.flatnonzero(active)
        ids, active, its, prev, fwd, bwd, best, br, bt = (
            a[keep] for a in (ids, active, its, prev, fwd, bwd, best, br, bt)
        )
        counters["rounds"] += 1
        for lo in range(0, len(ids), cap):  # the lanes still running, at most cap per call
            part = slice(lo, min(len(ids), lo + cap))
            n = part.stop - part.start
            pad = _pad(np.arange(part.start, part.stop))
            state = (
                active[pad] & (pad < part.stop),
                its[pad],
                prev[pad],
                fwd[pad],
                bwd[pad],
                best[pad],
                br[pad],
                bt[pad],
            )
            out, nflag = round_(pr, tgt, tl, pl, maps, dev(ck_all[ids[pad]]), tuple(dev(a) for a in state))
            new_its = np.asarray(out[1])[:n]
            iters = int((new_its - its[part]).max())  # every lane of the bucket computed that many
            counters["lanes_iterated"] += len(pad) * iters
            counters["queries"] += len(pad) * iters * per_lane
            counters["lane_iterations"] += int((new_its - its[part]).sum())
            counters["brute_queries"] += int(nflag)
            for whole, got in zip((active, its, prev, fwd, bwd, best, br, bt), out, strict=True):
                whole[part] = np.asarray(got)[:n]
        best_obj[ids], best_r[ids], best_t[ids] = best, br, bt
    if stats is not None:
        stats.update(counters)
    return best_obj.reshape(c, s), best_r.reshape(c, s, 3, 3), best_t.reshape(c, s, 3)


def _pad(ids: np.ndarray) -> np.ndarray:
    """``ids`` padded to its bucket with copies of its last entry."""
    size = _bucket(len(ids))
    return np.concatenate([ids, np.full(size - len(ids), ids[-1] if len(ids) else 0, ids.dtype)])


@cache
def _compiled_part_cd(tile: int):
    jax, jnp = jax_modules()
    lax = jax.lax

    def pair(x, y):  # (n, 3), (n, 3) -> CD
        return _nearest(jnp, lax, x, y, tile)[1].mean() + _nearest(jnp, lax, y, x, tile)[1].mean()

    def listed(moved, target, i, j):  # (P, n, 3), (P, n, 3), (Q,), (Q,) -> (Q,)
        return jax.vmap(pair)(moved[i], target[j])

    return jax.jit(jax.vmap(listed, (0, None, None, None)))


def part_cd_batch(
    moved_parts: np.ndarray, target_parts: np.ndarray, pairs: ArrayLike | None = None, tile: int = DEFAULT_TILE
) -> np.ndarray:
    """``C (C, P, P)``: ``C[c, i, j]`` = CD(registered pred part ``i`` of checkpoint ``c``, target
    part ``j``) for ``moved_parts (C, P, n, 3)`` and ``target_parts (P, n, 3)``, for the pairs
    ``(i, j)`` of ``pairs (Q, 2)`` (default: all; ``inf`` elsewhere). Brute force: a checkpoint
    needs only the pairs within equivalence groups, a few per part."""
    _, jnp = jax_modules()
    c, p, n = moved_parts.shape[:3]
    if pairs is None:
        pairs = np.array([(i, j) for i in range(p) for j in range(p)])
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    got = _compiled_part_cd(fit_tile(c * len(pairs), n, tile))(
        jnp.asarray(moved_parts, dtype=jnp.float64),
        jnp.asarray(target_parts, dtype=jnp.float64),
        jnp.asarray(pairs[:, 0]),
        jnp.asarray(pairs[:, 1]),
    )
    out = np.full((c, p, p), np.inf)
    out[:, pairs[:, 0], pairs[:, 1]] = np.asarray(got)
    return out
