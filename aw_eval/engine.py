"""Scoring of checkpoints: registration, part matching and metrics (``exact`` and ``fast`` modes).

``exact`` runs every start of the protocol at full resolution with the same arithmetic as
:mod:`aw_eval.reference` (so results equal the reference's), with certified warm-started
neighbours (:mod:`aw_eval.kernels.icp`) in search structures built once per task (the target's, the
parts' baked clouds'); a prediction whose parts touch gets its own Delaunay graph after the
first start (:data:`CONTACT_WALKS`). ``fast`` (:mod:`aw_eval.kernels.fast`) prunes starts coarse-to-fine.

Scoring one checkpoint (:func:`score`) is a pure function of ``(geometry, poses, mode)``. A batch
(:func:`score_batch`) removes duplicate rows; in ``fast`` mode it also reads its rows as a
trajectory (a near-threshold refinement may start from the previous row's), so a batch is a pure
function of its rows in order: any worker layout gives identical numbers.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from aw.pose import as_finite, cube_rotations, pca_frame, quat_to_matrix
from aw_eval.chamfer import chamfer_pairs
from aw_eval.geometry import TaskGeometry
from aw_eval.kernels.icp import ICPProblem, graph_for, nearest_positions
from aw_eval.kernels.kdtree import build_tree
from aw_eval.kernels.partwalk import PartClouds, build_part_clouds
from aw_eval.results import BatchScores, Registration, ScoreResult, match_within_groups

__all__ = ["task_context", "starts_for", "prediction_problem", "register_points", "register", "register_checkpoint", "finalize", "score", "score_batch", "part_diagnostics",
           "PartDiagnostics", "MODES"]

MODES = ("exact", "fast")


@dataclass
class TaskContext:
    """Per-process derived structures of a task (never pickled)."""

    target_parts: np.ndarray  # (P, n, 3) normalized
    target: np.ndarray  # (P * n, 3)
    tree_t: object  # KD-tree of ``target``
    target_frame: tuple[np.ndarray, np.ndarray]  # pca_frame(target)
    pairs: np.ndarray  # (G, 2) (i, j) pairs inside groups, row-major per group
    part_trees: list | None = None  # KD-trees of the target parts (built on first use)
    part_graphs: list | None = None  # their Delaunay graphs (None entries: Qhull could not)
    baked: list | None = None  # (KD-tree, graph) of every part's cloud in its baked frame (unnormalized)
    target_boxes: tuple | None = None  # per-part axis-aligned boxes of the target parts
    target_means: np.ndarray | None = None  # (P, 3) per-part means of the target parts
    part_clouds: PartClouds | None = None  # ``baked`` joined for assembly searches (None: a part has no graph)
    _graph_t: object = False  # Delaunay graph of ``tree_t``'s points (None: Qhull could not)

    @property
    def graph_t(self):
        """Delaunay graph of the target in tree order, built on first use (``None`` if Qhull cannot)."""
        if self._graph_t is False:
            self._graph_t = graph_for(self.tree_t)
        return self._graph_t


def task_context(geom: TaskGeometry) -> TaskContext:
    ctx = geom._derived.get("ctx")
    if ctx is None:
        tp = geom.target_parts()
        target = np.ascontiguousarray(tp.reshape(-1, 3))
        pairs = [(i, j) for g in geom.groups for i in g for j in g]
        ctx = TaskContext(tp, target, build_tree(target), pca_frame(target), np.asarray(pairs, dtype=np.int64).reshape(-1, 2))
        geom._derived["ctx"] = ctx
    return ctx


_CUBE = cube_rotations()  # exact 0/+-1 entries: computing them once changes no number


def starts_for(pred: np.ndarray, target_frame, poses: np.ndarray, target_poses: np.ndarray, divisor: float,
               rotations: tuple[np.ndarray, np.ndarray] | None = None):
    """All starts ``(R0 (S, 3, 3), t0 (S, 3))``: 24 PCA starts then one same-ID start per part.

    Same arithmetic, in the same order, as :func:`aw_eval.reference.pca_starts` and
    :func:`aw_eval.reference.part_starts`. ``rotations``: the matrices of ``poses`` and
    ``target_poses`` ``(P, 3, 3)`` where the caller has them already.
    """
    mu_p, a_p = pca_frame(pred)
    mu_t, a_t = target_frame
    r_pca = a_t @ _CUBE @ a_p.T  # (24, 3, 3)
    t_pca = mu_t - r_pca @ mu_p
    if rotations is None:
        rotations = (quat_to_matrix(poses[:, 3:]), quat_to_matrix(target_poses[:, 3:]))
    r_part = rotations[1] @ np.swapaxes(rotations[0], 1, 2)  # (P, 3, 3)
    t_part = (target_poses[:, :3] - (r_part @ poses[:, :3, None])[:, :, 0]) / divisor
    return np.concatenate([r_pca, r_part]), np.concatenate([t_pca, t_part])


def checkpoint_rotations(geom: TaskGeometry, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotation matrices of a checkpoint's ``poses (P, 7)`` and of the task's target poses,
    as :func:`starts_for` takes them (computed once per checkpoint and task)."""
    return geom.rotations(poses), geom.target_rotations()


