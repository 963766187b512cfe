"""PartNet as prepared for part assembly (DGL / Manual-PA layout).

Layout under ``root`` (DGL's ``prepare_data`` folder)::

    <Category>.<split>.npy | .txt          shape ids of one category split (Chair.test.npy, ...)
    shape_data/<id>_level<k>.npy           a pickled dict per shape (np.save of a dict):
        part_pcs      (P, N, 3)  points of each part in its canonical part frame
        part_poses    (P, 7)     [tx, ty, tz, qw, qx, qy, qz]: assembled = R(q) p + t
        part_ids      (P,)       semantic part label
        geo_part_ids  (P,)       geometry class; equal ids = interchangeable parts
        sym           (P, ...)   symmetry flags (kept in meta)
    part_meshes/<id>_level<k>/<i>.obj      optional: a mesh per part (index i of part_pcs), in the
                                           canonical part frame or in the assembled frame
    diagrams/<id>/*.png                    optional: Manual-PA instruction pages, in order

PartNet is Y-up; parts are turned Z-up with (x, y, z) -> (x, -z, y). Without published meshes a
part's surface is the convex hull of its points (``meta["geometry"] == "convex_hull"``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from aw.assembly import AssembledObject, SourcePart, y_up_to_z_up
from aw.formats import FormatError
from aw.pose import quat_to_matrix
from aw.sources.meshdata import (
    MESH_SUFFIXES,
    image_files,
    load_part_mesh,
    load_pickled_npy,
    natural_key,
    points_surface,
)

__all__ = ["SOURCE", "CATEGORY_NAMES", "ShapeData", "shape_path", "read_shape", "read_split", "load_object", "catalog"]

SOURCE = "partnet"
CATEGORY_NAMES = {
    "chair": "chair",
    "table": "table",
    "storagefurniture": "storage",
    "storage": "storage",
    "lamp": "lamp",
}
"""Split-list category (lower case) -> benchmark category name."""


class ShapeData:
    """The checked contents of one ``shape_data/<id>_level<k>.npy`` file (assembled frame, Y up)."""

    def __init__(self, path: Path, raw: Any):
        self.path = path
        if not isinstance(raw, dict):
            raise FormatError(path, f"expected a pickled dict (np.save of a dict), got {type(raw).__name__}")
        for key in ("part_pcs", "part_poses"):
            if key not in raw:
                raise FormatError(path, f"{key}: missing (keys: {sorted(map(str, raw))})")
        pcs = np.asarray(raw["part_pcs"])
        if pcs.ndim != 3 or pcs.shape[2] != 3 or pcs.shape[0] < 1 or pcs.shape[1] < 4:
            raise FormatError(path, f"part_pcs: expected shape (P, N, 3) with N >= 4, got {tuple(pcs.shape)}")
        if not np.issubdtype(pcs.dtype, np.number):
            raise FormatError(path, f"part_pcs: not numeric ({pcs.dtype})")
        pcs = pcs.astype(np.float64)
        if not np.isfinite(pcs).all():
            bad = np.argwhere(~np.isfinite(pcs).all(axis=2))[0]
            raise FormatError(path, f"part_pcs: non-finite points (part {int(bad[0])}, point {int(bad[1])})")
        n = pcs.shape[0]
        poses = np.asarray(raw["part_poses"])
        if poses.shape != (n, 7) or not np.issubdtype(poses.dtype, np.number):
            raise FormatError(
                path, f"part_poses: expected shape ({n}, 7) [tx, ty, tz, qw, qx, qy, qz], got {tuple(poses.shape)}"
            )
        poses = poses.astype(np.float64)
        if not np.isfinite(poses).all():
            raise FormatError(path, "part_poses: non-finite values")
        qn = np.linalg.norm(poses[:, 3:], axis=1)
        if np.any(qn < 1e-6):
            raise FormatError(path, f"part_poses: zero quaternion for part {int(np.argmin(qn))}")
        poses[:, 3:] /= qn[:, None]
        self.part_pcs = pcs
        self.part_poses = poses
        self.part_ids = self._labels(raw, "part_ids", n)
        self.geo_part_ids = self._labels(raw, "geo_part_ids", n)
        sym = raw.get("sym")
        self.sym = None if sym is None else np.asarray(sym)
        if self.sym is not None and (self.sym.ndim == 0 or self.sym.shape[0] != n):
            raise FormatError(path, f"sym: expected one row per part ({n}), got shape {tuple(self.sym.shape)}")

    def _labels(self, raw: dict, key: str, n: int) -> np.ndarray | None:
        if key not in raw or raw[key] is None:
            return None
        a = np.asarray(raw[key]).reshape(-1)
        if a.shape != (n,):
            raise FormatError(
                self.path, f"{key}: expected {n} entries (one per part), got shape {tuple(np.asarray(raw[key]).shape)}"
            )
        return a

    @property
    def n_parts(self) -> int:
        return self.part_pcs.shape[0]

    def assembled_points(self) -> np.ndarray:
        """``(P, N, 3)`` points moved by their part poses (assembled frame, Y up)."""
        rot = quat_to_matrix(self.part_poses[:, 3:])  # (P, 3, 3)
        return np.einsum("pij,pnj->pni", rot, self.part_pcs) + self.part_poses[:, None, :3]

    def equivalence(self) -> list[list[str]] | None:
        """Groups of part names (``part_<i>``) sharing a ``geo_part_ids`` value."""
        if self.geo_part_ids is None:
            return None
        groups: dict[Any, list[str]] = {}
        for i, g in enumerate(self.geo_part_ids.tolist()):
            groups.setdefault(g, []).append(part_name(i, self.n_parts))
        out = [g for g in groups.values() if len(g) > 1]
        return out or None


def part_name(i: int, n: int) -> str:
    return f"part_{i:0{max(2, len(str(n - 1)))}d}"


def shape_path(root: str | Path, shape_id: str | int, level: int = 3) -> Path:
    return Path(root) / "shape_data" / f"{shape_id}_level{level}.npy"


def read_shape(root: str | Path, shape_id: str | int, level: int = 3) -> ShapeData:
    path = shape_path(root, shape_id, level)
    return ShapeData(path, load_pickled_npy(path))


def read_split(path: str | Path) -> list[str]:
    """Shape ids of a split list (``.npy`` array or ``.txt``, one id per line)."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(path, "split list not found")
    if path.suffix == ".npy":
        arr = load_pickled_npy(path)
        arr = np.asarray(arr).reshape(-1)
        return [
            str(int(x)) if isinstance(x, (np.integer, int)) or (isinstance(x, float) and x.is_integer()) else str(x)
            for x in arr.tolist()
        ]
    ids = [line.strip() for line in path.read_text().splitlines() if line.strip() and not line.startswith("#")]
    return ids


