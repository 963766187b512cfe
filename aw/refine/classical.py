"""``classical``: pairwise fracture-surface registration for two-fragment tasks, no model weights.

1. Each fragment's mesh is split into smooth regions (faces joined across edges bending less than
   ``SMOOTH_DEG``). Candidate fracture surfaces are the regions covering at least
   ``MIN_REGION_SHARE`` of the fragment that are not planar (an unbroken face of the original
   object is flat or smoothly curved; a break is rough). A planar contact is never a fracture:
   it would let two end caps or two side walls pass for one.
2. Global search (no initial poses, or ``options["mode"] == "global"``): for every pair of
   candidate regions (anchor, other), the other region is turned so that its mean outward normal
   faces the anchor region's, centroids together, at ``IN_PLANE_STEPS`` angles about that normal;
   each start is refined by ICP restricted to the two regions (point-to-plane with a weak
   point-to-point term, correspondences only between opposed normals, a shrinking radius).
3. Local refinement (initial poses given, the default then): the same ICP from the given relative
   pose, restricted to the candidate regions, with the radius starting at ``LOCAL_RADIUS`` of
   the object's size.
4. Every result is scored by how much of the two regions meet (points with an opposed partner
   within a tolerance whose tangent plane is within a quarter of it; the smaller of the two
   shares) minus twice the share of the other fragment's samples that sink into the anchor; the
   best wins. The anchor keeps its pose.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from aw.prepare.official_protocol import pose_of, rotation_of
from aw.refine.base import RefineRequest

__all__ = ["refine", "register_pair", "segment_regions"]

SMOOTH_DEG = 30.0
MIN_REGION_SHARE = 0.05
PLANAR_RMS = 2e-3  # plane-fit RMS over the fragment's size below which a region is flat
IN_PLANE_STEPS = 24
ICP_ITERATIONS = 30
REGION_POINTS = 700
COARSE_POINTS = 250
COARSE_ITERATIONS = 15
FINE_STARTS = 4
BODY_POINTS = 2000
LOCAL_RADIUS = 0.15
OPPOSED = -0.5  # cosine below which two normals face each other
PLANE_SHARE = 0.25  # of the neighbour tolerance: how far off a partner's tangent plane a point may lie


class _Surface:
    """Area-weighted samples ``points (n, 3)`` with outward face normals ``normals (n, 3)``."""

    def __init__(self, points: np.ndarray, normals: np.ndarray):
        self.points, self.normals = points, normals
        self.tree = cKDTree(points)


def _sample(mesh: trimesh.Trimesh, faces: np.ndarray, count: int, rng: np.random.Generator) -> _Surface:
    tri = mesh.triangles[faces]
    area = mesh.area_faces[faces]
    pick = rng.choice(len(faces), size=count, p=area / area.sum())
    u = rng.random((count, 2))
    s = np.sqrt(u[:, 0])
    w = np.column_stack((1 - s, s * (1 - u[:, 1]), s * u[:, 1]))
    return _Surface(np.einsum("ni,nij->nj", w, tri[pick]), mesh.face_normals[faces][pick])


def segment_regions(mesh: trimesh.Trimesh, smooth_deg: float = SMOOTH_DEG) -> list[np.ndarray]:
    """Face-index arrays of the smooth regions, largest area first."""
    adj = mesh.face_adjacency
    keep = mesh.face_adjacency_angles < np.radians(smooth_deg)
    n = len(mesh.faces)
    graph = coo_matrix((np.ones(int(keep.sum())), (adj[keep, 0], adj[keep, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    regions = [np.flatnonzero(labels == k) for k in range(labels.max() + 1)]
    return sorted(regions, key=lambda f: -mesh.area_faces[f].sum())


def _candidates(mesh: trimesh.Trimesh, size: float) -> list[np.ndarray]:
    """Candidate fracture regions: large enough and not planar (all large regions if none is)."""
    total = mesh.area
    large = [f for f in segment_regions(mesh) if mesh.area_faces[f].sum() >= MIN_REGION_SHARE * total]
    rough = []
    for f in large:
        c = mesh.triangles_center[f]
        w = mesh.area_faces[f]
        centred = c - np.average(c, axis=0, weights=w)
        normal = np.linalg.eigh((centred * w[:, None]).T @ centred)[1][:, 0]
        rms = np.sqrt(np.average((centred @ normal) ** 2, weights=w))
        if rms > PLANAR_RMS * size:
            rough.append(f)
    return (rough or large)[:4]


def _icp(
    src: _Surface,
    dst: _Surface,
    rot: np.ndarray,
    shift: np.ndarray,
    radius: float,
    floor: float,
    iterations: int = ICP_ITERATIONS,
) -> tuple[np.ndarray, np.ndarray]:
    """Move ``src`` onto ``dst`` (opposed normals only); returns the refined ``(R (3, 3), t (3,))``."""
    for _ in range(iterations):
        p = src.points @ rot.T + shift
        n = src.normals @ rot.T
        d, found = dst.tree.query(p, distance_upper_bound=radius)
        j = np.asarray(found)  # (k,) rows; a miss is len(dst.points), where d is inf
        ok = np.isfinite(d)
        ok[ok] &= np.einsum("ij,ij->i", n[ok], dst.normals[j[ok]]) < OPPOSED
        if ok.sum() < 12:
            break
        ps, q, m = p[ok], dst.points[j[ok]], dst.normals[j[ok]]
        plane = np.hstack([np.cross(ps, m), m])
        rhs = np.einsum("ij,ij->i", q - ps, m)
        # a weak point-to-point term keeps flat stretches from sliding freely
        skew = np.zeros((len(ps), 3, 3))
        skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = ps[:, 2], -ps[:, 1], ps[:, 0]
        skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = -ps[:, 2], ps[:, 1], -ps[:, 0]
        point = np.concatenate([skew, np.broadcast_to(np.eye(3), skew.shape)], axis=2).reshape(-1, 6)
        a = np.vstack([plane, 0.2 * point])
        b = np.concatenate([rhs, 0.2 * (q - ps).reshape(-1)])
        x = np.linalg.lstsq(a, b, rcond=None)[0]
        step = Rotation.from_rotvec(x[:3]).as_matrix()
        rot, shift = step @ rot, step @ shift + x[3:]
        radius = max(floor, 0.7 * radius)
        if np.linalg.norm(x) < 1e-9:
            break
    return rot, shift


def _coverage(a: _Surface, b: _Surface, rot: np.ndarray, shift: np.ndarray, eps: float) -> float:
    """The smaller of two shares: points of ``b`` (moved) with an opposed partner in ``a`` within
    ``eps`` that lies within ``PLANE_SHARE * eps`` of the partner's tangent plane, and the same
    for ``a`` in ``b``. The tight plane distance tells an exact fit of rough surfaces from a
    near-symmetric one that only comes close."""
    p, n = b.points @ rot.T + shift, b.normals @ rot.T

    def share(src, src_n, dst, dst_n, tree) -> float:
        d, j = tree.query(src, distance_upper_bound=eps)
        ok = np.isfinite(d)
        hit = ok.copy()
        k = j[ok]
        hit[ok] = (np.einsum("ij,ij->i", src_n[ok], dst_n[k]) < OPPOSED) & (
            np.abs(np.einsum("ij,ij->i", src[ok] - dst[k], dst_n[k])) < PLANE_SHARE * eps
        )
        return float(hit.mean())

    return min(share(p, n, a.points, a.normals, a.tree), share(a.points, a.normals, p, n, cKDTree(p)))


def _sunk(anchor_body: _Surface, other_body: _Surface, rot: np.ndarray, shift: np.ndarray, eps: float) -> float:
    """Share of the other fragment's samples inside the anchor (behind its nearest surface point)."""
    p = other_body.points @ rot.T + shift
    d, j = anchor_body.tree.query(p)
    depth = np.einsum("ij,ij->i", p - anchor_body.points[j], anchor_body.normals[j])
    return float(np.mean(depth < -2 * eps))


