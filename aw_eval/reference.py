"""The evaluation protocol written plainly with NumPy and ``scipy.spatial.cKDTree``: the oracle.

This module is the readable statement of Appendix A.3 (with the project's documented choices,
see ``docs/evaluator.md``), written the way a careful straightforward implementation does it,
and the baseline every speed ratio in docs/performance.md is taken against: one checkpoint and
one start at a time, two ``cKDTree`` s per registration (target and unmoved prediction, built
once and shared by every start), two tree queries per ICP iteration. The backward direction
queries the target moved by the inverse transform against the unmoved prediction's tree (rigid
motions keep distances), so no tree is built inside the loop; the official scorer registers the
same way (assembly-world-bench ``registration.py``). The fast paths in :mod:`aw_eval.scoring`
are tested against it.

Arrays: a cloud is ``(n, 3)`` float64; part clouds are ``(P, n, 3)``; poses are wire-form
``(P, 7)`` = ``[x, y, z, qw, qx, qy, qz]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from aw.pose import apply_pose, cube_rotations, pca_frame, quat_to_matrix
from aw_eval.settings import ProtocolSettings

__all__ = [
    "kabsch",
    "nn_sq",
    "chamfer",
    "icp",
    "pca_starts",
    "part_starts",
    "register",
    "equivalence_groups",
    "part_cd_matrix",
    "match_parts",
    "score",
    "RefRegistration",
    "RefScore",
]


def kabsch(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Proper rigid ``(R (3, 3), t (3,))`` minimizing ``sum |R src_k + t - dst_k|^2``.

    ``src, dst: (k, 3)`` paired rows, equal weights; no scale; a reflection is corrected by
    flipping the sign of the last singular direction (determinant +1).
    """
    cs = src.mean(axis=0)
    cd = dst.mean(axis=0)
    h = (src - cs).T @ (dst - cd)
    u, _, vt = np.linalg.svd(h)
    d = 1.0 if np.linalg.det(vt.T @ u.T) >= 0 else -1.0
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, cd - r @ cs


