"""The fracture protocol (Fantastic Breaks / Breaking Bad comparisons, Appendix A.3) as the
official benchmark evaluates it (``assembly_world_agent/evaluation/garf.py`` of
AssemblyWorld/assembly-world-agent), number for number.

- Samples: 5000 area-weighted surface points in all; part ``i`` (parts in sorted id order) gets
  ``20 + floor(4960 * A_i / sum A)`` (``4960 = 5000 - 20 P`` for ``P`` parts), and whatever is
  left goes to the part with the most (first on ties). ``A_i``: half the summed cross-product
  norms of the part's sampling triangles. Part ``i`` draws from the stream
  ``(42, dataset, sample id, part id, "garf-evaluation")``
  (:func:`aw.prepare.official_protocol.stream`), with the official surface sampler.
- Scale: coordinates are divided by ``max(1, e) * s``: ``e`` the largest axis-aligned extent of
  any part's *source* mesh (source units, before any pose), ``s`` the task's scale (the norm of
  the first column of the source -> task matrix) (:func:`fracture_divisor`).
- Each part's samples are centred on their own mean; a part's pose then moves that centre.
  A predicted rotation is the one the official reads from the restored state
  (``evaluation/inputs.py`` ``final_poses``: MuJoCo's ``xmat`` after ``mj_forward``), the pose's
  quaternion being a free joint's (:func:`aw.official.episode.free_body_rotations`); a target
  rotation is SciPy's matrix of the target quaternion, as the official takes it.
- Anchor: the part with the most samples (first on ties). One shared transform puts the anchor's
  predicted pose exactly on its target; part identities stay fixed and the anchor counts in
  every average.
- RE: per part, the root mean square of the three intrinsic-XYZ Euler angle differences in
  degrees (SciPy's ``as_euler("XYZ")``), each ``|d|`` taken as ``min(|d|, 360 - |d|)``. TE: per
  part, the root mean square of the three centre differences. PA: fraction of parts whose own
  squared Chamfer distance is below 0.01 (strictly). CD: per part, the mean squared distance of
  its predicted points to the whole target assembly plus that of its target points to the whole
  predicted assembly. Every figure is then the mean over parts.

Display multipliers (x100 TE, x1000 CD) belong to reports, not here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from aw.official.episode import free_body_rotations
from aw.prepare.official_protocol import (
    FRACTURE_SEED as SEED,
)
from aw.prepare.official_protocol import allocate_fracture_samples as allocate_samples
from aw.prepare.official_protocol import (
    fracture_divisor,
    fracture_samples,
    rotation_of,
)

__all__ = [
    "FractureMetrics",
    "SEED",
    "allocate_samples",
    "fracture_divisor",
    "fracture_metrics",
    "fracture_metrics_from_samples",
    "wrapped_euler_error",
]

PA_THRESHOLD = 0.01


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
    scale: float  # the divisor
    counts: np.ndarray  # (P,) samples per part


def wrapped_euler_error(r_pred: np.ndarray, r_target: np.ndarray) -> np.ndarray:
    """Per-part RMS of the wrapped intrinsic-XYZ Euler differences (degrees), rotations ``(P, 3, 3)``."""
    out = []
    for rp, rt in zip(np.reshape(r_pred, (-1, 3, 3)), np.reshape(r_target, (-1, 3, 3)), strict=True):
        d = np.abs(
            Rotation.from_matrix(rp).as_euler("XYZ", degrees=True)
            - Rotation.from_matrix(rt).as_euler("XYZ", degrees=True)
        )
        d = np.minimum(d, 360 - d)
        out.append(np.sqrt(np.mean(d**2)))
    return np.array(out)


def _chamfer(a: np.ndarray, b: np.ndarray) -> float:
    ab = cKDTree(b).query(a)[0]
    ba = cKDTree(a).query(b)[0]
    return float(np.mean(ab * ab) + np.mean(ba * ba))


def fracture_metrics_from_samples(
    samples: Sequence[ArrayLike],
    pred_poses: ArrayLike,
    target_poses: ArrayLike,
    scale: float = 1.0,
    pa_threshold: float = PA_THRESHOLD,
) -> FractureMetrics:
    """Fracture metrics from per-part samples (``(n_i, 3)`` each, in the frame the poses act on),
    ``pred_poses (P, 7)`` (the free joints' coordinates of the state, as stored) and
    ``target_poses (P, 7)``, both ``[tx, ty, tz, qw, qx, qy, qz]``; coordinates are divided by
    ``scale`` (the divisor)."""
    clouds = [np.asarray(s, dtype=np.float64) for s in samples]
    state = np.asarray(pred_poses, dtype=np.float64).reshape(-1, 7)
    goal = np.asarray(target_poses, dtype=np.float64).reshape(-1, 7)
    p = len(clouds)
    if (
        p < 1
        or len(state) != p
        or len(goal) != p
        or any(s.ndim != 2 or s.shape[1:] != (3,) or len(s) < 1 for s in clouds)
    ):
        raise ValueError("need one non-empty (n, 3) sample set and one pred/target pose per part")
    if not all(np.isfinite(x).all() for x in (*clouds, state, goal)):
        raise ValueError("samples and poses must be finite")
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError("scale must be positive")
    points, predicted, target = [], [], []
    for s, pp, r, tp in zip(clouds, state, free_body_rotations(state[:, 3:]), goal, strict=True):
        centre = s.mean(0)
        points.append((s - centre) / scale)
        predicted.append((r, (r @ centre + pp[:3]) / scale))
        target.append((rotation_of(tp[3:]), (centre @ rotation_of(tp[3:]).T + tp[:3]) / scale))
    counts = np.array([len(s) for s in clouds])
    anchor = int(np.argmax(counts))
    ra, ta = predicted[anchor]
    rg, tg = target[anchor]
    turn = rg @ ra.T
    shift = tg - turn @ ta
    aligned = [(turn @ r, turn @ t + shift) for r, t in predicted]
    pred = [q @ r.T + t for q, (r, t) in zip(points, aligned, strict=True)]
    gt = [q @ r.T + t for q, (r, t) in zip(points, target, strict=True)]
    pred_tree, gt_tree = cKDTree(np.concatenate(pred)), cKDTree(np.concatenate(gt))
    part_re = wrapped_euler_error(np.stack([r for r, _ in aligned]), np.stack([r for r, _ in target]))
    part_te = np.array([np.sqrt(np.mean((a[1] - b[1]) ** 2)) for a, b in zip(aligned, target, strict=True)])
    part_cd = np.array([_chamfer(a, b) for a, b in zip(pred, gt, strict=True)])
    shape_cd = np.array(
        [np.mean(gt_tree.query(a)[0] ** 2) + np.mean(pred_tree.query(b)[0] ** 2) for a, b in zip(pred, gt, strict=True)]
    )
    return FractureMetrics(
        re=float(np.mean(part_re)),
        te=float(np.mean(part_te)),
        pa=float(np.mean((part_cd < pa_threshold).astype(float))),
        cd=float(np.mean(shape_cd)),
        part_re=part_re,
        part_te=part_te,
        part_cd=part_cd,
        shape_cd=shape_cd,
        anchor=anchor,
        scale=float(scale),
        counts=counts,
    )


def fracture_metrics(
    meshes: Sequence[tuple[np.ndarray, ArrayLike]],
    part_ids: Sequence[str],
    pred_poses: ArrayLike,
    target_poses: ArrayLike,
    dataset: str,
    sample_id: str,
    divisor: float,
    seed: int = SEED,
    pa_threshold: float = PA_THRESHOLD,
) -> FractureMetrics:
    """The fracture protocol for the task's part meshes ``(vertices (n_i, 3), faces)`` (the frame the
    poses act on), in ``part_ids`` order (sorted, as the official orders them); ``divisor`` from
    :func:`fracture_divisor`."""
    samples = fracture_samples(meshes, part_ids, dataset, sample_id, seed)
    return fracture_metrics_from_samples(samples, pred_poses, target_poses, divisor, pa_threshold)
