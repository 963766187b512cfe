"""Checked conversion of published arrays and files into part meshes, shared by the dataset loaders.

Every problem raises :class:`aw.formats.FormatError` naming the file and the field (for example
``parts[2].faces``), never a bare NumPy or trimesh exception.
"""

from __future__ import annotations

import pickle
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from aw.formats import FormatError
from aw.meshes import load_mesh

__all__ = [
    "IMAGE_SUFFIXES",
    "MESH_SUFFIXES",
    "check_vertices",
    "check_faces",
    "mesh_from_arrays",
    "triangulate_polygons",
    "load_part_mesh",
    "natural_key",
    "image_files",
    "load_pickled_npy",
    "points_surface",
]

MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".webp", ".bmp")


def check_vertices(values: Any, where: str | Path, field: str) -> np.ndarray:
    """``values`` as finite float64 vertices ``(n, 3)`` with ``n >= 3``.

    A flat sequence of ``3 n`` numbers is accepted as well (row-major xyz triples).
    """
    try:
        v = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise FormatError(where, f"{field}: not a numeric array of xyz coordinates") from None
    if v.ndim == 1 and len(v) % 3 == 0:
        v = v.reshape(-1, 3)
    if v.ndim != 2 or v.shape[1] != 3:
        raise FormatError(where, f"{field}: expected shape (n, 3), got {tuple(v.shape)}")
    if len(v) < 3:
        raise FormatError(where, f"{field}: {len(v)} vertices; a part needs at least 3")
    bad = ~np.isfinite(v).all(axis=1)
    if bad.any():
        raise FormatError(where, f"{field}: {int(bad.sum())} non-finite vertices (first at row {int(np.argmax(bad))})")
    return v


def _is_ragged(faces: Any) -> bool:
    if isinstance(faces, np.ndarray) and faces.dtype != object:
        return False
    lens = {len(f) for f in faces} if len(faces) else {3}
    return len(lens) > 1 or lens != {3}


def _plane_coords(pts: np.ndarray) -> np.ndarray:
    """Coordinates ``(k, 2)`` of a polygon's vertices ``(k, 3)`` in its best-fit plane (Newell normal)."""
    nxt = np.roll(pts, -1, axis=0)
    normal = np.array(
        [
            np.sum((pts[:, 1] - nxt[:, 1]) * (pts[:, 2] + nxt[:, 2])),
            np.sum((pts[:, 2] - nxt[:, 2]) * (pts[:, 0] + nxt[:, 0])),
            np.sum((pts[:, 0] - nxt[:, 0]) * (pts[:, 1] + nxt[:, 1])),
        ]
    )
    norm = np.linalg.norm(normal)
    if norm == 0:
        return np.zeros((len(pts), 2))
    normal /= norm
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    w = np.cross(normal, u)  # (u, w, normal) right-handed: the polygon is counter-clockwise in (u, w)
    return np.stack([pts @ u, pts @ w], axis=1)


def _ear_clip(xy: np.ndarray) -> list[tuple[int, int, int]] | None:
    """Ear clipping of a simple counter-clockwise polygon ``(k, 2)``; None when it gets stuck."""
    idx = list(range(len(xy)))
    tris: list[tuple[int, int, int]] = []

    def cross(a, b, c):
        return (xy[b, 0] - xy[a, 0]) * (xy[c, 1] - xy[a, 1]) - (xy[b, 1] - xy[a, 1]) * (xy[c, 0] - xy[a, 0])

    guard = 0
    while len(idx) > 3 and guard < 10 * len(xy) ** 2:
        guard += 1
        for k in range(len(idx)):
            a, b, c = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
            if cross(a, b, c) <= 0:
                continue  # reflex or degenerate corner
            inside = False
            for p in idx:
                if p in (a, b, c):
                    continue
                if cross(a, b, p) >= 0 and cross(b, c, p) >= 0 and cross(c, a, p) >= 0:
                    inside = True
                    break
            if not inside:
                tris.append((a, b, c))
                idx.pop(k)
                break
        else:
            return None
    if len(idx) == 3:
        tris.append((idx[0], idx[1], idx[2]))
    return tris