def register_points(prob: ICPProblem, r0: np.ndarray, t0: np.ndarray, max_iters: int, tol: float,
                    after_first=None) -> Registration:
    """Every start refined by the protocol's ICP; the lowest objective wins, ties to the earlier.
    ``after_first``: optional ``(problem, first start's ICPResult) -> problem`` for the remaining
    starts (the same registration problem with another search structure: same answers)."""
    objs = np.empty(len(r0))
    best = None
    for k in range(len(r0)):
        res = prob.run(r0[k], t0[k], max_iters, tol)
        objs[k] = res.objective
        if best is None or res.objective < best[0]:
            best = (res.objective, res.rotation, res.translation, k)
        if k == 0 and after_first is not None:
            prob = after_first(prob, res)
    return Registration(float(best[0]), best[1], best[2], int(best[3]), objs)


def _part_structures(geom: TaskGeometry, ctx: TaskContext) -> None:
    """Per-task search structures of the parts (built once): the normalized target parts and
    every part's cloud in its baked frame, which a checkpoint's prediction only moves rigidly."""
    if ctx.part_trees is None:
        ctx.part_trees = [build_tree(t) for t in ctx.target_parts]
        ctx.part_graphs = [graph_for(t) for t in ctx.part_trees]
        ctx.target_boxes = (ctx.target_parts.min(axis=1), ctx.target_parts.max(axis=1))
        ctx.target_means = ctx.target_parts.mean(axis=1)
        ctx.baked = [(tree, graph_for(tree)) for tree in (build_tree(c) for c in geom.clouds)]
        ctx.part_clouds = build_part_clouds(ctx.baked)


def prediction_problem(geom: TaskGeometry, ctx: TaskContext, poses: np.ndarray, pred_parts: np.ndarray) -> ICPProblem:
    """Full-resolution ICP of a checkpoint ``poses (P, 7)`` onto the task's target. The backward
    search walks the parts' baked clouds (per task, :mod:`aw_eval.kernels.partwalk`): nothing is built
    per checkpoint. Where a part has no Delaunay graph, the prediction gets its own tree and
    graph (same results, slower)."""
    _part_structures(geom, ctx)
    if ctx.part_clouds is not None:
        return ICPProblem.for_assembly(pred_parts, poses, geom.divisor, ctx.part_clouds, ctx.target, tree_t=ctx.tree_t,
                                       graph_t=ctx.graph_t, rotations=geom.rotations(poses))
    return _own_structures_problem(ctx, pred_parts)[0]