def nn_sq(query: np.ndarray, ref: np.ndarray, tree: cKDTree | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Nearest neighbour in ``ref (m, 3)`` of every row of ``query (n, 3)``: ``(index (n,), squared
    distance (n,))``; squared distances are recomputed from coordinates (not from the tree)."""
    tree = cKDTree(ref) if tree is None else tree
    _, idx = tree.query(query)
    idx = np.asarray(idx)
    return idx, np.sum((query - ref[idx]) ** 2, axis=1)


def chamfer(x: np.ndarray, y: np.ndarray) -> float:
    """Squared bidirectional Chamfer distance (eq. 1) of ``x (n, 3)`` and ``y (m, 3)``."""
    return float(nn_sq(x, y)[1].mean() + nn_sq(y, x)[1].mean())


def _objective(p: np.ndarray, t_pts: np.ndarray, tree_t: cKDTree, tree_p: cKDTree, r: np.ndarray, t: np.ndarray):
    """SCD of ``R p + t`` against ``t_pts`` with the forward and backward neighbour indices.

    Backward: the nearest moved point ``R p_j + t`` to ``t_k`` is the nearest ``p_j`` to
    ``R^T (t_k - t)``, so the unmoved prediction's tree answers it; its squared distance is
    recomputed in the target frame, like the forward one."""
    x = p @ r.T + t
    fwd, dfwd = nn_sq(x, t_pts, tree_t)
    _, bwd = tree_p.query((t_pts - t) @ r)
    dbwd = np.sum((t_pts - x[bwd]) ** 2, axis=1)
    return float(dfwd.mean() + dbwd.mean()), fwd, bwd


def icp(
    p,
    t_pts,
    r0,
    t0,
    max_iters: int = 100,
    tol: float = 1e-9,
    tree_t: cKDTree | None = None,
    tree_p: cKDTree | None = None,
):
    """Symmetric ICP of ``p (n, 3)`` onto ``t_pts (m, 3)`` from ``(r0, t0)``.

    Each iteration fits ONE proper Kabsch transform of the original ``p`` to ``t_pts`` on the
    forward pairs ``(p_j, t_fwd(j))`` and the backward pairs ``(p_bwd(k), t_k)`` together, taken
    at the current transform. Stops after ``max_iters`` fits or when ``prev - new < tol`` (a
    worsening also stops). Returns ``(best objective, R, t)``: the best state it visited.
    """
    tree_t = cKDTree(t_pts) if tree_t is None else tree_t
    tree_p = cKDTree(p) if tree_p is None else tree_p
    obj, fwd, bwd = _objective(p, t_pts, tree_t, tree_p, r0, t0)
    best = (obj, r0, t0)
    prev = obj
    for _ in range(max_iters):
        src = np.concatenate([p, p[bwd]])
        dst = np.concatenate([t_pts[fwd], t_pts])
        r, t = kabsch(src, dst)
        new, fwd, bwd = _objective(p, t_pts, tree_t, tree_p, r, t)
        if new < best[0]:
            best = (new, r, t)
        if prev - new < tol:
            break
        prev = new
    return best


def pca_starts(pred: np.ndarray, target: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The 24 PCA starts ``(R0, t0)``: ``R0 = A_T S A_P^T``, ``t0 = mu_T - R0 mu_P`` for every
    ``S`` in :data:`aw_eval.starts.CUBE` order, frames by :func:`aw_eval.starts.start_frame`
    (the official scorer's order and frames)."""
    from aw_eval.starts import CUBE, start_frame

    mu_p, a_p = start_frame(pred)
    mu_t, a_t = start_frame(target)
    out = []
    for s in CUBE:
        r0 = a_t @ s @ a_p.T
        out.append((r0, mu_t - r0 @ mu_p))
    return out


def part_starts(poses: np.ndarray, target_poses: np.ndarray, divisor: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Same-ID starts in part order: ``R0 = R*_i R_i^T``, ``t0 = (t*_i - R0 t_i) / divisor`` maps
    predicted part ``i`` exactly onto target part ``i`` (normalized units)."""
    out = []
    for pose, tgt in zip(poses, target_poses, strict=True):
        r0 = quat_to_matrix(tgt[3:]) @ quat_to_matrix(pose[3:]).T
        out.append((r0, (tgt[:3] - r0 @ pose[:3]) / divisor))
    return out


@dataclass
class RefRegistration:
    scd: float
    rotation: np.ndarray  # (3, 3)
    translation: np.ndarray  # (3,)
    start_index: int  # position in the start list
    objectives: np.ndarray  # (S,) best objective of every start


def register(pred: np.ndarray, target: np.ndarray, starts, settings: ProtocolSettings) -> RefRegistration:
    """Best ICP result over ``starts`` (lowest objective, ties to the earlier start)."""
    tree_t, tree_p = cKDTree(target), cKDTree(pred)
    objs = []
    best: tuple[float, np.ndarray, np.ndarray, int] | None = None
    for k, (r0, t0) in enumerate(starts):
        obj, r, t = icp(pred, target, r0, t0, settings.max_iters, settings.tol, tree_t, tree_p)
        objs.append(obj)
        if best is None or obj < best[0]:
            best = (obj, r, t, k)
    if best is None:
        raise ValueError("register needs at least one start")
    return RefRegistration(best[0], best[1], best[2], best[3], np.asarray(objs))


def equivalence_groups(clouds: np.ndarray, divisor: float, settings: ProtocolSettings) -> list[list[int]]:
    """Groups of interchangeable parts: each part's normalized cloud in its own PCA frame,
    ``q_i = A_i^T (c_i - mu_i) / divisor``; every pair ``i < j`` registered ``q_i -> q_j`` with
    the 24 starts ``(S, 0)``; an edge where the best CD <= ``equiv_cd``; groups = connected
    components, each sorted, ordered by first member."""
    n = len(clouds)
    qs = []
    for c in clouds:
        mu, a = pca_frame(c)
        qs.append(((c - mu) @ a) / divisor)
    starts = [(s, np.zeros(3)) for s in cube_rotations()]
    parent = list(range(n))

    def find(i):
        while parent[i] != i:
            i = parent[i]
        return i

    for i in range(n):
        for j in range(i + 1, n):
            reg = register(qs[i], qs[j], starts, settings)
            if reg.scd <= settings.equiv_cd:
                ri, rj = find(i), find(j)
                parent[max(ri, rj)] = min(ri, rj)
    comps: dict[int, list[int]] = {}
    for i in range(n):
        comps.setdefault(find(i), []).append(i)
    return sorted((sorted(g) for g in comps.values()), key=lambda g: g[0])


def part_cd_matrix(pred_parts: np.ndarray, target_parts: np.ndarray, groups) -> np.ndarray:
    """``C (P, P)``: ``C[i, j]`` = CD(pred part i, target part j) within groups, ``inf`` across."""
    p = len(pred_parts)
    c = np.full((p, p), np.inf)
    for g in groups:
        for i in g:
            for j in g:
                c[i, j] = chamfer(pred_parts[i], target_parts[j])
    return c


def match_parts(cost: np.ndarray, groups) -> tuple[np.ndarray, np.ndarray]:
    """Hungarian assignment within each group: ``(assignment (P,), errors (P,))``."""
    p = len(cost)
    assign = np.arange(p)
    for g in groups:
        g = np.asarray(g)
        rows, cols = linear_sum_assignment(cost[np.ix_(g, g)])
        assign[g[rows]] = g[cols]
    return assign, cost[np.arange(p), assign]


@dataclass
class RefScore:
    pa: float
    sr: bool
    scd: float
    sra: bool
    part_errors: np.ndarray  # (P,)
    assignment: np.ndarray  # (P,)
    registration: RefRegistration


def score(clouds, target_poses, divisor, groups, poses, settings: ProtocolSettings) -> RefScore:
    """Score one checkpoint.

    ``clouds (P, n, 3)`` baked-frame samples, ``target_poses (P, 7)``, ``poses (P, 7)``.
    """
    clouds = np.asarray(clouds, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    target_poses = np.asarray(target_poses, dtype=np.float64)
    pred_parts = apply_pose(poses, clouds) / divisor
    target_parts = apply_pose(target_poses, clouds) / divisor
    pred = pred_parts.reshape(-1, 3)
    target = target_parts.reshape(-1, 3)
    starts = pca_starts(pred, target) + part_starts(poses, target_poses, divisor)
    reg = register(pred, target, starts, settings)
    moved = pred_parts @ reg.rotation.T + reg.translation
    cost = part_cd_matrix(moved, target_parts, groups)
    assign, errors = match_parts(cost, groups)
    ok = errors <= settings.threshold
    return RefScore(
        pa=float(ok.mean()),
        sr=bool(ok.all()),
        scd=reg.scd,
        sra=bool(reg.scd < settings.sra_threshold),
        part_errors=errors,
        assignment=assign,
        registration=reg,
    )
