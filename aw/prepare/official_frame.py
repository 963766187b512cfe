"""The official PCA frame of a point set: the one rule that the official preparation
(``utils/transforms.py`` ``pca_frame`` of AssemblyWorld/assembly-world-agent, as of commit
e4b7c9e) and the official scorer (``assembly_world_bench/geometry.py`` ``pca_frame``, the same
rule) both apply. Every caller in this project uses :func:`pca_frame`: the preparation's part
frames, scale and geometry groups (:mod:`aw.prepare.official_protocol`,
:mod:`aw.prepare.official_similarity`) and the evaluator's PCA starts
(:func:`aw_eval.starts.start_frame`), so following the official code when it moves is one change
here (docs/datasets.md says how to re-check it).
"""

from __future__ import annotations

import numpy as np

__all__ = ["EIGEN_TIE", "MIN_AXIS", "DegenerateFrameError", "pca_frame"]

EIGEN_TIE = 1e-10  # eigenvalues within this fraction of the largest span one eigenspace
MIN_AXIS = 1e-8  # a projected point shorter than this (of the farthest point's length) gives no axis


class DegenerateFrameError(ValueError):
    """The points have fewer than two geometric axes (coincident or collinear points)."""


def pca_frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Origin ``(3,)`` and right-handed basis ``(3, 3)`` of ``points: (n, 3)`` (columns: largest
    variance first, so the smallest-variance axis is local Z).

    The origin is the mean. Eigenvalues of the centred scatter matrix, largest first, that lie
    within :data:`EIGEN_TIE` of the largest (relative) form one eigenspace. In each eigenspace in
    turn, its axes are the projections onto it of the centred points (in point order, scaled by
    the farthest point's distance), each made orthogonal to the axes already taken there and
    normalized, skipping those shorter than :data:`MIN_AXIS`: the points' own order fixes every
    sign and every direction inside a repeated eigenspace. The first two axes are then made
    orthonormal once more (a projection that nearly cancels leaves a tiny cross-axis residual
    after normalization; e4b7c9e added this step), and the third is their cross product.

    Raises :class:`DegenerateFrameError` when fewer than two axes exist.
    """
    center = points.mean(axis=0)
    centred = points - points.mean(axis=0)
    values, vectors = np.linalg.eigh(centred.T @ centred)
    values, vectors = values[::-1], vectors[:, ::-1]
    tie = max(float(values[0]), np.finfo(float).tiny) * EIGEN_TIE
    rows = centred / max(np.linalg.norm(centred, axis=1).max(), np.finfo(float).tiny)
    axes: list[np.ndarray] = []
    lo = 0
    while lo < 3 and len(axes) < 2:
        hi = lo + 1
        while hi < 3 and abs(values[hi] - values[lo]) <= tie:
            hi += 1
        span = vectors[:, lo:hi]
        onto = span @ span.T
        taken: list[np.ndarray] = []
        for row in rows:
            axis = onto @ row
            for earlier in taken:
                axis -= earlier * np.dot(earlier, axis)
            size = np.linalg.norm(axis)
            if size > MIN_AXIS:
                axis /= size
                taken.append(axis)
            if len(taken) == hi - lo:
                break
        axes += taken
        lo = hi
    if len(axes) < 2:
        raise DegenerateFrameError("degenerate part: fewer than two geometric axes")
    e1 = axes[0] / np.linalg.norm(axes[0])
    e2 = axes[1] - e1 * np.dot(e1, axes[1])
    e2 /= np.linalg.norm(e2)
    return center, np.column_stack([e1, e2, np.cross(e1, e2)])