def triangulate_polygons(vertices: np.ndarray, faces: Sequence[Sequence[int]]) -> np.ndarray:
    """Triangles ``(m, 3)`` for polygon ``faces`` (index lists of 3 or more vertices).

    Convex polygons are fanned from their first vertex; non-convex planar ones are ear-clipped in
    their best-fit plane, keeping the polygon's orientation (so face normals stay outward).
    """
    out: list[tuple[int, int, int]] = []
    for face in faces:
        f = [int(i) for i in face]
        if len(f) == 3:
            out.append((f[0], f[1], f[2]))
            continue
        xy = _plane_coords(vertices[f])
        tris = None
        if len(f) > 3:
            a = np.roll(xy, -1, axis=0) - xy
            b = np.roll(xy, -2, axis=0) - np.roll(xy, -1, axis=0)
            turns = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
            if not (np.all(turns >= 0) or np.all(turns <= 0)):
                tris = _ear_clip(xy)
        if tris is None:
            tris = [(0, k, k + 1) for k in range(1, len(f) - 1)]
        out.extend((f[i], f[j], f[k]) for i, j, k in tris)
    return np.asarray(out, dtype=np.int64).reshape(-1, 3)


def check_faces(
    values: Any, n_vertices: int, where: str | Path, field: str, polygons: bool = True
) -> list[list[int]] | np.ndarray:
    """Face index lists, checked: integers in ``[0, n_vertices)`` with at least 3 per face.

    Returns an ``(m, 3)`` int array for triangles, else the polygon lists (``polygons=True``).
    With ``polygons=False`` anything but triangles is an error.
    """
    if values is None:
        raise FormatError(where, f"{field}: missing")
    try:
        arr = np.asarray(values)
        regular = arr.dtype != object and arr.ndim == 2
    except ValueError:  # ragged lists
        regular = False
    if regular:
        if not np.issubdtype(arr.dtype, np.integer):
            if (
                not np.issubdtype(arr.dtype, np.floating)
                or not np.all(np.isfinite(arr))
                or np.any(arr != np.round(arr))
            ):
                raise FormatError(where, f"{field}: face indices must be integers")
            arr = arr.astype(np.int64)
        if arr.shape[1] < 3:
            raise FormatError(where, f"{field}: expected faces of at least 3 vertices, got shape {tuple(arr.shape)}")
        if arr.shape[1] != 3 and not polygons:
            raise FormatError(
                where, f"{field}: expected triangles of shape (m, 3), got {tuple(arr.shape)} (polygon faces)"
            )
        polys: Any = arr.astype(np.int64)
    else:
        if not polygons:
            raise FormatError(where, f"{field}: expected triangles of shape (m, 3), got polygons of varying size")
        polys = []
        for k, f in enumerate(values):
            try:
                fi = np.asarray(f)
            except ValueError:
                raise FormatError(where, f"{field}[{k}]: not a list of vertex indices") from None
            if fi.ndim != 1 or not (
                np.issubdtype(fi.dtype, np.integer)
                or (np.issubdtype(fi.dtype, np.floating) and np.all(fi == np.round(fi)))
            ):
                raise FormatError(where, f"{field}[{k}]: face indices must be integers")
            if len(fi) < 3:
                raise FormatError(where, f"{field}[{k}]: a face needs at least 3 vertices, got {len(fi)}")
            polys.append([int(i) for i in fi])
    if len(polys) == 0:
        raise FormatError(where, f"{field}: no faces")
    flat = np.concatenate([np.asarray(p).ravel() for p in polys]) if isinstance(polys, list) else polys.ravel()
    if flat.min() < 0 or flat.max() >= n_vertices:
        raise FormatError(
            where,
            f"{field}: vertex index out of range [0, {n_vertices}) (min {int(flat.min())}, max {int(flat.max())})",
        )
    return polys


def mesh_from_arrays(
    vertices: Any, faces: Any, where: str | Path, field: str, polygons: bool = True
) -> trimesh.Trimesh:
    """A checked triangle mesh from raw arrays; polygon faces are triangulated when allowed.

    ``field`` names the mesh in errors (``<field>.vertices`` / ``<field>.faces``).
    """
    v = check_vertices(vertices, where, f"{field}.vertices")
    f = check_faces(faces, len(v), where, f"{field}.faces", polygons=polygons)
    if isinstance(f, np.ndarray) and f.shape[1] == 3:
        tris = f
    else:
        tris = triangulate_polygons(v, f if isinstance(f, list) else f.tolist())
    return trimesh.Trimesh(v, tris, process=False)


