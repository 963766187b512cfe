"""Source-level fracture protocol (Fantastic Breaks / Breaking Bad comparisons, Appendix A.3).

- 5000 area-weighted surface samples across parts: part ``i`` gets ``max(20, floor(5000 A_i /
  sum A))``, and the remainder (positive or negative) goes to the largest allocation (first on
  ties); part ``i`` samples with :func:`aw_eval.sampling.part_seed` ``(seed, i)``.
- Scale: every coordinate is divided by ``max(1, e_max)``, ``e_max`` the largest axis-aligned
  extent of any part in its target (source) placement.
- One shared transform puts the anchor (the part with the most samples, first on ties) exactly
  at its target; part identities stay fixed and the anchor is included in every average.
- RE = mean over parts of ``sqrt(|dphi|^2 / 3)``, ``dphi`` the per-component intrinsic-XYZ Euler
  differences in degrees, each wrapped to ``min(d, 360 - d)``; TE likewise on the differences of
  sampled centroids. PA: fraction of parts with part CD (pred part vs its own target part)
  strictly below 0.01. CD: for each part, the mean squared distance of its predicted samples to
  the nearest sample of the whole target assembly plus the mean squared distance of its target
  samples to the nearest sample of the whole predicted assembly; then the mean over parts.

Display multipliers (x100 TE, x1000 CD) belong to reports, not here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from aw.pose import apply_pose, as_finite, euler_xyz_from_matrix, quat_to_matrix
from aw_eval.sampling import part_seed, surface_samples

__all__ = ["FractureMetrics", "allocate_samples", "fracture_metrics", "fracture_metrics_from_samples", "wrapped_euler_error"]


@dataclass
class FractureMetrics:
    re: float  # degrees
    te: float  # scaled units
    pa: float  # fraction of parts with part CD < pa_threshold
    cd: float  # shape CD (scaled units squared)
    part_re: np.ndarray  # (P,)
    part_te: np.ndarray  # (P,)
    part_cd: np.ndarray  # (P,) CD of each part with its own target part
    shape_cd: np.ndarray  # (P,) global-neighbour CD terms per part
    anchor: int
    scale: float
    counts: np.ndarray  # (P,) samples per part


def allocate_samples(areas, total: int = 5000, minimum: int = 20) -> np.ndarray:
    """Samples per part ``(P,)`` by area with at least ``minimum`` each; remainder to the largest."""
    a = as_finite(areas, None, "areas").reshape(-1)
    if a.size == 0 or np.any(a < 0) or a.sum() <= 0:
        raise ValueError("areas must be non-negative with a positive sum")
    if minimum * a.size > total:
        raise ValueError(f"{a.size} parts need at least {minimum * a.size} samples, more than total={total}")
    n = np.maximum(minimum, np.floor(total * a / a.sum()).astype(np.int64))
    n[int(np.argmax(n))] += total - int(n.sum())
    if n.min() < minimum:
        raise ValueError("cannot honour the per-part minimum with this total")
    return n


def wrapped_euler_error(r_pred: np.ndarray, r_target: np.ndarray) -> np.ndarray:
    """Per-part ``sqrt(|dphi|^2 / 3)`` in degrees for rotations ``(P, 3, 3)``, components wrapped."""
    e_p = np.degrees(euler_xyz_from_matrix(r_pred))
    e_t = np.degrees(euler_xyz_from_matrix(r_target))
    d = np.abs(e_p - e_t) % 360.0
    d = np.minimum(d, 360.0 - d)
    return np.sqrt(np.sum(d * d, axis=-1) / 3.0)


def _nn_sq(query: np.ndarray, ref: np.ndarray) -> np.ndarray:
    _, idx = cKDTree(ref).query(query)
    return np.sum((query - ref[idx]) ** 2, axis=1)


def fracture_metrics_from_samples(samples, pred_poses, target_poses, scale: float = 1.0, pa_threshold: float = 0.01) -> FractureMetrics:
    """Fracture metrics from per-part samples (list of ``(n_i, 3)`` in the part's own frame),
    ``pred_poses (P, 7)`` and ``target_poses (P, 7)``; coordinates are divided by ``scale``."""
    samples = [as_finite(s, (3,), "samples") for s in samples]
    p = len(samples)
    pred_poses = as_finite(pred_poses, (7,), "pred_poses").reshape(-1, 7)
    target_poses = as_finite(target_poses, (7,), "target_poses").reshape(-1, 7)
    if p < 1 or pred_poses.shape[0] != p or target_poses.shape[0] != p or any(len(s) < 1 for s in samples):
        raise ValueError("need one non-empty sample set and one pred/target pose per part")
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError("scale must be positive")
    counts = np.array([len(s) for s in samples])
    anchor = int(np.argmax(counts))
    r_p = quat_to_matrix(pred_poses[:, 3:])
    r_t = quat_to_matrix(target_poses[:, 3:])
    # The shared transform g = target_anchor o pred_anchor^-1 (exact on the anchor).
    r_g = r_t[anchor] @ r_p[anchor].T
    t_g = target_poses[anchor, :3] - r_g @ pred_poses[anchor, :3]
    r_aligned = r_g @ r_p
    pred_pts = [(apply_pose(pred_poses[i], samples[i]) @ r_g.T + t_g) / scale for i in range(p)]
    tgt_pts = [apply_pose(target_poses[i], samples[i]) / scale for i in range(p)]

    part_re = wrapped_euler_error(r_aligned, r_t)
    dc = np.stack([a.mean(axis=0) - b.mean(axis=0) for a, b in zip(pred_pts, tgt_pts)])
    part_te = np.sqrt(np.sum(dc * dc, axis=1) / 3.0)
    part_cd = np.array([_nn_sq(a, b).mean() + _nn_sq(b, a).mean() for a, b in zip(pred_pts, tgt_pts)])
    all_pred = np.concatenate(pred_pts)
    all_tgt = np.concatenate(tgt_pts)
    fwd = _nn_sq(all_pred, all_tgt)
    bwd = _nn_sq(all_tgt, all_pred)
    bounds = np.concatenate([[0], np.cumsum(counts)])
    shape_cd = np.array([fwd[bounds[i]:bounds[i + 1]].mean() + bwd[bounds[i]:bounds[i + 1]].mean() for i in range(p)])
    return FractureMetrics(
        re=float(part_re.mean()),
        te=float(part_te.mean()),
        pa=float(np.mean(part_cd < pa_threshold)),
        cd=float(shape_cd.mean()),
        part_re=part_re,
        part_te=part_te,
        part_cd=part_cd,
        shape_cd=shape_cd,
        anchor=anchor,
        scale=float(scale),
        counts=counts,
    )


def fracture_metrics(meshes: list[trimesh.Trimesh], pred_poses, target_poses, total: int = 5000, minimum: int = 20,
                     seed: int = 0, pa_threshold: float = 0.01) -> FractureMetrics:
    """The fracture protocol for part ``meshes`` (in the frame the poses act on)."""
    if not meshes:
        raise ValueError("need at least one part mesh")
    target_poses = as_finite(target_poses, (7,), "target_poses").reshape(-1, 7)
    if len(target_poses) != len(meshes):
        raise ValueError(f"{len(meshes)} meshes but {len(target_poses)} target poses")
    counts = allocate_samples([m.area for m in meshes], total, minimum)
    samples = [surface_samples(m, int(c), part_seed(seed, i)) for i, (m, c) in enumerate(zip(meshes, counts))]
    e_max = max(float(np.ptp(apply_pose(t, np.asarray(m.vertices)), axis=0).max()) for m, t in zip(meshes, target_poses))
    return fracture_metrics_from_samples(samples, pred_poses, target_poses, max(1.0, e_max), pa_threshold)
