"""Registration (Appendix A.3 of the paper): one rigid transform of the whole prediction onto the
whole target, by symmetric ICP from every start of :mod:`aw_eval.starts`.

The ICP rule, from each start: find both directions' nearest neighbours (each moved predicted
point's nearest target point, each target point's nearest moved predicted point), fit the
proper rigid transform of all those pairs at once (Kabsch), repeat for at most ``max_iters``
(100) iterations or until the objective (the SCD, the sum of both directions' mean squared
nearest distances) improves by less than ``tol`` (1e-9); keep the best state visited. The start
with the lowest objective wins; on an exact tie the earlier start wins.

``exact`` runs every start at full resolution (the same numbers as :mod:`aw_eval.reference`);
The ``jax`` backend registers many checkpoints of a task at once, every start of every
checkpoint batched on an XLA device (:func:`register_exact_many`, over
:func:`aw_eval.kernels.icp_batch`; stopped starts leave the batch between rounds): the same
rule, the same neighbours, the same numbers to rounding.
``fast`` prunes the starts coarse-to-fine (:func:`aw_eval.kernels.coarse_to_fine`) and refines
further where a decision is near its threshold (agreement with ``exact`` is measured, not
guaranteed; see docs/performance.md).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from aw.pose import as_finite
from aw_eval.geometry import Checkpoint, TaskGeometry
from aw_eval.kernels import (
    ICPProblem,
    ICPResult,
    TaskIndex,
    accelerator_present,
    build_tree,
    coarse_to_fine,
    fast_settings,
    graph_for,
    icp_batch,
    same_basin,
)
from aw_eval.results import Registration, ScoreResult
from aw_eval.settings import ProtocolSettings
from aw_eval.starts import pca_starts, same_id_starts, start_frame

__all__ = [
    "MODES",
    "BACKENDS",
    "resolve_backend",
    "register_exact_many",
    "jax_part_maps",
    "checkpoint_starts",
    "register_points",
    "register_exact",
    "register_fast",
    "escalate",
    "near_threshold",
    "register",
    "register_checkpoint",
    "CONTACT_WALKS",
]

MODES = ("exact", "fast")
# numba: compiled walks on the CPU, one start at a time; jax: batched leaf-box certified lookups on
# any XLA device; auto: jax for exact when JAX sees an accelerator, numba otherwise (on a CPU the
# compiled walks are far faster: docs/performance.md)
BACKENDS = ("auto", "numba", "jax")


def checkpoint_starts(geom: TaskGeometry, ck: Checkpoint) -> tuple[np.ndarray, np.ndarray]:
    """Every start of checkpoint ``ck``: ``(R0 (24 + P, 3, 3), t0 (24 + P, 3))``."""
    r_pca, t_pca = pca_starts(start_frame(ck.points), geom.target_frame())
    r_part, t_part = same_id_starts(ck.rotations, ck.poses, geom.target_rotations(), geom.target_poses, geom.divisor)
    return np.concatenate([r_pca, r_part]), np.concatenate([t_pca, t_part])


def register_points(
    prob: ICPProblem,
    r0: np.ndarray,
    t0: np.ndarray,
    max_iters: int,
    tol: float,
    after_first: Callable[[ICPProblem, ICPResult], ICPProblem] | None = None,
) -> Registration:
    """Every start ``r0 (S, 3, 3)``, ``t0 (S, 3)`` refined by the protocol's ICP; the lowest
    objective wins, ties to the earlier. ``after_first``: optional ``(problem, first start's
    ICPResult) -> problem`` for the remaining starts (the same registration problem with another
    search structure: same answers)."""
    if len(r0) < 1:
        raise ValueError("register_points needs at least one start")
    objs = np.empty(len(r0))
    best: ICPResult | None = None
    best_k = 0
    for k in range(len(r0)):
        res = prob.run(r0[k], t0[k], max_iters, tol)
        objs[k] = res.objective
        if best is None or res.objective < best.objective:
            best, best_k = res, k
        if k == 0 and after_first is not None:
            prob = after_first(prob, res)
    assert best is not None  # at least one start ran
    return Registration(float(best.objective), best.rotation, best.translation, best_k, objs)


# Part walks per backward search from which a prediction gets its own Delaunay graph (see
# _own_graph_where_parts_touch). Measured on the first start (benchmarks/profile_icp.py and the
# box final states of bench_score.py): 1.04-1.16 on the benchmark checkpoints, whose own graph
# would cost more to build (0.08-1.2 s) than it saves (net -0.13 to -0.32 s); 1.47-1.53 on box
# assemblies whose parts touch face to face, where it saves 1.1-2.0 s of 4.5-5.7 s.
CONTACT_WALKS = 1.3


def _own_graph_where_parts_touch(
    index: TaskIndex, pred_parts: np.ndarray
) -> Callable[[ICPProblem, ICPResult], ICPProblem]:
    """``after_first`` hook of :func:`register_points` for ``exact``: where the first start's
    backward search walked more than ``CONTACT_WALKS`` parts per query (parts in contact: every
    query near a contact walks both parts), the remaining starts search the prediction's own
    Delaunay graph instead (the union's Voronoi cells need one walk; a Qhull build per
    checkpoint). The neighbours are exact either way; only the objective's summation order
    changes (last digits)."""

    def after_first(prob: ICPProblem, first: ICPResult) -> ICPProblem:
        if first.part_searches == 0 or first.part_walks <= CONTACT_WALKS * first.part_searches:
            return prob
        own, has_graph = index.own_problem(pred_parts)
        return own if has_graph else prob

    return after_first


def _full_problem(geom: TaskGeometry, ck: Checkpoint) -> ICPProblem:
    return geom.index().assembly_problem(ck.poses, ck.rotations, ck.parts, geom.divisor)


def jax_part_maps(geom: TaskGeometry, cks: list[Checkpoint]) -> np.ndarray:
    """``(C, P, 3, 4)``: ``[A | b]`` taking a point of checkpoint ``c``'s normalized prediction
    frame into part ``q``'s baked cloud over the divisor (``A = R_q^T``, ``b = -R_q^T t_q / divisor``)."""
    rt = np.swapaxes(np.stack([ck.rotations for ck in cks]), 2, 3)  # (C, P, 3, 3)
    t = np.stack([ck.poses[:, :3] for ck in cks]) / geom.divisor  # (C, P, 3)
    return np.concatenate([rt, -(rt @ t[..., None])], axis=3)