def _own_structures_problem(ctx: TaskContext, pred_parts: np.ndarray) -> tuple[ICPProblem, bool]:
    """ICP of the prediction ``pred_parts (P, n, 3)`` searched through its own KD-tree and
    Delaunay graph (built here, per checkpoint); the flag says whether Qhull gave a graph."""
    tree_p = build_tree(pred_parts.reshape(-1, 3))
    graph_p = graph_for(tree_p)
    prob = ICPProblem(tree_p.points, ctx.target, tree_t=ctx.tree_t, tree_p=tree_p, graph_t=ctx.graph_t, graph_p=graph_p)
    return prob, graph_p is not None


def _part_cd(ctx: TaskContext, moved_parts: np.ndarray, to_baked: tuple, i: int, j: int) -> float:
    """CD(registered pred part i, target part j) with squared distances from normalized
    coordinates, as the reference computes them. Forward: the target part's tree and graph (per
    task); backward: the target points mapped into part i's baked frame by ``to_baked = (A (P, 3,
    3), b (P, 3))`` (``c = A y + b``), searched in the baked cloud's tree and graph (per task)."""
    tree_t, tree_b, graph_b = ctx.part_trees[j], *ctx.baked[i]
    # queries in their own trees' order: consecutive queries are neighbours in space, so each
    # walk starts next to its answer (FPS order would jump across the part)
    x, y = moved_parts[i][tree_b.index], tree_t.points
    fwd = nearest_positions(tree_t, ctx.part_graphs[j], x)
    a, b = to_baked
    bwd = nearest_positions(tree_b, graph_b, y @ a[i].T + b[i])  # tree positions of part i = rows of x
    return mean_squared_norm(x - tree_t.points[fwd]) + mean_squared_norm(y - x[bwd])


def mean_squared_norm(d: np.ndarray) -> float:
    """``mean(sum(d * d, axis=1))`` of ``d (k, 3)``, the same sums in the same order (each row's
    ``(d0^2 + d1^2) + d2^2``, then NumPy's mean) without the slow short-axis reduction."""
    s = d[:, 0] * d[:, 0]
    s += d[:, 1] * d[:, 1]
    s += d[:, 2] * d[:, 2]
    return float(np.mean(s))


