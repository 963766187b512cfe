"""Scatter part footprints on the XY plane: non-overlapping boxes with a minimum gap.

Footprints are the axis-aligned XY bounding boxes of the already yawed parts. The packing is a
seeded shelf packing: parts in a seeded random order fill rows of a width chosen so that the
layout is roughly 4:3 (the camera's aspect), each part centred vertically in its row. Parts in
one row are separated along X by at least ``gap``, rows along Y by at least ``gap``, so every
pair of boxes is separated along some axis by at least ``gap``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MIN_GAP", "LAYOUT_GAP", "shelf_pack", "free_spot", "box_gap"]

MIN_GAP = 0.02
"""Appendix A.1: minimum gap between the bounding boxes of any two parts (normalized units)."""

LAYOUT_GAP = MIN_GAP + 1e-6
"""Gap used when packing: a hair above the minimum so that the fixed-precision OBJ text
(9 decimals) can never bring two boxes closer than ``MIN_GAP``."""


def shelf_pack(sizes, order, gap: float = LAYOUT_GAP, aspect: float = 4.0 / 3.0) -> np.ndarray:
    """Lower-left corners ``(n, 2)`` for boxes of ``sizes: (n, 2)`` (width along X, depth along Y).

    ``order``: a permutation of ``range(n)``, the order in which parts fill the rows. The
    layout's bounding box is centred on the origin.
    """
    sizes = np.asarray(sizes, dtype=np.float64)
    n = len(sizes)
    if sizes.shape != (n, 2) or n == 0 or np.any(sizes < 0) or not np.all(np.isfinite(sizes)):
        raise ValueError(f"sizes must be finite, non-negative, shape (n, 2) with n >= 1; got {sizes.shape}")
    order = [int(i) for i in order]
    if sorted(order) != list(range(n)):
        raise ValueError("order must be a permutation of range(n)")
    area = float(np.sum((sizes[:, 0] + gap) * (sizes[:, 1] + gap)))
    row_width = max(float(sizes[:, 0].max()), np.sqrt(area * aspect))

    rows: list[list[int]] = [[]]
    x = 0.0
    for i in order:
        if rows[-1] and x + sizes[i, 0] > row_width:
            rows.append([])
            x = 0.0
        rows[-1].append(i)
        x += sizes[i, 0] + gap

    corners = np.zeros((n, 2))
    y = 0.0
    for row in rows:
        depth = float(sizes[row, 1].max())
        x = 0.0
        for i in row:
            corners[i] = (x, y + 0.5 * (depth - sizes[i, 1]))
            x += sizes[i, 0] + gap
        y += depth + gap
    lo = corners.min(axis=0)
    hi = (corners + sizes).max(axis=0)
    return corners - 0.5 * (lo + hi)


def free_spot(boxes_lo, boxes_hi, size, rng: np.random.Generator, gap: float = LAYOUT_GAP) -> np.ndarray:
    """Lower-left corner ``(2,)`` for a new box of ``size (2,)`` clear of every existing box.

    The new box goes beside the layout's overall bounding box, on a seeded side and at a seeded
    position along it, ``gap`` away, so it cannot touch any existing box.
    """
    lo = np.min(np.asarray(boxes_lo, dtype=np.float64), axis=0)
    hi = np.max(np.asarray(boxes_hi, dtype=np.float64), axis=0)
    size = np.asarray(size, dtype=np.float64)
    side = int(rng.integers(4))
    u = float(rng.uniform())
    if side in (0, 1):  # +X or -X side: slide along Y
        x = hi[0] + gap if side == 0 else lo[0] - gap - size[0]
        y = lo[1] + u * max(hi[1] - lo[1] - size[1], 0.0)
        return np.array([x, y])
    y = hi[1] + gap if side == 2 else lo[1] - gap - size[1]
    x = lo[0] + u * max(hi[0] - lo[0] - size[0], 0.0)
    return np.array([x, y])


def box_gap(lo_a, hi_a, lo_b, hi_b) -> float:
    """Separation of two axis-aligned boxes: the largest per-axis gap (negative if they overlap).

    Boxes are at least ``d`` apart (in any norm) when this is ``>= d``.
    """
    lo_a, hi_a, lo_b, hi_b = (np.asarray(v, dtype=np.float64) for v in (lo_a, hi_a, lo_b, hi_b))
    per_axis = np.maximum(lo_b - hi_a, lo_a - hi_b)
    return float(per_axis.max())
