"""Geometric measures used by task construction: unique vertices, PCA boxes, part-size ratios.

"Unique vertices" keeps the first occurrence of every distinct vertex, in mesh order. Keeping
the order (instead of ``np.unique``'s sorted order) makes :func:`aw.pose.pca_frame`, whose sign
and degenerate-eigenspace rules look at points in order, equivariant under rigid motion: the
PCA frame of a moved part is the moved PCA frame of the part.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import trimesh

from aw.pose import pca_frame

__all__ = [
    "unique_vertices",
    "pca_box",
    "pca_bbox_diagonal",
    "part_size_ratio",
    "eval_divisor",
]


def unique_vertices(vertices) -> np.ndarray:
    """Distinct rows of ``vertices: (n, 3)`` in order of first appearance, ``(m, 3)``."""
    v = np.asarray(vertices.vertices if isinstance(vertices, trimesh.Trimesh) else vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
        raise ValueError(f"vertices must have shape (n, 3) with n >= 1, got {v.shape}")
    _, first = np.unique(v, axis=0, return_index=True)
    return v[np.sort(first)]


def pca_box(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """PCA frame of ``points: (n, 3)`` and the extent of the points in it.

    Returns ``(origin (3,), axes (3, 3), (lo (3,), hi (3,)))`` with local coordinates
    ``(p - origin) @ axes`` bounded by ``lo`` and ``hi``.
    """
    origin, axes = pca_frame(points)
    local = (np.asarray(points, dtype=np.float64) - origin) @ axes
    return origin, axes, (local.min(axis=0), local.max(axis=0))


def pca_bbox_diagonal(mesh_or_vertices) -> float:
    """Diagonal of the PCA-aligned bounding box of a part's unique vertices."""
    _, _, (lo, hi) = pca_box(unique_vertices(mesh_or_vertices))
    return float(np.linalg.norm(hi - lo))


def part_size_ratio(parts: Sequence) -> float:
    """Largest over smallest part PCA bounding-box diagonal (Appendix C, ``tab:part_scale``)."""
    diags = np.array([pca_bbox_diagonal(p) for p in parts])
    if len(diags) == 0:
        raise ValueError("no parts")
    if diags.min() <= 0:
        raise ValueError("a part has a zero-size bounding box")
    return float(diags.max() / diags.min())


def eval_divisor(parts: Sequence) -> float:
    """The evaluator's scale divisor: the largest part PCA bounding-box diagonal (Appendix A.3)."""
    return max(pca_bbox_diagonal(p) for p in parts)