def _mesh_dir(root: Path, shape_id: str, level: int) -> Path | None:
    for d in (root / "part_meshes" / f"{shape_id}_level{level}", root / "part_meshes" / str(shape_id)):
        if d.is_dir():
            return d
    return None


def _part_meshes(mesh_dir: Path, shape: ShapeData) -> tuple[list[trimesh.Trimesh], list[str]]:
    """Meshes of the parts in the assembled frame (Y up), and the frame each was found in.

    A mesh's frame is the one in which its vertices lie closest to the part's points: the
    canonical part frame (then the part pose moves it) or the assembled frame.
    """
    files = {p.stem: p for p in mesh_dir.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES}
    assembled = shape.assembled_points()
    meshes, frames = [], []
    for i in range(shape.n_parts):
        f = files.get(str(i)) or files.get(part_name(i, shape.n_parts))
        if f is None:
            raise FormatError(
                mesh_dir, f"part mesh {i}: missing (expected {i}.obj or another of {MESH_SUFFIXES}) for part_pcs[{i}]"
            )
        mesh = load_part_mesh(f, f"part mesh {i}")
        tree = cKDTree(np.asarray(mesh.vertices))
        d_canon = np.mean(tree.query(shape.part_pcs[i])[0])
        d_asm = np.mean(tree.query(assembled[i])[0])
        if d_canon < d_asm:
            rot = quat_to_matrix(shape.part_poses[i, 3:])
            v = np.asarray(mesh.vertices) @ rot.T + shape.part_poses[i, :3]
            mesh = trimesh.Trimesh(v, np.asarray(mesh.faces), process=False)
            frames.append("canonical")
        else:
            frames.append("assembled")
        meshes.append(mesh)
    return meshes, frames


