"""The official preparation's PCA frame of a part (``assembly_world_agent`` of
AssemblyWorld/assembly-world-agent), beneath :mod:`aw.prepare.official_protocol` and
:mod:`aw.prepare.official_similarity`, which both use it."""

from __future__ import annotations

import numpy as np

__all__ = ["pca_frame"]


def pca_frame(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Origin ``(3,)`` and right-handed basis ``(3, 3)`` (columns: largest variance first).

    Axes come from the eigenvectors of the scatter matrix; within an eigenspace (eigenvalues
    within ``1e-10`` of the largest, relative), the axes are the projections of the centred
    vertices, in vertex order, that are not (nearly) spanned by the axes already chosen. The
    third axis is the cross product of the first two.
    """
    center = vertices.mean(axis=0)
    centred = vertices - vertices.mean(axis=0)
    values, vectors = np.linalg.eigh(centred.T @ centred)
    values, vectors = values[::-1], vectors[:, ::-1]
    tolerance = max(float(values[0]), np.finfo(float).tiny) * 1e-10
    radius = max(np.linalg.norm(centred, axis=1).max(), np.finfo(float).tiny)
    axes: list[np.ndarray] = []
    first = 0
    while first < 3 and len(axes) < 2:
        last = first + 1
        while last < 3 and abs(values[last] - values[first]) <= tolerance:
            last += 1
        span = vectors[:, first:last]
        projector = span @ span.T
        found: list[np.ndarray] = []
        for row in centred / radius:
            axis = projector @ row
            for earlier in found:
                axis -= earlier * np.dot(earlier, axis)
            norm = np.linalg.norm(axis)
            if norm > 1e-8:
                axis /= norm
                found.append(axis)
            if len(found) == last - first:
                break
        axes.extend(found)
        first = last
    if len(axes) < 2:
        raise ValueError("degenerate part: fewer than two geometric axes")
    return center, np.column_stack([axes[0], axes[1], np.cross(axes[0], axes[1])])
