"""The official preparation protocol: the task geometry and evaluation inputs exactly as the
official benchmark prepares them (``assembly_world_agent/preparation.py`` of
AssemblyWorld/assembly-world-agent), number for number.

From an object's parts (source-frame vertices, polygon faces, assembled poses, each pose read
as the official adapters read it, :func:`adapter_pose`):

1. ``scale = 2 * max_i max_v |v - mean(V_i)|`` over all vertices of each part (source units).
2. Normalization: the assembled object rotated to Z up, centred in XY on its box centre and
   grounded at its lowest point, divided by ``scale``.
3. Each part in its vertex-PCA frame (:func:`pca_frame`), divided by ``scale``.
4. Points: 4096 area-weighted surface samples of the (earcut-triangulated) local mesh from the
   stream ``(seed, dataset, sample, part, "surface")``, then farthest-point sampling to 1000
   from a first index drawn from ``(seed, dataset, sample, part, "fps")``.
5. Initial layout: a yaw per part from ``(seed, dataset, sample, part, "yaw")``, rejection-sampled
   XY positions from ``(seed, dataset, sample, "placement")`` (:func:`place_parts`); every mesh,
   cloud and target is baked into that layout (initial body poses are the identity).
6. Scale divisor: the largest PCA-box diagonal of the baked parts' vertices (all of them).
7. Equivalence groups: :func:`aw.prepare.official_similarity.geometry_groups`.

Every random stream is a PCG64 seeded with the first 16 bytes (little endian) of the SHA-256 of
the compact JSON ``[seed, *identity]`` (:func:`stream`), so a part's numbers depend only on its
own identity, never on iteration order.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from aw.pair_search import local_workers
from aw.prepare.official_frame import pca_frame

__all__ = [
    "SURFACE_POINTS",
    "FPS_POINTS",
    "MIN_GAP",
    "OfficialPart",
    "OfficialSample",
    "OfficialPrepared",
    "stream",
    "pca_frame",
    "adapter_pose",
    "triangulate",
    "sample_surface",
    "farthest_point_sample",
    "farthest_point_samples",
    "place_parts",
    "evaluation_scale",
    "fracture_divisor",
    "surface_area",
    "allocate_fracture_samples",
    "fracture_samples",
    "prepare_official",
]

SURFACE_POINTS = 4096
FPS_POINTS = 1000
MIN_GAP = 0.02  # the official PreparationConfig.min_gap (normalized units)
IDENTITY_POSE = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
# The fracture protocol's shared samples (``evaluation/garf.py``): 5000 in all, at least 20 a part.
FRACTURE_SEED = 42
FRACTURE_TOTAL = 5000
FRACTURE_MINIMUM = 20


@dataclass(frozen=True)
class OfficialPart:
    """One source part as the official adapters see it: ``vertices (n, 3)`` float64 in the source
    frame (every vertex, referenced or not), ``faces``: polygons (index tuples of 3 or more),
    ``pose (7,)``: the assembled pose ``[tx, ty, tz, qw, qx, qy, qz]`` of the part."""

    part_id: str
    vertices: np.ndarray
    faces: tuple[tuple[int, ...], ...]
    pose: tuple[float, ...] = IDENTITY_POSE


@dataclass(frozen=True)
class OfficialSample:
    """The identity and geometry the official preparation reads: ``dataset`` is the Hugging Face
    repository id (e.g. ``AssemblyWorld/partnet-manualpa``), ``source_to_z_up (3, 3)``."""

    dataset: str
    sample_id: str
    parts: tuple[OfficialPart, ...]
    source_to_z_up: np.ndarray = field(default_factory=lambda: np.eye(3))


@dataclass
class OfficialPrepared:
    """Prepared geometry, parts sorted by id: baked meshes ``(n_i, 3)`` with their faces, the
    evaluation points ``(P, 1000, 3)`` (baked frame), target poses ``(P, 7)`` mapping baked onto
    assembled, the scale divisor and the equivalence groups (sorted part-id lists)."""

    part_ids: list[str]
    vertices: list[np.ndarray]
    faces: list[tuple[tuple[int, ...], ...]]
    points: np.ndarray
    targets: np.ndarray
    divisor: float
    groups: list[list[str]]
    scale: float
    fracture_divisor: float
    dataset: str
    sample_id: str


def stream(seed: int, *identity: str) -> np.random.Generator:
    """The random stream of ``identity`` under ``seed`` (see the module doc)."""
    text = json.dumps([int(seed), *identity], ensure_ascii=True, separators=(",", ":"))
    key = int.from_bytes(hashlib.sha256(text.encode()).digest()[:16], "little")
    return np.random.Generator(np.random.PCG64(key))


# ------------------------------------------------------------------ frames and poses


def rotation_of(quaternion: ArrayLike) -> np.ndarray:
    """``(3, 3)`` rotation of a ``(w, x, y, z)`` quaternion (normalized by SciPy)."""
    q = np.asarray(quaternion, dtype=np.float64)
    return Rotation.from_quat(q[[1, 2, 3, 0]]).as_matrix()


def pose_of(position: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """``(7,)`` pose of a position and a proper rotation, quaternion canonical (``w >= 0``)."""
    if not np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-10, rtol=0) or not np.isclose(
        np.linalg.det(rotation), 1, atol=1e-10, rtol=0
    ):
        raise ValueError("rotation is not orthonormal and right-handed")
    quat = Rotation.from_matrix(rotation).as_quat(canonical=True)[[3, 0, 1, 2]]
    return np.concatenate([np.asarray(position, dtype=np.float64), quat])


def adapter_pose(values: Sequence[float]) -> np.ndarray:
    """``(7,)`` an assembled pose ``[tx, ty, tz, qw, qx, qy, qz]`` as the official adapters read
    it (``utils/transforms.py`` ``pose_from_values``): the quaternion, of any non-zero length
    and either sign, becomes SciPy's rotation matrix and then that matrix's canonical quaternion
    (:func:`pose_of`, ``w >= 0``), so the preparation works from the same bits as the official."""
    pose = np.asarray(values, dtype=np.float64)
    if pose.shape != (7,) or not np.isfinite(pose).all():
        raise ValueError(f"a pose needs 7 finite numbers [tx, ty, tz, qw, qx, qy, qz], got {pose.tolist()!r}")
    if np.linalg.norm(pose[3:]) < 1e-12:
        raise ValueError(f"a pose's quaternion must be non-zero, got {pose[3:].tolist()!r}")
    return pose_of(pose[:3], rotation_of(pose[3:]))


def moved(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """``points (n, 3)`` under ``pose (7,)`` (rotation taken from its quaternion)."""
    return np.asarray(points) @ rotation_of(pose[3:]).T + pose[:3]


# ------------------------------------------------------------------ sampling


def triangulate(vertices: np.ndarray, faces: Sequence[Sequence[int]]) -> np.ndarray:
    """Triangles ``(m, 3)`` for sampling: triangles as given, other polygons ear-cut (mapbox
    earcut) in their best-fit plane; degenerate polygons and zero-area triangles are left out."""
    import mapbox_earcut

    tris = []
    for face in faces:
        idx = np.asarray(face, dtype=np.int64)
        if len(idx) == 3:
            tris.append(idx[None, :])
            continue
        corners = vertices[idx]
        centred = corners - corners.mean(axis=0)
        _, singular, axes = np.linalg.svd(centred, full_matrices=False)
        if singular[1] <= np.finfo(float).eps * singular[0]:
            continue
        flat = np.ascontiguousarray(centred @ axes[:2].T)
        cut = mapbox_earcut.triangulate_float64(flat, np.array([len(idx)], dtype=np.uint32)).reshape(-1, 3)
        if len(cut) != len(idx) - 2:
            raise ValueError("a polygon could not be fully triangulated")
        tris.append(idx[cut])
    if not tris:
        raise ValueError("the mesh has zero effective surface area")
    tris_all = np.concatenate(tris)
    xyz = vertices[tris_all]
    area = np.linalg.norm(np.cross(xyz[:, 1] - xyz[:, 0], xyz[:, 2] - xyz[:, 0]), axis=1)
    if not np.isfinite(area).all() or not (area > 0).any():
        raise ValueError("the mesh has zero or invalid surface area")
    return tris_all[area > 0]


def sample_surface(vertices: np.ndarray, faces, count: int, rng: np.random.Generator) -> np.ndarray:
    """``(count, 3)`` area-weighted surface points: a triangle per point (one ``choice``), then
    ``u (count, 2)`` uniforms, barycentric weights ``(1 - s, s (1 - u1), s u1)`` with ``s = sqrt(u0)``."""
    xyz = vertices[triangulate(vertices, faces)]
    areas = np.linalg.norm(np.cross(xyz[:, 1] - xyz[:, 0], xyz[:, 2] - xyz[:, 0]), axis=1)
    chosen = xyz[rng.choice(len(xyz), size=count, p=areas / areas.sum())]
    u = rng.random((count, 2))
    s = np.sqrt(u[:, 0])
    weights = np.column_stack((1 - s, s * (1 - u[:, 1]), s * u[:, 1]))
    return np.einsum("ni,nij->nj", weights, chosen)


def farthest_point_sample(points: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """Indices ``(count,)``: a random first index (one ``integers`` draw), then each time the point
    farthest (squared distance) from those chosen; ties go to the lowest index."""
    if not 0 < count <= len(points):
        raise ValueError(f"farthest-point sampling needs 0 < count <= {len(points)}, got {count}")
    chosen = np.empty(count, dtype=np.int64)
    nearest = np.full(len(points), np.inf)
    taken = np.zeros(len(points), dtype=bool)
    current = int(rng.integers(len(points)))
    for k in range(count):
        chosen[k] = current
        taken[current] = True
        d = points - points[current]
        nearest = np.minimum(nearest, np.einsum("ij,ij->i", d, d))
        nearest[taken] = -np.inf
        current = int(np.argmax(nearest))
    return chosen


@lru_cache(maxsize=1)
def _einsum_sums_x_z_then_y() -> bool:
    """Whether this NumPy's ``einsum("ij,ij->i", d, d)`` rounds as ``(x x + z z) + y y`` (its
    two-lane loop does here), checked on spread-out random rows, once per process."""
    d = np.random.default_rng(0).normal(size=(4096, 3)) * [1.0, 30.0, 0.01] + 7.0
    return bool(
        np.array_equal(np.einsum("ij,ij->i", d, d), (d[:, 0] * d[:, 0] + d[:, 2] * d[:, 2]) + d[:, 1] * d[:, 1])
    )


def farthest_point_samples(points: np.ndarray, count: int, firsts: Sequence[int], chunk: int = 16) -> np.ndarray:
    """:func:`farthest_point_sample` of many clouds ``points (P, n, 3)`` at once, from given first
    indices ``firsts (P,)`` (each drawn from its own part's stream): indices ``(P, count)``, the same
    ones (the tests compare them index for index). Each step serves ``chunk`` clouds, with the
    coordinates in separate rows and the squared distance rounded as the single version's
    ``einsum`` rounds it (:func:`_einsum_sums_x_z_then_y`; else that ``einsum``, batched): about
    3.5x less CPU time than one cloud at a time, and the chunks run on the process's threads
    (:func:`aw.pair_search.local_workers`). A point once chosen keeps ``-inf`` (``minimum``
    cannot raise it), as the mask there does."""
    points = np.asarray(points, dtype=np.float64)
    n_clouds, n = points.shape[:2]
    if not 0 < count <= n:
        raise ValueError(f"farthest-point sampling needs 0 < count <= {n}, got {count}")
    rowwise = _einsum_sums_x_z_then_y()
    chosen = np.empty((n_clouds, count), dtype=np.int64)

    def sample_chunk(lo: int) -> None:
        block = points[lo : lo + chunk]
        xs, ys, zs = (np.ascontiguousarray(block[..., c]) for c in range(3))
        rows = np.arange(len(block))
        nearest = np.full(block.shape[:2], np.inf)
        current = np.asarray(firsts[lo : lo + chunk], dtype=np.int64)
        for k in range(count):
            chosen[lo : lo + chunk, k] = current
            if rowwise:
                dx = xs - xs[rows, current][:, None]
                dy = ys - ys[rows, current][:, None]
                dz = zs - zs[rows, current][:, None]
                squared = dx * dx + dz * dz + dy * dy
            else:
                d = block - block[rows, current][:, None, :]
                squared = np.einsum("pij,pij->pi", d, d)
            np.minimum(nearest, squared, out=nearest)
            nearest[rows, current] = -np.inf
            current = np.argmax(nearest, axis=1)

    starts = range(0, n_clouds, chunk)
    workers = min(local_workers(), len(starts))
    if workers > 1:  # chunks are independent, and NumPy's array work runs outside the GIL
        with ThreadPoolExecutor(workers) as pool:
            list(pool.map(sample_chunk, starts))
    else:
        for lo in starts:
            sample_chunk(lo)
    return chosen


# ------------------------------------------------------------------ layout and scale


def _apart_from_all(box: np.ndarray, others: np.ndarray, gap: float) -> bool:
    """Whether the XY box ``box (2, 2)`` (``[min, max]``) keeps ``gap`` from every box of ``others
    (k, 2, 2)`` along X or Y; one NumPy call, since placing P parts makes P^2 comparisons."""
    if not len(others):
        return True
    return bool(np.all(np.any(box[1] + gap <= others[:, 0], axis=1) | np.any(others[:, 1] + gap <= box[0], axis=1)))


def place_parts(
    local: dict[str, np.ndarray],
    dataset: str,
    sample_id: str,
    seed: int,
    gap: float = MIN_GAP,
    attempts: int = 128,
    expansions: int = 5,
) -> dict[str, np.ndarray]:
    """Initial pose ``(7,)`` per part: a random yaw, then XY positions drawn in a square (grown 1.5x
    up to ``expansions`` times) until every part's XY box keeps ``gap`` from the earlier ones, a
    grid when that fails; the layout is centred on the origin and every part rests on ``z = 0``."""
    ids = sorted(local)
    yawed, turns, boxes = {}, {}, {}
    for pid in ids:
        yaw = stream(seed, dataset, sample_id, pid, "yaw").uniform(-np.pi, np.pi)
        c, s = np.cos(yaw), np.sin(yaw)
        turn = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        yawed[pid], turns[pid] = local[pid] @ turn.T, turn
        boxes[pid] = np.array([yawed[pid][:, :2].min(0), yawed[pid][:, :2].max(0)])
    rng = stream(seed, dataset, sample_id, "placement")
    order = [ids[i] for i in rng.permutation(len(ids))]
    widest = max(float(np.max(b[1] - b[0])) for b in boxes.values())
    side = (widest + gap) * np.ceil(np.sqrt(len(ids)))
    where: dict[str, np.ndarray] = {}
    for _ in range(expansions):
        placed, where = np.empty((len(ids), 2, 2)), {}
        for pid in order:
            for _try in range(attempts):
                xy = rng.uniform(-side / 2, side / 2, size=2)
                box = boxes[pid] + xy
                if _apart_from_all(box, placed[: len(where)], gap):
                    placed[len(where)] = box
                    where[pid] = xy
                    break
            else:
                break
        if len(where) == len(ids):
            break
        side *= 1.5
    if len(where) != len(ids):
        columns = int(np.ceil(np.sqrt(len(ids))))
        pitch = widest + gap + 1e-12  # the margin keeps ">= gap" true after rounding
        for slot, pid in enumerate(order):
            where[pid] = np.array([slot % columns, slot // columns]) * pitch - boxes[pid].mean(0)
    final = [boxes[pid] + where[pid] for pid in ids]
    middle = (np.min([b[0] for b in final], axis=0) + np.max([b[1] for b in final], axis=0)) / 2
    poses = {pid: pose_of(np.r_[where[pid] - middle, -yawed[pid][:, 2].min()], turns[pid]) for pid in ids}
    shifted = np.stack([boxes[pid] + poses[pid][:2] for pid in ids])
    for i, box in enumerate(shifted):
        if not _apart_from_all(box, shifted[:i], gap - 1e-12):
            raise ValueError("the initial layout failed its final non-overlap check")
    return poses


def evaluation_scale(vertices: Sequence[np.ndarray]) -> float:
    """The largest diagonal of a part's vertices ``(n_i, 3)`` in its own PCA frame."""
    diagonals = []
    for v in vertices:
        center, basis = pca_frame(v)
        diagonals.append(float(np.linalg.norm(np.ptp((v - center) @ basis, axis=0))))
    divisor = max(diagonals)
    if not np.isfinite(divisor) or divisor <= 0:
        raise ValueError("invalid evaluation scale")
    return divisor


def fracture_divisor(source_vertices: Sequence[np.ndarray], source_to_task: np.ndarray) -> float:
    """The fracture protocol's divisor (``evaluation/garf.py``): ``max(1, largest per-part
    axis-aligned extent of the source meshes (n_i, 3))`` times the norm of the first column of
    the ``(4, 4)`` source -> task matrix (the task's scale)."""
    extent = max(1.0, *(float(np.ptp(np.asarray(v, dtype=np.float64), axis=0).max()) for v in source_vertices))
    return extent * float(np.linalg.norm(np.asarray(source_to_task)[:3, 0]))


def surface_area(vertices: np.ndarray, faces) -> float:
    """Half the summed cross-product norms of the mesh's sampling triangles (:func:`triangulate`)."""
    v = np.asarray(vertices, dtype=np.float64)
    xyz = v[triangulate(v, faces)]
    return float(np.linalg.norm(np.cross(xyz[:, 1] - xyz[:, 0], xyz[:, 2] - xyz[:, 0]), axis=1).sum() / 2)


def allocate_fracture_samples(areas, total: int = FRACTURE_TOTAL, minimum: int = FRACTURE_MINIMUM) -> np.ndarray:
    """Samples per part ``(P,)``: ``minimum`` each plus the area share of the rest (truncated);
    the remainder to the part with the most (first on ties)."""
    a = np.asarray(areas, dtype=float).reshape(-1)
    if a.size == 0 or not np.isfinite(a).all() or (a <= 0).any() or total < minimum * a.size:
        raise ValueError(f"need positive finite areas and total >= {minimum} per part, got {a.size} parts for {total}")
    counts = minimum + ((total - minimum * a.size) * a / a.sum()).astype(int)
    counts[np.argmax(counts)] += total - counts.sum()
    return counts


def fracture_samples(
    meshes: Sequence[tuple[np.ndarray, ArrayLike]],
    part_ids: Sequence[str],
    dataset: str,
    sample_id: str,
    seed: int = FRACTURE_SEED,
) -> list[np.ndarray]:
    """The fracture protocol's shared samples of the part meshes ``(vertices (n_i, 3), faces)``
    (in ``part_ids`` order): a list of ``(c_i, 3)`` arrays in the meshes' frame, ``c_i`` from
    :func:`allocate_fracture_samples`, part ``i`` drawn from the stream ``(seed, dataset,
    sample_id, part id, "garf-evaluation")``. The anchor is the part with the most samples
    (``argmax`` of the counts, first on ties)."""
    if not meshes or len(meshes) != len(part_ids):
        raise ValueError(f"need one mesh per part id, got {len(meshes)} meshes for {len(part_ids)} ids")
    counts = allocate_fracture_samples([surface_area(v, f) for v, f in meshes])
    return [
        sample_surface(
            np.asarray(v, dtype=np.float64), f, int(n), stream(seed, dataset, sample_id, pid, "garf-evaluation")
        )
        for (v, f), pid, n in zip(meshes, part_ids, counts, strict=True)
    ]


# ------------------------------------------------------------------ the protocol


def _normalization(assembled: np.ndarray, source_to_z_up: np.ndarray, scale: float) -> np.ndarray:
    """``(4, 4)`` source -> task matrix: rotate to Z up, centre in XY, ground, divide by ``scale``."""
    pose_of(np.zeros(3), source_to_z_up)  # refuses a matrix that is not a rotation
    upright = assembled @ source_to_z_up.T
    low, high = upright.min(axis=0), upright.max(axis=0)
    if not np.isfinite(np.linalg.norm(high - low)) or np.linalg.norm(high - low) <= 0:
        raise ValueError("degenerate assembled bounding box")
    origin = (low + high) / 2
    origin[2] = low[2]
    if not np.isfinite(scale) or scale <= 0:
        raise ValueError("degenerate part scale")
    matrix = np.eye(4)
    matrix[:3, :3] = source_to_z_up / scale
    matrix[:3, 3] = -origin / scale
    return matrix


def prepare_official(
    sample: OfficialSample, seed: int = 0, gap: float = MIN_GAP, groups: bool = True
) -> OfficialPrepared:
    """Prepare ``sample`` by the official protocol (sampling and initialization seed ``seed``).

    ``groups=False`` leaves the equivalence groups as singletons (no registration)."""
    from aw.prepare.official_similarity import geometry_groups

    parts = list(sample.parts)
    ids = [p.part_id for p in parts]
    if not parts or len(set(ids)) != len(ids):
        raise ValueError(f"{sample.sample_id}: expected non-empty, unique part ids")
    try:
        poses = [adapter_pose(p.pose) for p in parts]
    except ValueError as exc:
        raise ValueError(f"{sample.dataset}/{sample.sample_id}: {exc}") from None
    assembled = [moved(p.vertices, q) for p, q in zip(parts, poses, strict=True)]
    scale = 2 * max(float(np.linalg.norm(p.vertices - p.vertices.mean(0), axis=1).max()) for p in parts)
    to_task = _normalization(np.concatenate(assembled), np.asarray(sample.source_to_z_up, dtype=np.float64), scale)

    local, candidates, firsts, targets = {}, {}, {}, {}
    for p, q in zip(parts, poses, strict=True):
        center, basis = pca_frame(p.vertices)
        local[p.part_id] = (p.vertices - center) @ basis / scale
        target_center = moved(center, q) @ to_task[:3, :3].T + to_task[:3, 3]
        target_basis = sample.source_to_z_up @ rotation_of(q[3:]) @ basis
        where = (sample.dataset, sample.sample_id, p.part_id)
        try:
            candidates[p.part_id] = sample_surface(
                local[p.part_id], p.faces, SURFACE_POINTS, stream(seed, *where, "surface")
            )
        except ValueError as exc:
            raise ValueError(f"{sample.dataset}/{sample.sample_id}/{p.part_id}: {exc}") from None
        firsts[p.part_id] = int(stream(seed, *where, "fps").integers(SURFACE_POINTS))  # farthest_point_sample's draw
        targets[p.part_id] = pose_of(target_center, target_basis)
    stacked = np.stack([candidates[pid] for pid in ids])
    picked = farthest_point_samples(stacked, FPS_POINTS, [firsts[pid] for pid in ids])
    clouds = {pid: stacked[k][picked[k]].copy() for k, pid in enumerate(ids)}

    initial = place_parts(local, sample.dataset, sample.sample_id, seed, gap)
    baked = {}
    for pid, start in initial.items():  # bake the layout; targets then act on baked geometry
        turn = rotation_of(start[3:])
        target_turn = rotation_of(targets[pid][3:]) @ turn.T
        baked[pid] = moved(local[pid], start)
        clouds[pid] = moved(clouds[pid], start)
        targets[pid] = pose_of(targets[pid][:3] - target_turn @ start[:3], target_turn)

    order = sorted(ids)
    faces = {p.part_id: p.faces for p in parts}
    divisor = evaluation_scale([baked[pid] for pid in ids])
    points = np.stack([clouds[pid] for pid in order])
    verts = [baked[pid] for pid in order]
    found = geometry_groups(order, points, verts, divisor) if groups else [[pid] for pid in order]
    return OfficialPrepared(
        order,
        verts,
        [faces[pid] for pid in order],
        points,
        np.stack([targets[pid] for pid in order]),
        divisor,
        found,
        scale,
        fracture_divisor([p.vertices for p in parts], to_task),
        sample.dataset,
        sample.sample_id,
    )