def _pages(root: Path, shape_id: str, pages_dir: str | Path | None) -> list[Path]:
    if pages_dir is not None:
        return image_files(Path(pages_dir) / str(shape_id))
    for name in ("diagrams", "manuals", "manual_images", "pages"):
        found = image_files(root / name / str(shape_id))
        if found:
            return found
    return []


def load_object(
    root: str | Path,
    shape_id: str | int,
    level: int = 3,
    category: str = "",
    pages_dir: str | Path | None = None,
) -> AssembledObject:
    """One PartNet shape as an assembled object (Z up), parts named ``part_00, part_01, ...``
    in ``part_pcs`` order. ``references["image"]`` is the final manual page when the shape
    has Manual-PA pages (otherwise the task builder renders the assembled object)."""
    root = Path(root)
    shape_id = str(shape_id)
    shape = read_shape(root, shape_id, level)
    mesh_dir = _mesh_dir(root, shape_id, level)
    meta: dict[str, Any] = {"shape_id": shape_id, "level": level, "file": str(shape.path)}
    if mesh_dir is not None:
        meshes, frames = _part_meshes(mesh_dir, shape)
        meta["geometry"] = "meshes"
        meta["mesh_frames"] = frames
    else:
        pts = shape.assembled_points()
        meshes = [points_surface(pts[i], shape.path, f"part_pcs[{i}]") for i in range(shape.n_parts)]
        meta["geometry"] = "convex_hull"
    parts = [SourcePart(part_name(i, shape.n_parts), y_up_to_z_up(m)) for i, m in enumerate(meshes)]
    if shape.part_ids is not None:
        meta["part_ids"] = shape.part_ids.tolist()
    if shape.geo_part_ids is not None:
        meta["geo_part_ids"] = shape.geo_part_ids.tolist()
    if shape.sym is not None:
        meta["sym"] = shape.sym.tolist()
    references: dict[str, list[Any]] = {}
    pages = _pages(root, shape_id, pages_dir)
    if pages:
        references["image"] = [pages[-1]]  # the final illustrated page shows the finished object
        meta["manual_pages"] = [str(p) for p in pages]
    return AssembledObject(
        object_id=shape_id,
        source=SOURCE,
        dataset="partnet",
        category=category,
        parts=parts,
        references=references,
        equivalence=shape.equivalence(),
        meta=meta,
    )


def split_lists(root: str | Path, split: str) -> dict[str, Path]:
    """``{category: split list path}`` for every ``<Category>.<split>.npy|txt`` in ``root``."""
    root = Path(root)
    out: dict[str, Path] = {}
    for p in sorted(root.iterdir(), key=lambda p: natural_key(p.name)):
        if not p.is_file() or p.suffix not in (".npy", ".txt"):
            continue
        stem_parts = p.stem.split(".")
        if len(stem_parts) == 2 and stem_parts[1] == split:
            cat = stem_parts[0].lower()
            out.setdefault(CATEGORY_NAMES.get(cat, cat), p)
    return out


def catalog(root: str | Path, level: int = 3, split: str = "test", categories: list[str] | None = None):
    """Every shape of ``split`` (all shapes of ``shape_data`` when the root has no split lists)
    as :class:`aw.sources.compose.CatalogEntry` records (part counts read from the files)."""
    from aw.sources.compose import CatalogEntry

    root = Path(root)
    if not root.is_dir():
        raise FormatError(root, "PartNet folder not found")
    lists = split_lists(root, split)
    if categories is not None:
        lists = {c: p for c, p in lists.items() if c in categories}
    if lists:
        ids = [(cat, sid) for cat, p in lists.items() for sid in read_split(p)]
    else:
        suffix = f"_level{level}.npy"
        files = sorted((root / "shape_data").glob(f"*{suffix}"), key=lambda p: natural_key(p.name))
        if not files:
            raise FormatError(root, f"no split lists (<Category>.{split}.npy) and no shape_data/*{suffix} files")
        ids = [("", p.name[: -len(suffix)]) for p in files]
    out = []
    seen = set()
    for cat, sid in ids:
        if sid in seen:
            continue
        seen.add(sid)
        shape = read_shape(root, sid, level)
        out.append(
            CatalogEntry(
                SOURCE, sid, cat, shape.n_parts, "aw.sources.partnet:load_object", (str(root), sid, level, cat)
            )
        )
    return out
