"""A fragment as the refiner sees it: samples of its surface, its noise, and the smooth regions
that may be fracture surfaces.

Face normals are first filtered (bilateral: a face's normal moves towards its neighbours' when
they are close to it, never across a sharp rim), so that a scan's noise neither splits a break
into pieces nor hides the rim round it. The mesh is then split into smooth regions (faces joined
across edges whose filtered normals bend less than ``SMOOTH_DEG``); a region is a candidate
contact when it covers at least ``MIN_REGION_SHARE`` of the fragment, and it is planar when a
plane fits it to within ``PLANAR_RMS`` of the object's size above the noise. With three or more
fragments a region also offers its planar parts and, when it wraps round a thin slice, its two
sides as candidates of their own (:func:`_candidates`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

__all__ = ["Cloud", "Fragment", "Region", "filtered_normals", "fragment", "outline", "sample", "segment_regions"]

SMOOTH_DEG = 30.0
FILTER_DEG = 20.0  # neighbours whose normals differ by much more than this do not smooth a face
FILTER_ITERATIONS = 4
MIN_REGION_SHARE = 0.02
MAX_REGIONS = 10
PLANAR_RMS = 2e-3  # of the object's size, above the noise: a flat region
PLANE_DEG = 8.0  # how far a face's normal may stray from its plane's and still lie on it
PLANE_SEEDS = 5
WRAP = 0.5  # a smooth region whose mean normal is shorter than this wraps round: both faces of a thin slice
SIDE_DEG = 60.0  # how far a face's normal may stray from the slice's and still be on one side of it
BODY_POINTS = 3000
REGION_POINTS = 700
COARSE_POINTS = 250
COARSE_BODY_POINTS = 600
OUTLINE_POINTS = 300


@dataclass
class Cloud:
    """Area-weighted surface samples ``points (n, 3)`` with outward normals ``normals (n, 3)``."""

    points: np.ndarray
    normals: np.ndarray
    tree: cKDTree = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.tree = cKDTree(self.points)

    def moved(self, rot: np.ndarray, shift: np.ndarray) -> Cloud:
        return Cloud(self.points @ rot.T + shift, self.normals @ rot.T)


@dataclass
class Region:
    """A candidate contact: its faces, area, area-weighted mean normal and centroid, whether it
    is planar, its extents along its principal axes (``extents (3,)``, descending), samples of
    it (``fine`` for fitting and scoring, ``coarse`` for the search) and, when planar, samples of
    its outline (``outline (k, 3)``, evenly spaced along its boundary edges, with the normals of
    the walls it meets there, ``rim_normals (k, 3)``), and its ``sag``: how
    far its middle stands out along its outward normal from a plane through its rim (a quadric's
    fit; negative for a bulge, positive for a hollow; a break and its match have opposite sags)."""

    faces: np.ndarray
    area: float
    normal: np.ndarray
    centroid: np.ndarray
    planar: bool
    extents: np.ndarray
    fine: Cloud
    coarse: Cloud
    outline: np.ndarray
    rim_normals: np.ndarray
    sag: float


@dataclass
class Fragment:
    """One part: its mesh (merged vertices), whole-surface samples ``body``, the candidate contact
    regions (largest first), and the object's ``size``, the sample ``spacing`` and the surface
    ``noise`` (the median distance of a sample from its neighbours' plane), in mesh units."""

    mesh: trimesh.Trimesh
    body: Cloud
    coarse_body: Cloud
    regions: list[Region]
    size: float
    spacing: float
    noise: float


def sample(
    mesh: trimesh.Trimesh, normals: np.ndarray, faces: np.ndarray, count: int, rng: np.random.Generator
) -> Cloud:
    """``count`` area-weighted samples of ``faces``, each carrying its face's row of ``normals (f, 3)``."""
    tri = mesh.triangles[faces]
    area = mesh.area_faces[faces]
    pick = rng.choice(len(faces), size=count, p=area / area.sum())
    u = rng.random((count, 2))
    s = np.sqrt(u[:, 0])
    w = np.column_stack((1 - s, s * (1 - u[:, 1]), s * u[:, 1]))
    return Cloud(np.einsum("ni,nij->nj", w, tri[pick]), normals[faces][pick])


def filtered_normals(mesh: trimesh.Trimesh, iterations: int = FILTER_ITERATIONS) -> np.ndarray:
    """Face normals ``(f, 3)`` after bilateral filtering over edge neighbours: each pass replaces a
    normal by the area-weighted mean of its own and its neighbours', a neighbour weighted by
    ``exp(-(angle / FILTER_DEG)^2)`` (small angles), so that sharp rims stay sharp."""
    n = np.asarray(mesh.face_normals, dtype=np.float64).copy()
    adj = mesh.face_adjacency
    if not len(adj):
        return n
    i = np.concatenate([adj[:, 0], adj[:, 1]])
    j = np.concatenate([adj[:, 1], adj[:, 0]])
    area = mesh.area_faces
    scale = 1.0 - np.cos(np.radians(FILTER_DEG))
    for _ in range(iterations):
        w = area[j] * np.exp(-(((1.0 - np.einsum("ij,ij->i", n[i], n[j])) / scale) ** 2))
        acc = n * area[:, None]
        np.add.at(acc, i, w[:, None] * n[j])
        n = acc / np.maximum(np.linalg.norm(acc, axis=1, keepdims=True), 1e-15)
    return n


def segment_regions(mesh: trimesh.Trimesh, normals: np.ndarray, smooth_deg: float = SMOOTH_DEG) -> list[np.ndarray]:
    """Face-index arrays of the smooth regions (by the face ``normals (f, 3)``), largest area first."""
    adj = mesh.face_adjacency
    keep = np.einsum("ij,ij->i", normals[adj[:, 0]], normals[adj[:, 1]]) > np.cos(np.radians(smooth_deg))
    n = len(mesh.faces)
    graph = coo_matrix((np.ones(int(keep.sum())), (adj[keep, 0], adj[keep, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    order = np.argsort(labels, kind="stable")
    splits = np.flatnonzero(np.diff(labels[order])) + 1
    regions = np.split(order, splits)
    return sorted(regions, key=lambda f: -mesh.area_faces[f].sum())


def outline(
    mesh: trimesh.Trimesh, normals: np.ndarray, faces: np.ndarray, count: int = OUTLINE_POINTS
) -> tuple[np.ndarray, np.ndarray]:
    """``count`` points ``(count, 3)`` evenly spaced along the boundary edges of a set of faces
    (the edges only one of them has), and at each the normal ``(count, 3)`` (a row of ``normals
    (f, 3)``) of the face across that edge: the wall the region meets there."""
    ends = mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    key = np.sort(ends, axis=1) @ np.array([len(mesh.vertices), 1])  # one number per edge
    inside = np.zeros(len(mesh.faces), dtype=bool)
    inside[faces] = True
    owner = np.repeat(np.arange(len(mesh.faces)), 3)
    own, counts = np.unique(key[inside[owner]], return_counts=True)
    boundary = own[counts == 1]
    outer = ~inside[owner] & np.isin(key, boundary)  # the outside face of each boundary edge
    if not outer.any():
        return np.zeros((0, 3)), np.zeros((0, 3))
    edge_keys, first = np.unique(key[outer], return_index=True)
    across = owner[outer][first]
    edges = ends[outer][first]
    start, end = mesh.vertices[edges[:, 0]], mesh.vertices[edges[:, 1]]
    length = np.linalg.norm(end - start, axis=1)
    at = (np.arange(count) + 0.5) * length.sum() / count
    cum = np.concatenate([[0.0], np.cumsum(length)])
    k = np.clip(np.searchsorted(cum, at, side="right") - 1, 0, len(edges) - 1)
    u = ((at - cum[k]) / np.maximum(length[k], 1e-15))[:, None]
    return start[k] * (1 - u) + end[k] * u, normals[across[k]]


def _sag(cloud: Cloud, normal: np.ndarray, extents: np.ndarray) -> float:
    """The sag of a region's samples: a quadric ``h = a x^2 + b xy + c y^2 + d x + e y + f`` fitted
    over the plane across ``normal``; ``-(a + c) / 2 * (extent / 2)^2``, the mean extent of the
    region's first two principal axes."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    centred = cloud.points - cloud.points.mean(0)
    x, y, h = centred @ u, centred @ v, centred @ normal
    design = np.column_stack([x * x, x * y, y * y, x, y, np.ones_like(x)])
    coef = np.linalg.lstsq(design, h, rcond=None)[0]
    half = 0.25 * (extents[0] + extents[1])
    return float((coef[0] + coef[2]) / 2 * half * half)


def _components(mesh: trimesh.Trimesh, faces: np.ndarray) -> list[np.ndarray]:
    """The edge-connected components of a set of faces."""
    inside = np.zeros(len(mesh.faces), dtype=bool)
    inside[faces] = True
    adj = mesh.face_adjacency
    adj = adj[inside[adj[:, 0]] & inside[adj[:, 1]]]
    n = len(mesh.faces)
    graph = coo_matrix((np.ones(len(adj)), (adj[:, 0], adj[:, 1])), shape=(n, n))
    labels = connected_components(graph, directed=False)[1][faces]
    return [faces[labels == k] for k in np.unique(labels)]


def _planar_parts(mesh: trimesh.Trimesh, normals: np.ndarray, faces: np.ndarray, flat: float) -> list[np.ndarray]:
    """The large planar parts of a smooth region that is not planar as a whole: where a break
    meets the object's surface at a shallow angle the two run into one region, and a planar
    part of it (faces within ``PLANE_DEG`` of a common normal and within ``flat`` of one plane)
    may be a cut face of its own."""
    out = []
    rest = faces
    area = mesh.area_faces
    centres = mesh.triangles_center
    for _ in range(3):
        if area[rest].sum() < MIN_REGION_SHARE * mesh.area:
            break
        seeds = rest[np.argsort(-area[rest])[:200]]
        near = normals[seeds] @ normals[rest].T > np.cos(np.radians(PLANE_DEG))
        best_part = None
        for k in np.argsort(-(near @ area[rest]))[:PLANE_SEEDS]:  # the seeds whose normals are most common
            seed = seeds[k]
            members = rest[near[k]]
            on_plane = members[np.abs((centres[members] - centres[seed]) @ normals[seed]) < flat]
            if len(on_plane):
                part = max(_components(mesh, on_plane), key=lambda f: area[f].sum())
                if best_part is None or area[part].sum() > area[best_part].sum():
                    best_part = part
        if best_part is None or area[best_part].sum() < MIN_REGION_SHARE * mesh.area or len(best_part) == len(rest):
            break
        out.append(best_part)
        rest = np.setdiff1d(rest, best_part)
    return out


def _noise(body: Cloud, k: int = 12) -> float:
    """Median distance of a sample from the plane through its ``k`` nearest neighbours."""
    idx = np.asarray(body.tree.query(body.points, k=k + 1)[1])  # (n, k + 1)
    nb = body.points[idx[:, 1:]]
    centred = nb - nb.mean(axis=1, keepdims=True)
    normal = np.linalg.eigh(np.einsum("nki,nkj->nij", centred, centred))[1][:, :, 0]
    return float(np.median(np.abs(np.einsum("ni,ni->n", body.points - nb.mean(axis=1), normal))))


def _sides(mesh: trimesh.Trimesh, normals: np.ndarray, faces: np.ndarray) -> list[np.ndarray]:
    """The two sides of a smooth region that wraps round (its area-weighted mean normal shorter
    than ``WRAP``), each split into its connected pieces; ``[]`` for a region that does not wrap.
    A thin slice whose break meets the object's surface along a rounded rim is one smooth region,
    both faces and the rim between; its break is one side of it. The sides are the faces whose
    normals lie within ``SIDE_DEG`` of either direction of the axis the region's normals spread
    along most (the slice's normal)."""
    area = mesh.area_faces[faces]
    n = normals[faces]
    if np.linalg.norm(np.average(n, axis=0, weights=area)) > WRAP:
        return []
    axis = np.linalg.eigh((n * area[:, None]).T @ n)[1][:, -1]
    along = n @ axis
    cos = np.cos(np.radians(SIDE_DEG))
    sides = (faces[along > cos], faces[along < -cos])
    return [piece for side in sides if len(side) for piece in _components(mesh, side)]


def _candidates(mesh: trimesh.Trimesh, normals: np.ndarray, faces: np.ndarray, flat: float, keep_whole: bool):
    """A smooth region's candidate contacts: its planar parts (:func:`_planar_parts`) and, with
    ``keep_whole``, the region itself and its two sides when it wraps round (:func:`_sides`) as
    well (with three or more fragments a rough break with flat stretches is still one break to
    some neighbour); else the rest of it, split into its connected pieces (or the region whole
    when it has no planar part)."""
    planar = _planar_parts(mesh, normals, faces, flat)
    if keep_whole:
        return [faces, *planar, *_sides(mesh, normals, faces)]
    if not planar:
        return [faces]
    return planar + _components(mesh, np.setdiff1d(faces, np.concatenate(planar)))


def fragment(
    vertices: np.ndarray, faces: np.ndarray, size: float, rng: np.random.Generator, keep_whole: bool = False
) -> Fragment:
    """The fragment of a part mesh ``(vertices (v, 3), faces (f, 3))``; ``size``: the object's;
    ``keep_whole``: smooth regions stay candidates beside their planar parts (for objects of
    three or more fragments, see :func:`_candidates`)."""
    mesh = trimesh.Trimesh(vertices, faces, process=True)  # merged vertices: adjacency
    normals = filtered_normals(mesh)
    everything = np.arange(len(mesh.faces))
    body = sample(mesh, normals, everything, BODY_POINTS, rng)
    noise = _noise(body)
    parts = []
    for f in segment_regions(mesh, normals):
        if mesh.area_faces[f].sum() < MIN_REGION_SHARE * mesh.area:
            break
        parts += _candidates(mesh, normals, f, PLANAR_RMS * size + 3.0 * noise, keep_whole)
    parts.sort(key=lambda f: -mesh.area_faces[f].sum())
    regions: list[Region] = []
    for f in parts:
        area = float(mesh.area_faces[f].sum())
        if area < MIN_REGION_SHARE * mesh.area or len(regions) == MAX_REGIONS:
            break
        w = mesh.area_faces[f]
        c = mesh.triangles_center[f]
        centroid = np.average(c, axis=0, weights=w)
        centred = c - centroid
        axes = np.linalg.eigh((centred * w[:, None]).T @ centred)[1]
        rms = np.sqrt(np.average((centred @ axes[:, 0]) ** 2, weights=w))
        mean = np.average(normals[f], axis=0, weights=w)
        normal = mean / max(np.linalg.norm(mean), 1e-12)
        fine = sample(mesh, normals, f, REGION_POINTS, rng)
        spread = fine.points - fine.points.mean(0)
        extents = np.sort(np.ptp(spread @ np.linalg.eigh(spread.T @ spread)[1], axis=0))[::-1]
        planar = bool(rms < PLANAR_RMS * size + 2.0 * noise)
        rim, rim_normals = outline(mesh, normals, f) if planar else (np.zeros((0, 3)), np.zeros((0, 3)))
        regions.append(
            Region(
                faces=f,
                area=area,
                normal=normal,
                centroid=centroid,
                planar=planar,
                extents=extents,
                fine=fine,
                coarse=sample(mesh, normals, f, COARSE_POINTS, rng),
                outline=rim,
                rim_normals=rim_normals,
                sag=_sag(fine, normal, extents),
            )
        )
    spacing = float(np.sqrt(mesh.area / BODY_POINTS))
    coarse_body = Cloud(body.points[:COARSE_BODY_POINTS], body.normals[:COARSE_BODY_POINTS])  # samples are random
    return Fragment(mesh, body, coarse_body, regions, size, spacing, noise)
