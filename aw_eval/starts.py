"""Registration starts (Appendix A.3 of the paper): the 24 PCA starts, then one same-ID start
per part, in this order (a start's index is its position in it).

- **PCA starts**: with ``(mu, A)`` the PCA frame of a point set (mean, right-handed principal
  axes in descending variance), ``R0 = A_T S A_P^T`` and ``t0 = mu_T - R0 mu_P`` for each of the
  24 proper rotations ``S`` of the cube group: every way of laying the prediction's principal
  axes onto the target's.
- **same-ID starts**: ``R0 = R*_i R_i^T``, ``t0 = (t*_i - R0 t_i) / divisor`` puts predicted part
  ``i`` exactly onto target part ``i`` (normalized units): a nearly built assembly starts at its
  answer even where PCA is ambiguous.
"""

from __future__ import annotations

import numpy as np

from aw.pose import cube_rotations, pca_frame

__all__ = ["N_PCA_STARTS", "CUBE", "start_frame", "pca_starts", "same_id_starts"]

N_PCA_STARTS = 24
CUBE = cube_rotations()  # (24, 3, 3), exact 0/+-1 entries: computing them once changes no number


def start_frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(mu (3,), A (3, 3))``: the PCA frame of ``points (n, 3)`` that the PCA starts align."""
    return pca_frame(points)


def pca_starts(pred_frame: tuple[np.ndarray, np.ndarray], target_frame: tuple[np.ndarray, np.ndarray]):
    """The 24 PCA starts ``(R0 (24, 3, 3), t0 (24, 3))`` from the two :func:`start_frame` s."""
    mu_p, a_p = pred_frame
    mu_t, a_t = target_frame
    r = a_t @ CUBE @ a_p.T
    return r, mu_t - r @ mu_p


def same_id_starts(rotations: np.ndarray, poses: np.ndarray, target_rotations: np.ndarray, target_poses: np.ndarray,
                   divisor: float):
    """One start per part ``(R0 (P, 3, 3), t0 (P, 3))`` from a checkpoint's ``poses (P, 7)`` and
    their ``rotations (P, 3, 3)``, and the target's (same shapes)."""
    r = target_rotations @ np.swapaxes(rotations, 1, 2)
    t = (target_poses[:, :3] - (r @ poses[:, :3, None])[:, :, 0]) / divisor
    return r, t