def _box_gap_sq(point: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    d = np.maximum(0.0, np.maximum(lo - point, point - hi))
    return float(d @ d)


def match_parts(ctx: TaskContext, moved_parts: np.ndarray, groups, to_baked: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Hungarian assignment within groups on the part CDs: ``(assignment (P,), errors (P,))``.
    ``to_baked``: the maps of normalized registered coordinates into each part's baked frame
    (see :func:`_part_cd`); :func:`_part_structures` must have run.

    Inside a group, pairs start at a proven lower bound (``forward >= dist(mean X, box Y)^2``
    by Jensen's inequality, likewise backward) and only the pairs an optimal assignment uses
    are computed exactly, until it uses exact costs alone: that assignment is then optimal for
    the exact costs too, so far-apart pairs are never computed.
    """
    p = moved_parts.shape[0]
    assign = np.arange(p)
    errors = np.empty(p)
    tm, (tlo, thi) = ctx.target_means, ctx.target_boxes
    pm = plo = phi = None
    for g in groups:
        g = list(g)
        if len(g) == 1:
            i = g[0]
            errors[i] = _part_cd(ctx, moved_parts, to_baked, i, i)
            continue
        k = len(g)
        if pm is None:  # only groups of equivalent parts need the bounds
            pm, plo, phi = moved_parts.mean(axis=1), moved_parts.min(axis=1), moved_parts.max(axis=1)
        cost = np.array([[_box_gap_sq(pm[i], tlo[j], thi[j]) + _box_gap_sq(tm[j], plo[i], phi[i]) for j in g] for i in g])
        exact = np.zeros((k, k), dtype=bool)
        while True:
            cols = match_within_groups(cost, [list(range(k))])[0]
            todo = [(a, cols[a]) for a in range(k) if not exact[a, cols[a]]]
            if not todo:
                break
            for a, c in todo:
                cost[a, c] = _part_cd(ctx, moved_parts, to_baked, g[a], g[c])
                exact[a, c] = True
        for a in range(k):
            assign[g[a]] = g[cols[a]]
            errors[g[a]] = cost[a, cols[a]]
    return assign, errors


def finalize(geom: TaskGeometry, ctx: TaskContext, poses: np.ndarray, pred_parts: np.ndarray, reg: Registration,
             mode: str) -> ScoreResult:
    """Metrics of a registered checkpoint ``poses (P, 7)``: part CDs, Hungarian within groups,
    PA/SR/SCD/SR^a."""
    st = geom.settings
    moved = pred_parts @ reg.rotation.T + reg.translation
    _part_structures(geom, ctx)
    # registered normalized y = R_reg (R_i c + t_i) / div + t_reg  <=>  c = A_i y + b_i
    rot_i = geom.rotations(poses)
    a = geom.divisor * np.einsum("pji,kj->pik", rot_i, reg.rotation)  # div R_i^T R_reg^T
    b = -np.einsum("pji,pj->pi", rot_i, geom.divisor * (reg.rotation.T @ reg.translation) + poses[:, :3])
    assign, errors = match_parts(ctx, moved, geom.groups, (a, b))
    ok = errors <= st.threshold
    return ScoreResult(
        pa=float(ok.mean()),
        sr=bool(ok.all()),
        scd=float(reg.scd),
        sra=bool(reg.scd < st.sra_threshold),
        part_errors=errors,
        assignment=assign,
        reg_rotation=np.asarray(reg.rotation, dtype=np.float64),
        reg_translation=np.asarray(reg.translation, dtype=np.float64),
        start_index=int(reg.start_index),
        mode=mode,
    )


# Part walks per backward search from which a prediction gets its own Delaunay graph (see
# _own_graph_where_parts_touch). Measured on the first start (benchmarks/profile_icp.py and the
# box final states of bench_score.py): 1.04-1.16 on the benchmark checkpoints, whose own graph
# would cost more to build (0.08-1.2 s) than it saves (net -0.13 to -0.32 s); 1.47-1.53 on box
# assemblies whose parts touch face to face, where it saves 1.1-2.0 s of 4.5-5.7 s.
CONTACT_WALKS = 1.3


def _own_graph_where_parts_touch(ctx: TaskContext, pred_parts: np.ndarray):
    """``after_first`` hook of :func:`register_points` for ``exact``: where the first start's
    backward search walked more than ``CONTACT_WALKS`` parts per query (parts in contact: every
    query near a contact walks both parts), the remaining starts search the prediction's own
    Delaunay graph instead (the union's Voronoi cells need one walk; a Qhull build per
    checkpoint). The neighbours are exact either way; only the objective's summation order
    changes (last digits)."""

    def after_first(prob: ICPProblem, first) -> ICPProblem:
        if first.part_searches == 0 or first.part_walks <= CONTACT_WALKS * first.part_searches:
            return prob
        own, has_graph = _own_structures_problem(ctx, pred_parts)
        return own if has_graph else prob

    return after_first


def _register_exact(geom: TaskGeometry, ctx: TaskContext, poses: np.ndarray, pred_parts: np.ndarray) -> Registration:
    pred = np.ascontiguousarray(pred_parts.reshape(-1, 3))
    r0, t0 = starts_for(pred, ctx.target_frame, poses, geom.target_poses, geom.divisor, checkpoint_rotations(geom, poses))
    prob = prediction_problem(geom, ctx, poses, pred_parts)
    return register_points(prob, r0, t0, geom.settings.max_iters, geom.settings.tol,
                           _own_graph_where_parts_touch(ctx, pred_parts))


def register(pred, target, starts=None, settings=None) -> Registration:
    """Protocol ICP of ``pred (n, 3)`` onto ``target (m, 3)`` from ``starts`` (``(R0 (S, 3, 3),
    t0 (S, 3))``; default: the 24 PCA starts), best objective over starts (ties to the earlier)."""
    from aw_eval.settings import ProtocolSettings

    settings = settings or ProtocolSettings()
    pred = as_finite(pred, (3,), "pred")
    target = as_finite(target, (3,), "target")
    if pred.ndim != 2 or target.ndim != 2 or len(pred) < 1 or len(target) < 1:
        raise ValueError(f"register takes point sets (n, 3) and (m, 3), got {pred.shape} and {target.shape}")
    if starts is None:
        r0, t0 = starts_for(pred, pca_frame(target), np.zeros((0, 7)), np.zeros((0, 7)), 1.0)
    else:
        r0 = as_finite(starts[0], (3, 3), "start rotations").reshape(-1, 3, 3)
        t0 = as_finite(starts[1], (3,), "start translations").reshape(-1, 3)
        if len(r0) != len(t0) or len(r0) < 1:
            raise ValueError("starts need as many rotations as translations (at least one)")
    tree_p, tree_t = build_tree(pred), build_tree(target)
    prob = ICPProblem(pred, target, tree_t=tree_t, tree_p=tree_p, graph_t=graph_for(tree_t), graph_p=graph_for(tree_p))
    return register_points(prob, r0, t0, settings.max_iters, settings.tol)


def register_checkpoint(geom: TaskGeometry, poses, mode: str = "exact") -> Registration:
    """The protocol's registration of one checkpoint ``poses (P, 7)`` (all starts in ``exact``)."""
    _check_mode(mode)
    poses = geom.check_poses(poses)
    ctx = task_context(geom)
    pred_parts = geom.pred_parts(poses)
    if mode == "exact":
        return _register_exact(geom, ctx, poses, pred_parts)
    from aw_eval.kernels.fast import register_fast

    return register_fast(geom, ctx, poses, pred_parts)


def _check_mode(mode: str) -> None:
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")


def score(geom: TaskGeometry, poses, mode: str = "exact") -> ScoreResult:
    """Score one checkpoint ``poses (P, 7)`` (scored parts, in ``geom.part_ids`` order)."""
    _check_mode(mode)
    poses = geom.check_poses(poses)
    if poses.ndim != 2:
        raise ValueError(f"score takes one checkpoint (P, 7); use score_batch for {poses.shape}")
    return _score_one(geom, poses, mode, None)[0]


def _score_one(geom: TaskGeometry, poses: np.ndarray, mode: str, warm: Registration | None) -> tuple[ScoreResult, Registration | None]:
    """Score checked ``poses (P, 7)``; returns the result and, in ``fast`` mode, the refined
    registration when the checkpoint was near a threshold (else ``None``): the next checkpoint
    of a trajectory passes it back as ``warm`` (see :func:`aw_eval.kernels.fast.escalate`)."""
    ctx = task_context(geom)
    pred_parts = geom.pred_parts(poses)
    if mode == "exact":
        reg = _register_exact(geom, ctx, poses, pred_parts)
        return finalize(geom, ctx, poses, pred_parts, reg, mode), None
    from aw_eval.kernels import fast

    reg = fast.register_fast(geom, ctx, poses, pred_parts, fast.FAST)
    res = finalize(geom, ctx, poses, pred_parts, reg, mode)
    refined = None
    if fast.FAST.margin > 1 and fast.near_threshold(res, geom.settings, fast.FAST.margin):
        refined = fast.escalate(geom, ctx, poses, pred_parts, reg, warm)
        res = finalize(geom, ctx, poses, pred_parts, refined, mode)
    if fast.FAST.exact_margin > 1 and fast.near_threshold(res, geom.settings, fast.FAST.exact_margin):
        # a knife-edge decision: the last digits of the registration decide it, so only the
        # protocol's own registration (every start at full resolution) gives the protocol's answer
        res = finalize(geom, ctx, poses, pred_parts, _register_exact(geom, ctx, poses, pred_parts), mode)
    return res, refined


def score_batch(geom: TaskGeometry, poses, mode: str = "exact", progress=None) -> BatchScores:
    """Score ``poses (N, P, 7)`` in row order (identical rows are scored once, at their first
    occurrence). ``exact`` rows equal :func:`score`'s. In ``fast`` mode the rows are taken as a
    trajectory: a row refined near a threshold starts its refinement from the previous row's
    refined registration when both lie in the same basin (consecutive checkpoints differ by one
    edit; :func:`aw_eval.kernels.fast.escalate`), so a fast row depends on the row before it: the same
    batch gives the same numbers in any process or worker layout, but splitting a trajectory
    into other batches may change the last digits of a refined row.

    ``progress``: optional callable ``(done, total)`` called after each unique row.
    """
    _check_mode(mode)
    poses = geom.check_poses(poses)
    if poses.ndim != 3:
        raise ValueError(f"score_batch takes (N, P, 7) poses, got {poses.shape}")
    n = poses.shape[0]
    if n == 0:
        empty = ScoreResult(0.0, False, 0.0, False, np.zeros(geom.n_parts), np.arange(geom.n_parts), np.eye(3), np.zeros(3), 0)
        out = BatchScores.stack([empty], mode, 0)
        return BatchScores(**{k: (v[:0] if isinstance(v, np.ndarray) else v) for k, v in out.__dict__.items()})
    flat = np.ascontiguousarray(poses.reshape(n, -1))
    _, first, inverse = np.unique(flat, axis=0, return_index=True, return_inverse=True)
    t0 = time.perf_counter()
    results = {}
    warm = None
    for done, k in enumerate(sorted(first)):
        results[k], warm = _score_one(geom, poses[k], mode, warm)
        if progress is not None:
            progress(done + 1, len(first))
    by_unique = [results[k] for k in first]
    rows = [by_unique[u] for u in np.asarray(inverse).reshape(-1)]
    return BatchScores.stack(rows, mode, len(first), {"seconds": time.perf_counter() - t0})


@dataclass
class PartDiagnostics:
    """Per-part diagnostics of Appendix C.2 under the saved registration and matching (``(P,)``):

    - ``offset``: distance between the centroids of registered pred part ``i`` and of its matched
      target part (normalized units: the largest part's PCA box diagonal is 1);
    - ``centred_cd``: CD of the two clouds after moving each to zero mean (orientation and shape
      error without translation);
    - ``never_moved``: the pose equals the identity initial pose.
    """

    offset: np.ndarray
    centred_cd: np.ndarray
    never_moved: np.ndarray
    part_errors: np.ndarray
    assignment: np.ndarray

    @property
    def moved(self) -> np.ndarray:
        return ~self.never_moved


def _row(result, row: int | None) -> ScoreResult:
    if isinstance(result, BatchScores):
        if row is None:
            if len(result) != 1:
                raise ValueError("part_diagnostics on a BatchScores needs the row index")
            row = 0
        return result.row(int(row))
    return result


def part_diagnostics(geom: TaskGeometry, poses, result, row: int | None = None, atol: float = 1e-9) -> PartDiagnostics:
    """Diagnostics of one checkpoint ``poses (P, 7)`` scored as ``result`` (a :class:`ScoreResult`,
    or a :class:`BatchScores` with ``row``)."""
    res = _row(result, row)
    poses = geom.check_poses(poses)
    if poses.ndim != 2:
        raise ValueError(f"part_diagnostics takes one checkpoint (P, 7), got {poses.shape}")
    ctx = task_context(geom)
    moved = geom.pred_parts(poses) @ res.reg_rotation.T + res.reg_translation
    matched = ctx.target_parts[res.assignment]
    mc, tc = moved.mean(axis=1), matched.mean(axis=1)
    offset = np.linalg.norm(mc - tc, axis=1)
    centred = chamfer_pairs(moved - mc[:, None, :], matched - tc[:, None, :])
    q = poses[:, 3:] / np.linalg.norm(poses[:, 3:], axis=1, keepdims=True)
    never = (np.abs(poses[:, :3]).max(axis=1) <= atol) & (np.abs(np.abs(q[:, 0]) - 1.0) <= atol)
    return PartDiagnostics(offset, centred, never, np.asarray(res.part_errors), np.asarray(res.assignment))

