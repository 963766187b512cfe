"""Breaking Bad: fractured objects, as mesh folders or as the HDF5 variant.

Folder layout under ``root``::

    <subset>/<Category>/<shape_id>/fractured_<k>/piece_<i>.obj     (also mode_<k>/ folders)

HDF5 variant: any group holding a ``pieces`` group is one fractured object, and each
``pieces/<piece>`` group holds ``vertices (n, 3)`` and ``faces (m, 3)`` datasets, e.g.
``everyday/BeerBottle/<shape_id>/fractured_0/pieces/0/vertices``.

Pieces are in the assembled frame; the meshes are used as published (no up-axis change unless
``up_axis="y"``). Objects are named ``<Category>/<shape_id>/<fracture>`` and keyed by their
relative path.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from aw.assembly import AssembledObject, SourcePart, y_up_to_z_up
from aw.formats import FormatError
from aw.sources.meshdata import MESH_SUFFIXES, load_part_mesh, mesh_from_arrays, natural_key

__all__ = ["SOURCE", "load_object", "load_hdf5_object", "catalog", "hdf5_catalog"]

SOURCE = "breaking_bad"
_FRACTURE = re.compile(r"^(fractured|mode)_\d+$")


def _object_id(rel_parts: tuple[str, ...]) -> str:
    # <subset>/<Category>/<shape>/<fracture> -> <Category>_<shape>_<fracture>
    return "_".join(rel_parts[-3:])


def _category(rel_parts: tuple[str, ...]) -> str:
    return rel_parts[-3].lower() if len(rel_parts) >= 3 else ""


def load_object(root: str | Path, rel: str, up_axis: str = "z") -> AssembledObject:
    """The fractured object in ``root/rel`` (a ``fractured_<k>`` folder of ``piece_*`` meshes)."""
    root = Path(root)
    folder = root / rel
    if not folder.is_dir():
        raise FormatError(folder, "fracture folder not found")
    files = sorted(
        (p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES),
        key=lambda p: natural_key(p.name),
    )
    if len(files) < 2:
        raise FormatError(folder, f"pieces: {len(files)} piece mesh(es); a fractured object needs at least 2")
    parts = []
    for f in files:
        mesh = load_part_mesh(f, "piece")
        parts.append(SourcePart(f.stem, y_up_to_z_up(mesh) if up_axis == "y" else mesh))
    rel_parts = Path(rel).parts
    return AssembledObject(
        object_id=_object_id(rel_parts),
        source=SOURCE,
        dataset="breaking_bad",
        category=_category(rel_parts),
        parts=parts,
        meta={"path": str(Path(rel)), "subset": rel_parts[0] if len(rel_parts) >= 4 else ""},
    )


def catalog(root: str | Path, subsets: list[str] | None = None):
    """Every fracture folder under ``root`` as :class:`aw.sources.compose.CatalogEntry` records."""
    from aw.sources.compose import CatalogEntry

    root = Path(root)
    if not root.is_dir():
        raise FormatError(root, "Breaking Bad folder not found")
    out = []
    for d in sorted(root.glob("*/*/*/*"), key=lambda p: natural_key(str(p))):
        if not d.is_dir() or not _FRACTURE.match(d.name):
            continue
        rel = d.relative_to(root)
        if subsets is not None and rel.parts[0] not in subsets:
            continue
        n = sum(1 for p in d.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)
        out.append(
            CatalogEntry(
                SOURCE,
                _object_id(rel.parts),
                _category(rel.parts),
                n,
                "aw.sources.breaking_bad:load_object",
                (str(root), rel.as_posix()),
            )
        )
    return out


def _open_h5(path: Path):
    import h5py

    if not path.is_file():
        raise FormatError(path, "HDF5 file not found")
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        raise FormatError(path, f"cannot be read as HDF5 ({exc})") from None


def load_hdf5_object(path: str | Path, key: str, up_axis: str = "z") -> AssembledObject:
    """The fractured object stored under group ``key`` of an HDF5 file (``key/pieces/<piece>``)."""
    import h5py

    path = Path(path)
    with _open_h5(path) as h5:
        if key not in h5 or not isinstance(h5[key], h5py.Group):
            raise FormatError(path, f"{key}: group not found")
        if "pieces" not in h5[key] or not isinstance(h5[key]["pieces"], h5py.Group):
            raise FormatError(path, f"{key}/pieces: group not found")
        group = h5[key]["pieces"]
        names = sorted(group.keys(), key=natural_key)
        if len(names) < 2:
            raise FormatError(path, f"{key}/pieces: {len(names)} piece(s); a fractured object needs at least 2")
        parts = []
        for name in names:
            field = f"{key}/pieces/{name}"
            piece = group[name]
            if not isinstance(piece, h5py.Group):
                raise FormatError(path, f"{field}: expected a group with vertices and faces")
            for ds in ("vertices", "faces"):
                if ds not in piece or not isinstance(piece[ds], h5py.Dataset):
                    raise FormatError(path, f"{field}/{ds}: dataset missing")
            mesh = mesh_from_arrays(piece["vertices"][()], piece["faces"][()], path, field, polygons=False)
            parts.append(SourcePart(f"piece_{name}", y_up_to_z_up(mesh) if up_axis == "y" else mesh))
    rel_parts = tuple(p for p in key.split("/") if p)
    return AssembledObject(
        object_id=_object_id(rel_parts),
        source=SOURCE,
        dataset="breaking_bad",
        category=_category(rel_parts),
        parts=parts,
        meta={"hdf5": str(path), "key": key},
    )


def hdf5_catalog(path: str | Path):
    """Every group with a ``pieces`` subgroup as :class:`aw.sources.compose.CatalogEntry` records."""
    import h5py

    from aw.sources.compose import CatalogEntry

    path = Path(path)
    found: list[tuple[str, int]] = []

    def visit(name: str, obj: Any) -> None:
        if isinstance(obj, h5py.Group) and "pieces" in obj and isinstance(obj["pieces"], h5py.Group):
            found.append((name, len(obj["pieces"].keys())))

    with _open_h5(path) as h5:
        h5.visititems(visit)
    found.sort(key=lambda t: natural_key(t[0]))
    return [
        CatalogEntry(
            SOURCE,
            _object_id(tuple(k.split("/"))),
            _category(tuple(k.split("/"))),
            n,
            "aw.sources.breaking_bad:load_hdf5_object",
            (str(path), k),
        )
        for k, n in found
    ]