def register_exact_many(
    geom: TaskGeometry, cks: list[Checkpoint], stats: dict[str, Any] | None = None
) -> list[Registration]:
    """The protocol's registration of every checkpoint of ``cks`` at once (``jax`` backend): all
    starts of all checkpoints batched, neighbours certified by the task's leaf boxes
    (:meth:`aw_eval.kernels.TaskIndex.part_leaves`: the joined target forward, the parts' baked
    clouds backward, exact); per checkpoint the lowest objective wins, ties to the earlier start
    (``argmin`` takes the first). ``stats``: see :func:`aw_eval.kernels.icp_batch`."""
    st = geom.settings
    starts = [checkpoint_starts(geom, ck) for ck in cks]
    preds = np.stack([ck.points for ck in cks])
    target_leaves, baked_leaves = geom.index().part_leaves(geom.divisor)
    obj, rot, trans = icp_batch(
        preds,
        geom.index().target,
        np.stack([s[0] for s in starts]),
        np.stack([s[1] for s in starts]),
        st.max_iters,
        st.tol,
        target_leaves=target_leaves,
        pred_leaves=baked_leaves,
        pred_maps=jax_part_maps(geom, cks),
        stats=stats,
    )
    best = np.argmin(obj, axis=1)
    return [Registration(float(obj[c, k]), rot[c, k], trans[c, k], int(k), obj[c]) for c, k in enumerate(best)]


def register_exact(geom: TaskGeometry, ck: Checkpoint) -> Registration:
    """The protocol's registration of ``ck``: every start at full resolution."""
    r0, t0 = checkpoint_starts(geom, ck)
    return register_points(
        _full_problem(geom, ck),
        r0,
        t0,
        geom.settings.max_iters,
        geom.settings.tol,
        _own_graph_where_parts_touch(geom.index(), ck.parts),
    )


def register_fast(geom: TaskGeometry, ck: Checkpoint) -> Registration:
    """``fast``'s coarse-to-fine registration of ``ck`` (no escalation; see :mod:`aw_eval.kernels.fast`)."""
    st = geom.settings
    r0, t0 = checkpoint_starts(geom, ck)
    res, start = coarse_to_fine(
        geom.index(), ck.parts, _full_problem(geom, ck), r0, t0, st.max_iters, st.tol, fast_settings()
    )
    return Registration(res.objective, res.rotation, res.translation, start, None)