def register_pair(
    anchor: trimesh.Trimesh, other: trimesh.Trimesh, start: tuple[np.ndarray, np.ndarray] | None, seed: int = 42
) -> tuple[np.ndarray, np.ndarray, float]:
    """``(R, t, score)`` mapping ``other``'s frame into ``anchor``'s so that their fracture
    surfaces meet; ``start`` (R, t) asks for local refinement from it instead of a global search."""
    rng = np.random.default_rng(seed)
    size = float(np.ptp(np.vstack([anchor.vertices, other.vertices]), axis=0).max())
    regions_a, regions_b = _candidates(anchor, size), _candidates(other, size)
    body_a = _sample(anchor, np.arange(len(anchor.faces)), BODY_POINTS, rng)
    body_b = _sample(other, np.arange(len(other.faces)), BODY_POINTS, rng)
    spacing = np.sqrt(max(anchor.area, other.area) / BODY_POINTS)
    eps = max(2.0 * spacing, 5e-3 * size)

    def score(sa: _Surface, sb: _Surface, rot: np.ndarray, shift: np.ndarray) -> float:
        return _coverage(sa, sb, rot, shift, eps) - 2.0 * _sunk(body_a, body_b, rot, shift, eps)

    if start is not None:
        sa = _sample(anchor, np.concatenate(regions_a), 2 * REGION_POINTS, rng)
        sb = _sample(other, np.concatenate(regions_b), 2 * REGION_POINTS, rng)
        rot, shift = _icp(sb, sa, start[0], start[1], LOCAL_RADIUS * size, eps)
        return rot, shift, score(sa, sb, rot, shift)
    # coarse: every start, few points and iterations; fine: the best few, more of both
    coarse_a = [(fa, _sample(anchor, fa, COARSE_POINTS, rng), _mean_normal(anchor, fa)) for fa in regions_a]
    coarse_b = [(fb, _sample(other, fb, COARSE_POINTS, rng), _mean_normal(other, fb)) for fb in regions_b]
    # (score, order found, face regions of a and b, rotation (3, 3), shift (3,))
    found: list[tuple[float, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    for fa, sa, na in coarse_a:
        for fb, sb, nb in coarse_b:
            face = Rotation.align_vectors([-na], [nb])[0].as_matrix()
            for angle in np.arange(IN_PLANE_STEPS) * 2 * np.pi / IN_PLANE_STEPS:
                rot = Rotation.from_rotvec(angle * na).as_matrix() @ face
                shift = sa.points.mean(0) - rot @ sb.points.mean(0)
                rot, shift = _icp(sb, sa, rot, shift, 0.5 * size, eps, COARSE_ITERATIONS)
                found.append((score(sa, sb, rot, shift), len(found), fa, fb, rot, shift))
    found.sort(key=lambda x: (-x[0], x[1]))
    best = (np.eye(3), np.zeros(3), -np.inf)
    for _, _, fa, fb, rot, shift in found[:FINE_STARTS]:
        sa, sb = _sample(anchor, fa, REGION_POINTS, rng), _sample(other, fb, REGION_POINTS, rng)
        rot, shift = _icp(sb, sa, rot, shift, 4 * eps, eps)
        value = score(sa, sb, rot, shift)
        if value > best[2]:
            best = (rot, shift, value)
    return best


def _mean_normal(mesh: trimesh.Trimesh, faces: np.ndarray) -> np.ndarray:
    n = np.average(mesh.face_normals[faces], axis=0, weights=mesh.area_faces[faces])
    return n / max(np.linalg.norm(n), 1e-12)


def refine(request: RefineRequest) -> np.ndarray:
    """Poses ``(2, 7)`` for a two-fragment request: the anchor keeps its initial pose, the other
    fragment is registered onto it (see the module docstring)."""
    if len(request.part_ids) != 2:
        raise ValueError(f"the classical refiner handles two-fragment tasks, got {len(request.part_ids)} parts")
    a = request.anchor
    b = 1 - a
    mesh = [trimesh.Trimesh(v, f, process=True) for v, f in request.meshes]  # merged vertices: adjacency
    init = request.initial_poses
    ra, ta = rotation_of(init[a, 3:]), init[a, :3]
    start = None
    mode = request.options.get("mode", "local" if request.given_initial_poses else "global")
    if mode not in ("local", "global"):
        raise ValueError(f"option mode must be local or global, got {mode!r}")
    if mode == "local":
        rb, tb = rotation_of(init[b, 3:]), init[b, :3]
        start = (ra.T @ rb, ra.T @ (tb - ta))  # other's mesh frame -> anchor's mesh frame
    rot, shift, _ = register_pair(mesh[a], mesh[b], start, seed=request.seed)
    out = np.array(init, dtype=np.float64)
    out[b] = pose_of(ta + ra @ shift, ra @ rot)
    return out
