"""A lower bound on the Chamfer distance of two clouds over every rigid motion, by a branch and
bound over rotations: how far each cloud sticks out of the other's bounding box.

:mod:`aw.shape_bounds` compares quantities that no rotation changes (spreads, reaches, lengths),
so it rules out parts of clearly different sizes but not parts of similar size and different
proportions (a 0.6 x 0.4 x 0.2 box and a 0.5 x 0.5 x 0.2 one). This bound sees proportions under
every rotation, at a higher cost, and is run on the pairs the first one leaves.

**One rotation.** With the notation of :mod:`aw.shape_bounds` (``CD(X', Y) = F + B``, ``X' = R X
+ t``), give each cloud an orthonormal frame and its box ``[-h, h]`` in it (here the minimum-volume
oriented box, centred). Every point of ``Y`` lies in its box, so along axis ``k`` of ``Y``'s frame
the nearest point ``y`` of ``x'_a`` has ``|x'_ak - y_k| >= dist(p_a + t_k, [-h_k, h_k])``, ``p_a =
u . x_a`` with ``u = R^T e_k``, and ``d(x'_a, Y)^2`` is at least the sum of these squares over the
three axes. For two points with ``p_a >= p_b`` and any shift ``s``, ``dist(p_a + s, I) + dist(p_b +
s, I) >= p_a - p_b - 2 h_k``; so, pairing along each axis the ``j``-th highest projection with the
``j``-th lowest (any matching would do)::

    F >= sum_k (1 / 2n) sum_j (p_(n-1-j) - p_(j) - 2 h_k)_+^2

whatever ``t`` is, and ``B`` likewise with ``Y`` seen along ``R e_k`` against ``X``'s box.

**A set of rotations.** The angle-axis vectors ``|r| <= pi`` give every rotation; the search covers
them with cubes (a first grid of ``START_CUBES`` a side, each split in eight when needed, depth
first). For ``r`` in a cube of half-side ``sigma`` around ``r_0`` the rotations are within angle
``delta = sqrt(3) sigma`` of ``R(r_0)`` (Hartley and Kahl, "Global optimization through rotation
space search", IJCV 2009), so each axis direction ``u`` stays within ``delta`` of the centre's,
and a pair's projected length ``|v| cos(alpha)`` (``v = x_a - x_b`` at angle ``alpha`` to ``u``)
is at least ``|v| cos(alpha + delta)`` on the whole cube. A cube whose bound exceeds the
threshold holds no rotation that could make an edge.

**Where the time goes.** Each of the six terms depends on one direction only, and the cubes near
each other share directions, so a cube is first bounded from *tables*: for each cell of a sphere
grid (a cube map, ``2**level`` cells a side on each face), the longest ``TABLE_PAIRS`` pairs along
the cell's centre ``g``, each lowered for the cap of radius ``delta + cell radius`` around ``g``
(which holds every direction of the cubes that read it); dropping pairs only lowers the bound.
The coarse levels (``TABLE_LEVELS``, read by the first two depths of cubes) are built once per
cloud (:func:`box_frame`), the finer ones (``LAZY_LEVELS``) per pair, for the cells read, which
lie near the best rotations. A term depends on the pair, the cell and the other box's width
only, so each is computed once per pair and then read by every cube of its cell; the cells of
the first two depths' cubes are read off a grid computed once (:func:`_grid_rows`). A cube the
tables leave is split; from depth ``direct_from`` on it is also evaluated directly (its own
directions and ``delta``, every point, the terms with the largest table term first; the points
that cannot be in a long pair anywhere in it are skipped in its sub-cubes, which leaves the sums
as they are).

A pair is ruled out when every cube is. It stays a candidate (registered, as before) as soon as
one of the 24 rotations mapping box axes onto box axes, or the centre of a cube evaluated
directly, is itself within the threshold (no search can rule those out), or the cubes get too
small or too many (:class:`SearchLimits`: past that, a registration costs less).

The bound is safe in the same sense as :mod:`aw.shape_bounds` (the callers' groups are those of
registering every pair): the tables keep their lengths as 16-bit multiples rounded down, the
angles are widened far above rounding, and the comparison has the
:data:`aw.shape_bounds.SAFETY` slack. Arrays: ``points (n, 3)``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import trimesh
from numba import njit, types
from numba.typed import Dict

from aw.pose import cube_rotations
from aw.shape_bounds import SAFETY

__all__ = ["BoxFrame", "SearchLimits", "at_rotation", "box_frame", "compile_search", "rules_out", "search"]

# sphere-grid levels of the tables, one per depth of cubes: 8 and 16 cells a side of a cube face
# kept with each cloud, then 32, 64 and 128, read only near the best rotations, built per pair
TABLE_LEVELS = (3, 4)
LAZY_LEVELS = (5, 6, 7)
TABLE_PAIRS = 96  # longest pairs kept per table cell
START_CUBES = 16  # cubes a side of the first grid over [-pi, pi]^3
SUBSET = 256  # points of each cloud in the first pass over a cube evaluated directly
_MAX_DEPTH = 12
_SORT_BINS = 512
_ALIGNED = np.ascontiguousarray(cube_rotations())  # the rotations mapping box axes onto box axes


@dataclass(frozen=True)
class BoxFrame:
    """A cloud in the frame of its minimum-volume oriented box, centred on the box, with its
    direction tables.

    ``points (n, 3)`` (in a fixed shuffled order, so that the first ones are a spread-out
    subset); ``radii (n,)`` their distances from the centre; ``half (3,)`` the box's half-widths
    (the points' largest absolute coordinates); ``table (cells, TABLE_PAIRS)`` uint16 multiples
    of ``step``, per cell of :data:`TABLE_LEVELS` (faces +x, +y, +z: a direction and its opposite
    give the same pairs) the lengths of the longest pairs along the cell's centre, lowered for
    every direction of the cubes read at that level (see :func:`_tables`), sorted, rounded down,
    zero-padded."""

    points: np.ndarray
    radii: np.ndarray
    half: np.ndarray
    table: np.ndarray
    step: float


@dataclass(frozen=True)
class SearchLimits:
    """When the search gives up (the pair then stays a candidate): more than ``max_cubes`` cubes
    looked at, more than ``max_direct`` of them evaluated directly (the costly ones), or a cube
    of half-side below ``min_half`` (radians of angle-axis) still not ruled out. ``direct_from``:
    the depth from which the cubes the tables leave are evaluated directly. ``aligned_first``:
    first try the 24 rotations that map box axes onto box axes, and give up at once if one of
    them is within the threshold (the search could not rule it out)."""

    min_half: float = 2e-3
    max_cubes: int = 20000
    max_direct: int = 1000
    direct_from: int = 4
    aligned_first: bool = True


def box_frame(cloud: np.ndarray) -> BoxFrame:
    """``cloud (n, 3)`` in its box frame, with its tables. The frame only needs to be orthonormal
    for the bound to hold (a smaller box makes it tighter), so trimesh's minimum-volume box is
    orthonormalized."""
    cloud = np.asarray(cloud, dtype=np.float64)
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):  # flat clouds: trimesh divides by a zero volume
            warnings.simplefilter("ignore")
            transform, _ = trimesh.bounds.oriented_bounds(cloud)
        u, _, vt = np.linalg.svd(transform[:3, :3])
        axes = u @ vt
        if not np.isfinite(axes).all():
            axes = np.eye(3)
    except Exception:  # degenerate clouds (Qhull fails on flat or tiny input): any frame holds
        axes = np.eye(3)
    local = cloud @ axes.T
    local = local - 0.5 * (local.max(axis=0) + local.min(axis=0))
    local = np.ascontiguousarray(local[np.random.default_rng(0).permutation(len(local))])
    lowered = _tables(local, np.array(TABLE_LEVELS, np.int64), TABLE_PAIRS, START_CUBES)
    # in 16 bits (96 pairs x 960 cells), as multiples of a step, rounded down: each a lower bound
    step = max(float(lowered.max()), 1e-300) / 65535.0
    table = np.floor(np.maximum(lowered, 0.0) / step)
    table -= table * step > lowered  # (the decoding's own rounding)
    return BoxFrame(
        local,
        np.sqrt(np.einsum("ij,ij->i", local, local)),
        np.abs(local).max(axis=0),
        np.maximum(table, 0).astype(np.uint16),
        step,
    )


def rules_out(a: BoxFrame, b: BoxFrame, threshold: float, limits: SearchLimits = SearchLimits()) -> bool:
    """Whether ``CD(R A + t, B) > threshold`` (with the :data:`~aw.shape_bounds.SAFETY` slack) is
    proven for every rotation ``R`` and translation ``t``: then ``A -> B`` cannot register within
    ``threshold``. ``False`` means "not proven" (the pair must be registered)."""
    return search(a, b, threshold, limits)[0]


def search(
    a: BoxFrame, b: BoxFrame, threshold: float, limits: SearchLimits = SearchLimits(), stats: np.ndarray | None = None
) -> tuple[bool, int]:
    """:func:`rules_out`, and the cubes the search looked at. ``stats (_MAX_DEPTH + 2, 3)`` int64,
    if given, gets added per depth the cubes looked at, ruled out by the tables, and ruled out
    directly."""
    shape = (_MAX_DEPTH + 2, 3)
    if stats is None:
        stats = np.zeros(shape, np.int64)
    elif stats.shape != shape or stats.dtype != np.int64:
        raise ValueError(f"stats must be an int64 array of shape {shape}, got {stats.dtype} {stats.shape}")
    limit = threshold * (1 + SAFETY[0]) + SAFETY[1]
    looked = _search(
        a.points,
        a.radii,
        a.half,
        a.table,
        a.step,
        b.points,
        b.radii,
        b.half,
        b.table,
        b.step,
        float(limit),
        np.array(TABLE_LEVELS, np.int64),
        np.array(LAZY_LEVELS, np.int64),
        START_CUBES,
        *_fixed(),
        float(limits.min_half),
        int(limits.max_cubes),
        int(limits.max_direct),
        int(limits.direct_from),
        _ALIGNED if limits.aligned_first else _ALIGNED[:0],
        SUBSET,
        stats,
    )
    return looked > 0, abs(int(looked))


def at_rotation(a: BoxFrame, b: BoxFrame, rotation: np.ndarray) -> float:
    """The bound for one rotation ``(3, 3)`` of ``a.points`` onto ``b.points`` (the box frames'):
    below ``CD(a.points @ rotation.T + t, b.points)`` for every translation ``t``. The search
    proves it above a threshold for all rotations at once."""
    rot = np.ascontiguousarray(rotation, dtype=np.float64)
    return float(_at_rotation(a.points, a.radii, a.half, b.points, b.radii, b.half, rot))


def compile_search() -> None:
    """Run the search's kernels on tiny inputs (numba caches them beside this module), so that
    no search waits for a compile (:func:`aw_eval.kernels.compile_kernels` calls it)."""
    rng = np.random.default_rng(0)
    a, b = box_frame(rng.normal(size=(40, 3))), box_frame(rng.normal(size=(30, 3)))
    search(a, b, 1e-4, SearchLimits(aligned_first=False, max_cubes=50, direct_from=0))
    search(a, b, 1e-4)


# ---------------------------------------------------------------- compiled kernels


@njit(cache=True, nogil=True)
def _rotation(rx, ry, rz):
    """The rotation of angle-axis vector ``r`` (Rodrigues)."""
    out = np.empty((3, 3))
    _set_rotation(out, rx, ry, rz)
    return out


@njit(cache=True, nogil=True)
def _set_rotation(out, rx, ry, rz):
    """:func:`_rotation` written into ``out (3, 3)`` (the search turns many cubes: no allocation)."""
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle == 0.0:
        out[:] = 0.0
        out[0, 0] = out[1, 1] = out[2, 2] = 1.0
        return
    kx, ky, kz = rx / angle, ry / angle, rz / angle
    c, s = math.cos(angle), math.sin(angle)
    v = 1.0 - c
    out[0, 0] = c + kx * kx * v
    out[0, 1] = kx * ky * v - kz * s
    out[0, 2] = kx * kz * v + ky * s
    out[1, 0] = ky * kx * v + kz * s
    out[1, 1] = c + ky * ky * v
    out[1, 2] = ky * kz * v - kx * s
    out[2, 0] = kz * kx * v - ky * s
    out[2, 1] = kz * ky * v + kx * s
    out[2, 2] = c + kz * kz * v


@njit(cache=True, nogil=True)
def _start_centre(i, j, k, h0):
    """Centre of start cube ``(i, j, k)`` of the first grid (half-side ``h0``)."""
    return -math.pi + (2 * i + 1) * h0, -math.pi + (2 * j + 1) * h0, -math.pi + (2 * k + 1) * h0


@njit(cache=True, nogil=True)
def _child_centre(cx, cy, cz, h, d):
    """Centre of sub-cube ``d`` (0-7) of the cube of centre ``c`` and half-side ``h``."""
    return (cx + (0.5 if d & 1 else -0.5) * h, cy + (0.5 if d & 2 else -0.5) * h, cz + (0.5 if d & 4 else -0.5) * h)


@njit(cache=True, nogil=True)
def _grid_rows(levels, start_cubes):
    """``(cubes, 6)`` int32: for every cube of the first ``len(levels)`` depths (the start grid,
    then each cube's eight sub-cubes: cube ``c`` of depth ``q`` has sub-cubes ``8 c + d`` of depth
    ``q + 1``; depth ``q``'s cubes from row ``start_cubes**3 (8**q - 1) / 7``), the table cell
    (counted from its level's first row) of each side's and axis's direction at its centre,
    column ``3 side + k``. The same for every pair: the cubes of those depths read it instead of
    turning their centres into directions."""
    first = start_cubes**3
    total, count = 0, first
    for _ in range(len(levels)):
        total += count
        count *= 8
    out = np.empty((total, 6), np.int32)
    centres = np.empty((total, 3))
    h = math.pi / start_cubes
    for i in range(start_cubes):
        for j in range(start_cubes):
            for k in range(start_cubes):
                c = (i * start_cubes + j) * start_cubes + k
                centres[c, 0], centres[c, 1], centres[c, 2] = _start_centre(i, j, k, h)
    begin, count = 0, first
    for q in range(len(levels)):
        for c in range(count):
            cx, cy, cz = centres[begin + c, 0], centres[begin + c, 1], centres[begin + c, 2]
            rot = _rotation(cx, cy, cz)
            for side in range(2):
                for k in range(3):
                    u0, u1, u2 = _axis_direction(rot, side, k)
                    out[begin + c, 3 * side + k] = _cell_of(u0, u1, u2, levels[q])
            if q + 1 < len(levels):
                for d in range(8):
                    child = begin + count + 8 * c + d
                    centres[child, 0], centres[child, 1], centres[child, 2] = _child_centre(cx, cy, cz, h, d)
        begin += count
        count *= 8
        h *= 0.5
    return out


@njit(cache=True, nogil=True)
def _cell_table(levels):
    """``(cells, 4)``: :func:`_cell_geometry` of every cell of ``levels``, level after level."""
    rows = 0
    for level in levels:
        rows += 3 << (2 * level)
    out = np.empty((rows, 4))
    first = 0
    for level in levels:
        for row in range(3 << (2 * level)):
            out[first + row, 0], out[first + row, 1], out[first + row, 2], out[first + row, 3] = _cell_geometry(
                row, level
            )
        first += 3 << (2 * level)
    return out


@lru_cache(maxsize=1)
def _fixed() -> tuple[np.ndarray, np.ndarray]:
    """The grid's rows (:func:`_grid_rows`) and the lazy levels' cells (:func:`_cell_table`): the
    same for every pair, computed once per process (milliseconds; threads that ask at once may
    each compute them, and each gets both)."""
    return (_grid_rows(np.array(TABLE_LEVELS, np.int64), START_CUBES), _cell_table(np.array(LAZY_LEVELS, np.int64)))


@njit(cache=True, nogil=True)
def _face_point(face, s, t):
    """The unit direction through point ``(s, t)`` of face ``face`` (0, 1, 2: +x, +y, +z)."""
    if face == 0:
        x, y, z = 1.0, s, t
    elif face == 1:
        x, y, z = s, 1.0, t
    else:
        x, y, z = s, t, 1.0
    norm = math.sqrt(x * x + y * y + z * z)
    return x / norm, y / norm, z / norm


@njit(cache=True, nogil=True)
def _cell_of(u0, u1, u2, level):
    """The table row of the cell holding direction ``u`` or ``-u`` at ``level`` (a cube-map grid:
    ``2**level`` cells a side on the faces +x, +y, +z, projected onto the sphere from the centre),
    counted from the level's first row."""
    a0, a1, a2 = abs(u0), abs(u1), abs(u2)
    if a0 >= a1 and a0 >= a2:
        face, s, t, m = 0, u1, u2, u0
    elif a1 >= a2:
        face, s, t, m = 1, u0, u2, u1
    else:
        face, s, t, m = 2, u0, u1, u2
    side = 1 << level
    i = min(max(int((s / m + 1.0) * 0.5 * side), 0), side - 1)  # s / m: the same for u and -u
    j = min(max(int((t / m + 1.0) * 0.5 * side), 0), side - 1)
    return (face * side + i) * side + j


@njit(cache=True, nogil=True)
def _cell_geometry(row, level):
    """Centre direction of a cell and the largest angle from it to the cell (at a corner: the
    cell is a convex spherical quadrilateral), widened far above rounding."""
    side = 1 << level
    face, rest = row // (side * side), row % (side * side)
    i, j = rest // side, rest % side
    s0, s1 = -1.0 + 2.0 * i / side, -1.0 + 2.0 * (i + 1) / side
    t0, t1 = -1.0 + 2.0 * j / side, -1.0 + 2.0 * (j + 1) / side
    g0, g1, g2 = _face_point(face, 0.5 * (s0 + s1), 0.5 * (t0 + t1))
    radius = 0.0
    for s, t in ((s0, t0), (s0, t1), (s1, t0), (s1, t1)):
        c0, c1, c2 = _face_point(face, s, t)
        radius = max(radius, math.acos(min(max(g0 * c0 + g1 * c1 + g2 * c2, -1.0), 1.0)))
    return g0, g1, g2, radius * (1.0 + 1e-6) + 1e-9


@njit(cache=True, nogil=True)
def _level_delta(q, start_cubes):
    """The angle ``delta`` of the cubes at depth ``q`` (those that read table level ``q``)."""
    return math.sqrt(3.0) * math.pi / start_cubes / (1 << q)


@njit(cache=True, nogil=True)
def _table_row(points, cell, delta, work, out):
    """``out (pairs,)``: the row of a cell (``cell``: its centre ``g`` and radius, a row of
    :func:`_cell_table`) for cubes within ``delta`` of their centre: the longest pairs along ``g``
    (the ``j``-th highest projection with the ``j``-th lowest), each lowered to ``along cos(rho) -
    across sin(rho)`` for ``rho = delta +`` the cell's radius, in decreasing order, zero-padded.
    ``work``: :func:`_workspace`."""
    proj, where, high, low, spare, count, start = work
    n, pairs = points.shape[0], out.shape[0]
    bins = count.shape[0]
    out[:] = 0.0
    k = min(pairs, n // 2)
    g0, g1, g2, radius = cell[0], cell[1], cell[2], cell[3]
    lo_v, hi_v = np.inf, -np.inf
    for i in range(n):
        v = g0 * points[i, 0] + g1 * points[i, 1] + g2 * points[i, 2]
        proj[i] = v
        lo_v = min(lo_v, v)
        hi_v = max(hi_v, v)
    if k == 0 or hi_v <= lo_v:
        return
    # the k highest and k lowest points, from a histogram: the points of the top bins holding at
    # least k of them (and of the bottom bins), ordered
    count[:] = 0
    scale = bins / (hi_v - lo_v)
    for i in range(n):
        b = min(int((proj[i] - lo_v) * scale), bins - 1)
        where[i] = b
        count[b] += 1
    top, seen = bins - 1, count[bins - 1]
    while seen < k:
        top -= 1
        seen += count[top]
    bottom, seen = 0, count[0]
    while seen < k:
        bottom += 1
        seen += count[bottom]
    if bottom >= top:
        return  # most points in a few bins: the row stays empty (a lower bound still)
    n_hi, n_lo = 0, 0
    for i in range(n):
        if where[i] >= top:
            high[n_hi] = i
            n_hi += 1
        elif where[i] <= bottom:
            low[n_lo] = i
            n_lo += 1
    _sort_by(high, n_hi, proj, -1.0, spare, start)
    _sort_by(low, n_lo, proj, 1.0, spare, start)
    cos_d, sin_d = _cos_sin(delta + radius)
    for j in range(k):  # nearly in decreasing order already: sorted by insertion
        a, b = high[j], low[j]
        length = proj[a] - proj[b]
        v = length * cos_d - _across(points, a, b, length) * sin_d
        r = j - 1
        while r >= 0 and out[r] < v:
            out[r + 1] = out[r]
            r -= 1
        out[r + 1] = v


@njit(cache=True, nogil=True)
def _workspace(n):
    return (
        np.empty(n),
        np.empty(n, np.int64),
        np.empty(n, np.int64),
        np.empty(n, np.int64),
        np.empty(n, np.int64),
        np.zeros(256, np.int64),
        np.empty(_SORT_BINS + 1, np.int64),
    )


@njit(cache=True, nogil=True)
def _tables(points, levels, pairs, start_cubes):
    """``(cells, pairs)`` float64: :func:`_table_row` of every cell of ``levels`` (level ``q``
    read by the cubes at depth ``q``)."""
    rows = 0
    for level in levels:
        rows += 3 << (2 * level)
    out = np.zeros((rows, pairs))
    work = _workspace(points.shape[0])
    first = 0
    for q in range(len(levels)):
        for row in range(3 << (2 * levels[q])):
            g0, g1, g2, radius = _cell_geometry(row, levels[q])
            _table_row(points, np.array((g0, g1, g2, radius)), _level_delta(q, start_cubes), work, out[first + row])
        first += 3 << (2 * levels[q])
    return out


@njit(cache=True, nogil=True)
def _sort_by(idx, m, key, sign, spare, start):
    """Order ``idx[:m]`` by ``sign * key[idx]``, increasing: exactly (insertion sort) for short
    lists, else by _SORT_BINS bins of the keys' range (a counting sort; ``spare``: room for ``m``
    indices, ``start``: for _SORT_BINS + 1 counts). Any order gives a valid bound (it only
    chooses which points are paired); a nearly sorted one pairs nearly as the sorted one does."""
    if m <= 32:
        for q in range(1, m):
            v = idx[q]
            kv = sign * key[v]
            r = q - 1
            while r >= 0 and sign * key[idx[r]] > kv:
                idx[r + 1] = idx[r]
                r -= 1
            idx[r + 1] = v
        return
    bins = _SORT_BINS
    lo, hi = np.inf, -np.inf
    for q in range(m):
        v = sign * key[idx[q]]
        lo = min(lo, v)
        hi = max(hi, v)
    if hi <= lo:
        return
    scale = bins / (hi - lo)
    start[:] = 0
    for q in range(m):
        start[min(int((sign * key[idx[q]] - lo) * scale), bins - 1) + 1] += 1
    for b in range(bins):
        start[b + 1] += start[b]
    for q in range(m):
        b = min(int((sign * key[idx[q]] - lo) * scale), bins - 1)
        spare[start[b]] = idx[q]
        start[b] += 1
    idx[:m] = spare[:m]


@njit(cache=True, nogil=True)
def _across(points, a, b, along):
    """The component of ``x_a - x_b`` across the direction it has length ``along`` on."""
    dx = points[a, 0] - points[b, 0]
    dy = points[a, 1] - points[b, 1]
    dz = points[a, 2] - points[b, 2]
    return math.sqrt(max(dx * dx + dy * dy + dz * dz - along * along, 0.0))


@njit(cache=True, nogil=True)
def _cos_sin(angle):
    """``cos`` rounded down and ``sin`` rounded up, far beyond their rounding (``angle`` is
    capped at ``pi / 2``: beyond it no pair of positive length is long)."""
    d = min(angle * (1.0 + 1e-9) + 1e-12, 0.5 * math.pi)
    return math.cos(d) * (1.0 - 1e-12), math.sin(d) * (1.0 + 1e-12) + 1e-15


@njit(cache=True, nogil=True)
def _table_term(table, step, row, width, n, budget):
    """``(1 / 2n) sum_j (lowered length_j - width)_+^2`` over a table row's pairs, or a partial
    sum once past ``budget`` (the caller only asks "above it?")."""
    s = 0.0
    enough = 2.0 * n * budget
    for j in range(table.shape[1]):
        gap = np.float64(table[row, j]) * step - width
        if gap <= 0.0:
            break  # sorted: no later pair is longer
        s += gap * gap
        if s > enough:
            break
    return 0.5 * s / n


@njit(cache=True, nogil=True)
def _direct_term(
    points, radii, active, n_active, u0, u1, u2, width, cos_d, sin_d, delta, proj, low, high, next_active, spare, start
):
    """One (side, axis) term evaluated directly: ``(bound over the cube, bound at its centre,
    points kept)``.

    Over the points ``active[:n_active]``: every point that can be in a pair longer than
    ``width`` for some rotation of the cube (the parent's choice), so the sums equal those over
    all points. The points that can for some rotation of this cube are written to
    ``next_active`` (for its sub-cubes): a point moves by at most ``|x_a| delta`` along ``u``, so
    ``p_a + |x_a| delta`` must pass the lowest ``p_b - |x_b| delta`` plus ``width`` (or the
    mirror condition)."""
    n = points.shape[0]
    lo_v, hi_v = np.inf, -np.inf
    lo_s, hi_s = np.inf, -np.inf
    for q in range(n_active):
        i = active[q]
        v = u0 * points[i, 0] + u1 * points[i, 1] + u2 * points[i, 2]
        proj[i] = v
        lo_v = min(lo_v, v)
        hi_v = max(hi_v, v)
        lo_s = min(lo_s, v - radii[i] * delta)
        hi_s = max(hi_s, v + radii[i] * delta)
    kept = 0
    for q in range(n_active):
        i = active[q]
        if proj[i] + radii[i] * delta > lo_s + width or proj[i] - radii[i] * delta < hi_s - width:
            next_active[kept] = i
            kept += 1
    if hi_v - lo_v <= width:
        return 0.0, 0.0, kept
    # only the points below hi - width can be the low end of a pair longer than width (and those
    # above lo + width the high end): the j-th lowest overall is the j-th of them
    n_lo, n_hi = 0, 0
    for q in range(n_active):
        i = active[q]
        if proj[i] < hi_v - width:
            low[n_lo] = i
            n_lo += 1
        if proj[i] > lo_v + width:
            high[n_hi] = i
            n_hi += 1
    _sort_by(low, n_lo, proj, 1.0, spare, start)
    _sort_by(high, n_hi, proj, -1.0, spare, start)
    s, s0 = 0.0, 0.0
    for j in range(min(n_lo, n_hi, n // 2)):
        a, b = high[j], low[j]
        length = proj[a] - proj[b]
        if length <= width:
            break  # sorted: no later pair is longer
        s0 += (length - width) ** 2
        gap = length * cos_d - _across(points, a, b, length) * sin_d - width
        if gap > 0.0:
            s += gap * gap
    return 0.5 * s / n, 0.5 * s0 / n, kept


@njit(cache=True, nogil=True)
def _axis_direction(rot, side, k):
    """Side 0 projects ``R x`` on axis ``k``: direction ``R^T e_k`` (row ``k``); side 1 projects
    ``R^T y``: direction ``R e_k`` (column ``k``)."""
    if side == 0:
        return rot[k, 0], rot[k, 1], rot[k, 2]
    return rot[0, k], rot[1, k], rot[2, k]


@njit(cache=True, nogil=True)
def _direct_bound(ap, ar, bp, br, widths, rot, delta, limit, act, n_act, depth, proj, low, high, spare, start, order):
    """The six terms of a cube evaluated directly over the points ``act[depth]``: ``(bound over
    the cube, bound at its centre)`` (the second complete when the first is not above
    ``limit``); the points its sub-cubes need go to ``act[depth + 1]``. ``order (6,)``: the
    terms ``3 side + k`` in the order to evaluate them (the likely largest first: the sooner
    the sum passes ``limit``, the fewer are evaluated)."""
    cos_d, sin_d = _cos_sin(delta)
    bound, at_centre = 0.0, 0.0
    for c in order:
        side, k = c // 3, c % 3
        points, radii = (ap, ar) if side == 0 else (bp, br)
        u0, u1, u2 = _axis_direction(rot, side, k)
        f, f0, kept = _direct_term(
            points,
            radii,
            act[depth, side, k],
            n_act[depth, side, k],
            u0,
            u1,
            u2,
            widths[side, k],
            cos_d,
            sin_d,
            delta * (1.0 + 1e-9) + 1e-12,
            proj,
            low,
            high,
            act[depth + 1, side, k],
            spare,
            start,
        )
        n_act[depth + 1, side, k] = kept
        bound += f
        at_centre += f0
        if bound > limit:
            return bound, at_centre
    return bound, at_centre


@njit(cache=True, nogil=True)
def _widths(ah, bh):
    """``(2, 3)``: side 0 (``A`` turned by ``R``) against ``B``'s box, side 1 against ``A``'s."""
    out = np.empty((2, 3))
    out[0] = 2.0 * bh
    out[1] = 2.0 * ah
    return out


@njit(cache=True, nogil=True)
def _read_first(act, n_act, depth, counts, most):
    """Cubes at ``depth`` read the first ``most`` points of each cloud (all of them if fewer)."""
    for side in range(2):
        m = min(counts[side], most)
        for k in range(3):
            n_act[depth, side, k] = m
            act[depth, side, k, :m] = np.arange(m)


@njit(cache=True, nogil=True)
def _at_rotation(ap, ar, ah, bp, br, bh, rot):
    n_max = max(ap.shape[0], bp.shape[0])
    act = np.empty((2, 2, 3, n_max), np.int64)
    n_act = np.zeros((2, 2, 3), np.int64)
    _read_first(act, n_act, 0, (ap.shape[0], bp.shape[0]), n_max)
    proj, spare = np.empty(n_max), np.empty(n_max, np.int64)
    low, high = np.empty(n_max, np.int64), np.empty(n_max, np.int64)
    return _direct_bound(
        ap,
        ar,
        bp,
        br,
        _widths(ah, bh),
        rot,
        0.0,
        np.inf,
        act,
        n_act,
        0,
        proj,
        low,
        high,
        spare,
        np.empty(_SORT_BINS + 1, np.int64),
        np.arange(6),
    )[1]


@njit(cache=True, nogil=True)
def _search(
    ap,
    ar,
    ah,
    a_table,
    a_step,
    bp,
    br,
    bh,
    b_table,
    b_step,
    limit,
    levels,
    lazy_levels,
    start_cubes,
    grid,
    lazy_cells,
    min_half,
    max_cubes,
    max_direct,
    direct_from,
    aligned,
    subset,
    stats,
):
    """The number of cubes looked at, positive when every cube of the ball ``|r| <= pi`` is
    ruled out (see the module docstring), negative when the search gave up. ``grid``:
    :func:`_grid_rows` (none, ``(0, 6)``: the cells are found from the cubes' centres instead);
    ``lazy_cells``: :func:`_cell_table` of ``lazy_levels``."""
    n_max = max(ap.shape[0], bp.shape[0])
    widths = _widths(ah, bh)
    counts = (ap.shape[0], bp.shape[0])
    firsts = np.zeros(len(levels) + 1, np.int64)  # each table level's first row, and the rows in all
    grid_firsts = np.zeros(len(levels) + 1, np.int64)  # each depth's first row in `grid`
    for q in range(len(levels)):
        firsts[q + 1] = firsts[q] + (3 << (2 * levels[q]))
        grid_firsts[q + 1] = grid_firsts[q] + start_cubes**3 * 8**q
    lazy_firsts = np.zeros(len(lazy_levels), np.int64)  # each lazy level's first row in `lazy_cells`
    for q in range(1, len(lazy_levels)):
        lazy_firsts[q] = lazy_firsts[q - 1] + (3 << (2 * lazy_levels[q - 1]))
    act = np.empty((_MAX_DEPTH + 2, 2, 3, n_max), np.int64)  # act[d]: the points a cube at depth d reads
    n_act = np.zeros((_MAX_DEPTH + 2, 2, 3), np.int64)
    proj, low, high = np.empty(n_max), np.empty(n_max, np.int64), np.empty(n_max, np.int64)
    spare, start = np.empty(n_max, np.int64), np.empty(_SORT_BINS + 1, np.int64)

    # `aligned` (R, 3, 3): rotations tried first (those mapping the box axes onto the box axes): one
    # whose own bound is within the threshold cannot be ruled out, so the pair is given up at once
    # (first over a subset of the points: a bound above the limit there is above it over all)
    in_turn = np.arange(6)
    for r in range(aligned.shape[0]):
        for most in (subset, n_max):
            _read_first(act, n_act, 0, counts, most)
            bound, at_rotation = _direct_bound(
                ap, ar, bp, br, widths, aligned[r], 0.0, limit, act, n_act, 0, proj, low, high, spare, start, in_turn
            )
            if bound > limit:
                break
        if bound <= limit and at_rotation <= limit:
            return -1

    # Each term depends on the pair, a table row and a width only, and many cubes read the same
    # row: every term is computed once (up to past `limit`: "above it" is all a cube asks), at
    # the table levels in `memo` (row, 3 side + k), at the lazy ones per slot of `lazy`
    memo = np.full((firsts[len(levels)], 6), -1.0)
    # the lazy levels' rows, per side, built when first read: slot of (side, level, row) in `lazy`
    slots = Dict.empty(key_type=types.int64, value_type=types.int64)
    lazy = np.empty((256, a_table.shape[1]))
    lazy_memo = np.empty((256, 3))
    work = (_workspace(ap.shape[0]), _workspace(bp.shape[0]))

    cap = start_cubes**3 + 8 * (_MAX_DEPTH + 1)
    centres = np.empty((cap, 3))
    halves = np.empty(cap)
    depths = np.empty(cap, np.int64)
    ids = np.empty(cap, np.int64)  # a cube's row in `grid` (from its depth's first), at the table depths
    top = 0
    h0 = math.pi / start_cubes
    for i in range(start_cubes):
        for j in range(start_cubes):
            for k in range(start_cubes):
                centres[top, 0], centres[top, 1], centres[top, 2] = _start_centre(i, j, k, h0)
                halves[top] = h0
                depths[top] = 0
                ids[top] = (i * start_cubes + j) * start_cubes + k
                top += 1
    root3 = math.sqrt(3.0)
    terms = np.zeros(6)
    rot = np.empty((3, 3))  # the rotation at the centre of the cube looked at
    looked, direct = 0, 0
    while top > 0:
        top -= 1
        cx, cy, cz, h, depth, cube = (
            centres[top, 0],
            centres[top, 1],
            centres[top, 2],
            halves[top],
            depths[top],
            ids[top],
        )
        if math.sqrt(cx * cx + cy * cy + cz * cz) - root3 * h > math.pi:
            continue  # no rotation needs it: the ball |r| <= pi holds them all
        looked += 1
        stats[depth, 0] += 1
        if looked > max_cubes:
            return -looked
        delta = root3 * h
        bound = 0.0
        terms[:] = 0.0  # each (side, axis)'s table term, where read
        if depth < len(levels):  # the level made for this depth's cubes, its cells read off the grid
            if not grid.shape[0]:
                _set_rotation(rot, cx, cy, cz)
            for c in range(6):
                side, k = c // 3, c % 3
                if grid.shape[0]:
                    row = firsts[depth] + grid[grid_firsts[depth] + cube, c]
                else:  # no grid given: the cells of the centre's directions (what the grid holds)
                    u0, u1, u2 = _axis_direction(rot, side, k)
                    row = firsts[depth] + _cell_of(u0, u1, u2, levels[depth])
                term = memo[row, c]
                if term < 0.0:
                    table, step = (a_table, a_step) if side == 0 else (b_table, b_step)
                    term = _table_term(table, step, row, widths[side, k], counts[side], limit)
                    memo[row, c] = term
                terms[c] = term
                bound += term
                if bound > limit:
                    break
            if bound <= limit and depth >= direct_from and grid.shape[0]:
                _set_rotation(rot, cx, cy, cz)  # (for the direct evaluation)
        else:  # a lazy level: the one made for this depth, or the last (valid for smaller cubes)
            _set_rotation(rot, cx, cy, cz)
            q = min(depth - len(levels), len(lazy_levels) - 1)
            for side in range(2):
                for k in range(3):
                    u0, u1, u2 = _axis_direction(rot, side, k)
                    row = _cell_of(u0, u1, u2, lazy_levels[q])
                    key = ((side * 16 + q) << 40) | row
                    if key in slots:
                        slot = slots[key]
                    else:
                        slot = len(slots)
                        if slot == lazy.shape[0]:
                            grown = np.empty((2 * slot, lazy.shape[1]))
                            grown[:slot] = lazy
                            lazy = grown
                            grown_memo = np.empty((2 * slot, 3))
                            grown_memo[:slot] = lazy_memo
                            lazy_memo = grown_memo
                        _table_row(
                            ap if side == 0 else bp,
                            lazy_cells[lazy_firsts[q] + row],
                            _level_delta(len(levels) + q, start_cubes),
                            work[side],
                            lazy[slot],
                        )
                        lazy_memo[slot] = -1.0
                        slots[key] = slot
                    term = lazy_memo[slot, k]
                    if term < 0.0:
                        term = _table_term(lazy, 1.0, slot, widths[side, k], counts[side], limit)
                        lazy_memo[slot, k] = term
                    terms[3 * side + k] = term
                    bound += term
                    if bound > limit:
                        break
                if bound > limit:
                    break
        if bound > limit:
            stats[depth, 1] += 1
            continue
        if depth >= direct_from:
            direct += 1
            if direct > max_direct:
                return -looked
            # at the first depth evaluated directly: first over a subset of the points (dropping
            # points only lowers the bound), then over all of them
            passes = 2 if depth == direct_from else 1
            for p in range(passes):
                if depth == direct_from:
                    _read_first(act, n_act, depth, counts, subset if p + 1 < passes else n_max)
                bound, at_centre = _direct_bound(
                    ap,
                    ar,
                    bp,
                    br,
                    widths,
                    rot,
                    delta,
                    limit,
                    act,
                    n_act,
                    depth,
                    proj,
                    low,
                    high,
                    spare,
                    start,
                    np.argsort(-terms),
                )
                if bound > limit:
                    break
            if bound > limit:
                stats[depth, 2] += 1
                continue
            if at_centre <= limit:
                return -looked  # a rotation within the threshold by this bound
        if h < min_half or depth + 1 > _MAX_DEPTH:
            return -looked  # too fine to go on
        for d in range(8):
            centres[top, 0], centres[top, 1], centres[top, 2] = _child_centre(cx, cy, cz, h, d)
            halves[top] = 0.5 * h
            depths[top] = depth + 1
            ids[top] = 8 * cube + d if depth + 1 < len(levels) else -1
            top += 1
    return looked