def near_threshold(result: ScoreResult, settings: ProtocolSettings, margin: float) -> bool:
    """True when a PA/SR or SR^a decision of ``result`` is within a factor ``margin`` of its threshold."""
    e = np.asarray(result.part_errors)
    thr, sra = settings.threshold, settings.sra_threshold
    near_part = np.any((e >= thr / margin) & (e <= thr * margin))
    near_scd = sra / margin <= result.scd <= sra * margin
    return bool(near_part or near_scd)


def escalate(geom: TaskGeometry, ck: Checkpoint, reg: Registration, warm: Registration | None = None) -> Registration:
    """Refine ``reg`` at full resolution with the protocol's iteration budget; keep the better.

    ``warm``: the refined registration of the previous checkpoint of the same trajectory. When
    it is within ``warm_deg`` degrees and ``warm_t`` (:class:`aw_eval.kernels.FastSettings`) of ``reg`` (the same basin: the
    refinement of ``reg`` slides about that far) the refinement starts there instead: one edit
    earlier the same basin's ICP had already converged, so far fewer iterations remain (on
    near-threshold trajectory checkpoints of 8-part box tasks, 3-20 instead of 22-42). Elsewhere
    ``warm`` is ignored and the refinement starts at ``reg``.
    """
    st, fast = geom.settings, fast_settings()
    near = warm is not None and same_basin(
        warm.rotation, warm.translation, reg.rotation, reg.translation, fast.warm_deg, fast.warm_t
    )
    start = warm if near and warm is not None else reg
    res = _full_problem(geom, ck).run(start.rotation, start.translation, st.max_iters, st.tol)
    if res.objective < reg.scd:
        return Registration(res.objective, res.rotation, res.translation, reg.start_index, None)
    return reg


def register(
    pred: ArrayLike,
    target: ArrayLike,
    starts: tuple[ArrayLike, ArrayLike] | None = None,
    settings: ProtocolSettings | None = None,
) -> Registration:
    """Protocol ICP of ``pred (n, 3)`` onto ``target (m, 3)`` from ``starts`` (``(R0 (S, 3, 3),
    t0 (S, 3))``; default: the 24 PCA starts), best objective over starts (ties to the earlier)."""
    settings = settings or ProtocolSettings()
    pts = as_finite(pred, (3,), "pred")
    tgt = as_finite(target, (3,), "target")
    if pts.ndim != 2 or tgt.ndim != 2 or len(pts) < 1 or len(tgt) < 1:
        raise ValueError(f"register takes point sets (n, 3) and (m, 3), got {pts.shape} and {tgt.shape}")
    if starts is None:
        r0, t0 = pca_starts(start_frame(pts), start_frame(tgt))
    else:
        r0 = as_finite(starts[0], (3, 3), "start rotations").reshape(-1, 3, 3)
        t0 = as_finite(starts[1], (3,), "start translations").reshape(-1, 3)
        if len(r0) != len(t0) or len(r0) < 1:
            raise ValueError("starts need as many rotations as translations (at least one)")
    tree_p, tree_t = build_tree(pts), build_tree(tgt)
    prob = ICPProblem(pts, tgt, tree_t=tree_t, tree_p=tree_p, graph_t=graph_for(tree_t), graph_p=graph_for(tree_p))
    return register_points(prob, r0, t0, settings.max_iters, settings.tol)


def check_mode(mode: str) -> None:
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")


def resolve_backend(backend: str, mode: str) -> str:
    """``"numba"`` or ``"jax"`` for ``backend`` in :data:`BACKENDS` and ``mode``: ``auto`` picks
    ``jax`` for ``exact`` where JAX sees a GPU or TPU; ``jax`` runs ``exact`` only (``fast``'s
    pruning is a CPU design)."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "auto":
        return "jax" if mode == "exact" and accelerator_present() else "numba"
    if backend == "jax" and mode != "exact":
        raise ValueError(f"backend 'jax' runs mode 'exact' only, got mode {mode!r}")
    return backend


def register_checkpoint(geom: TaskGeometry, poses: ArrayLike, mode: str = "exact") -> Registration:
    """The protocol's registration of one checkpoint ``poses (P, 7)`` (all starts in ``exact``)."""
    check_mode(mode)
    ck = geom.checkpoint(poses)
    return register_exact(geom, ck) if mode == "exact" else register_fast(geom, ck)