def load_part_mesh(path: str | Path, field: str = "mesh") -> trimesh.Trimesh:
    """A part mesh file (polygons triangulated by trimesh), with a non-degenerate extent."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(path, f"{field}: file not found")
    mesh = load_mesh(path)
    if not np.any(np.ptp(np.asarray(mesh.vertices), axis=0) > 0):
        raise FormatError(path, f"{field}: all vertices coincide; a part needs extent")
    return mesh


_DIGITS = re.compile(r"(\d+)")


def natural_key(name: str) -> tuple:
    """Sort key putting ``page_2`` before ``page_10``."""
    return tuple(int(t) if t.isdigit() else t.lower() for t in _DIGITS.split(name))


def image_files(folder: str | Path) -> list[Path]:
    """Image files directly in ``folder`` in natural order (empty if the folder is missing)."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    files = [p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES]
    return sorted(files, key=lambda p: natural_key(p.name))


class _ArrayUnpickler(pickle.Unpickler):
    """Unpickles plain containers and NumPy arrays only: a dataset file must not run code."""

    _ALLOWED = {
        ("numpy", "ndarray"),
        ("numpy", "dtype"),
        ("numpy.core.multiarray", "_reconstruct"),
        ("numpy._core.multiarray", "_reconstruct"),
        ("numpy.core.multiarray", "scalar"),
        ("numpy._core.multiarray", "scalar"),
        ("numpy._core.numeric", "_frombuffer"),
        ("numpy.core.numeric", "_frombuffer"),
        ("builtins", "bytearray"),
        ("collections", "OrderedDict"),
        ("_codecs", "encode"),
    }

    def find_class(self, module: str, name: str):
        if (module, name) in self._ALLOWED:
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"refusing to load {module}.{name}")


def load_pickled_npy(path: str | Path) -> Any:
    """The object stored in a ``.npy`` file written by ``np.save`` of a dict (or any array).

    Object arrays are unpickled with an allow-list of NumPy types, so a crafted file cannot run
    code; Python 2 pickles (``latin1`` strings) are accepted, as many published files are old.
    A 0-d object array (``np.save(path, dict)``) returns the dict itself.
    """
    path = Path(path)
    if not path.is_file():
        raise FormatError(path, "file not found")
    try:
        with open(path, "rb") as fh:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                _shape, _fortran, dtype = np.lib.format.read_array_header_1_0(fh)
            else:
                _shape, _fortran, dtype = np.lib.format.read_array_header_2_0(fh)
            if dtype.hasobject:
                arr = _ArrayUnpickler(fh, encoding="latin1").load()
            else:
                fh.seek(0)
                arr = np.load(fh, allow_pickle=False)
    except FormatError:
        raise
    except Exception as exc:  # numpy/pickle raise many types for broken files
        raise FormatError(path, f"cannot be read as a .npy file ({type(exc).__name__}: {exc})") from None
    if isinstance(arr, np.ndarray) and arr.dtype == object and arr.shape == ():
        return arr.item()
    return arr


def points_surface(points: np.ndarray, where: str | Path, field: str) -> trimesh.Trimesh:
    """The convex hull of a part's point cloud ``(n, 3)``: a closed surface standing in for a
    mesh the dataset does not publish. Concavities of the part are lost (see docs/datasets.md)."""
    pts = check_vertices(points, where, field)
    if len(pts) < 4:
        raise FormatError(where, f"{field}: {len(pts)} points cannot span a surface")
    last: Exception | None = None
    for options in ("QbB Pp Qt", "QJ Pp"):  # joggle for flat (coplanar) point sets
        try:
            hull = trimesh.convex.convex_hull(pts, qhull_options=options, repair=True)
            if len(hull.faces):
                return trimesh.Trimesh(np.asarray(hull.vertices), np.asarray(hull.faces), process=False)
        except Exception as exc:  # qhull errors for degenerate inputs
            last = exc
    raise FormatError(where, f"{field}: no surface can be built from these points ({last})")
