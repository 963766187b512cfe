"""Import a folder of assembled objects: the universal way to bring one's own objects.

Layout::

    SRC/
      <object>/                   one folder per object (sorted by name)
        <part>.obj|.ply|.stl|.glb|.gltf|.off   one mesh per part, in the assembled frame
        meta.json                 optional, see :class:`ObjectMeta`
        ...                       reference images named in meta.json

Part names are the file stems. Parts may also live in a ``parts/`` subfolder (then only that
folder is read). Every error names the offending file. Keys of ``meta.json`` that
:class:`ObjectMeta` does not know are ignored; :func:`scan_folder` warns once per file, naming
them (:class:`UnknownMetaKeys`), and names every mesh path it does not read (:class:`SkippedPath`:
a directory, a link to a device, meshes beside a ``parts/`` folder). An object folder whose name
is not valid UTF-8 is an error before anything is built.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from aw.assembly import AssembledObject, SourcePart, y_up_to_z_up
from aw.formats import FormatError
from aw.formats.common import MAX_CATEGORY_CHARS
from aw.formats.io import read_model
from aw.formats.strict_json import read_json
from aw.meshes import load_mesh
from aw.sources.up_axis import guess_up_axis

__all__ = [
    "MESH_SUFFIXES",
    "UP_AXES",
    "ObjectMeta",
    "FolderObject",
    "SkippedPath",
    "UnknownMetaKeys",
    "load_object",
    "scan_folder",
    "skipped_paths",
    "unknown_keys",
]

MESH_SUFFIXES = (".obj", ".ply", ".stl", ".glb", ".gltf", ".off")
Condition = Literal["none", "image", "manual"]
UpAxis = Literal["z", "y", "auto"]
UP_AXES = ("auto", "z", "y")


class ObjectMeta(BaseModel):
    """``meta.json`` of one object folder (every field optional).

    ``conditions`` (or a single ``condition``) defaults to the conditions that have
    ``references``, else ``["none"]``; ``["none", "image"]`` builds paired tasks as for PartNet. A
    condition ``image`` or ``manual`` without references gets rendered ones (manual pages follow
    ``steps``, lists of part names, else one part per page). ``references`` paths are relative
    to the object folder. ``up_axis``: ``"y"`` turns Y-up meshes Z-up with (x, y, z) -> (x, -z, y),
    ``"z"`` keeps them, ``"auto"`` decides from the geometry (:mod:`aw.sources.up_axis`); unset,
    the importer's choice (``aw-prepare folder --up-axis``, default ``auto``) applies.
    """

    model_config = ConfigDict(extra="ignore")  # real folders carry metadata of their own

    object_id: str | None = Field(default=None, min_length=1, max_length=100)
    source: str | None = Field(default=None, min_length=1, max_length=64)
    dataset: str = Field(default="folder", min_length=1, max_length=64)
    category: str = Field(default="", max_length=MAX_CATEGORY_CHARS)
    condition: Condition | None = None
    conditions: list[Condition] | None = Field(default=None, min_length=1)
    references: dict[Literal["image", "manual"], list[str]] = Field(default_factory=dict)
    equivalence: list[list[str]] | None = None
    steps: list[list[str]] | None = None
    up_axis: UpAxis | None = None

    @model_validator(mode="after")
    def _one_condition_field(self) -> ObjectMeta:
        if self.condition is not None and self.conditions is not None:
            raise ValueError("give either condition or conditions, not both")
        return self


class FolderObject(BaseModel):
    """An object folder found by :func:`scan_folder`: where it is and what to build from it."""

    path: str
    object_id: str
    conditions: list[str]


class UnknownMetaKeys(UserWarning):
    """A ``meta.json`` has keys :class:`ObjectMeta` does not know (they are ignored)."""


class SkippedPath(UserWarning):
    """A path named like a part mesh that is not read (see :func:`skipped_paths`)."""


def unknown_keys(obj_dir: str | Path) -> list[str]:
    """The keys of ``obj_dir/meta.json`` that :class:`ObjectMeta` ignores, sorted."""
    path = Path(obj_dir) / "meta.json"
    if not path.exists():
        return []
    raw = read_json(path)
    return sorted(set(raw) - set(ObjectMeta.model_fields)) if isinstance(raw, dict) else []


def _part_files(obj_dir: Path) -> list[Path]:
    base = obj_dir / "parts" if (obj_dir / "parts").is_dir() else obj_dir
    files = sorted(p for p in base.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)
    if not files:
        raise FormatError(base, f"no part meshes ({', '.join(MESH_SUFFIXES)}) in this object folder")
    stems = [p.stem for p in files]
    dup = sorted({s for s in stems if stems.count(s) > 1})
    if dup:
        raise FormatError(
            base, f"several mesh files share the part name(s) {dup}; part names are file stems and must be unique"
        )
    return files


def skipped_paths(obj_dir: Path) -> list[tuple[Path, str]]:
    """Paths of ``obj_dir`` with a mesh suffix that :func:`load_object` does not read, with why."""
    base = obj_dir / "parts" if (obj_dir / "parts").is_dir() else obj_dir
    out = []
    for p in sorted(base.iterdir()):
        if p.suffix.lower() not in MESH_SUFFIXES:
            continue
        if p.is_dir():
            out.append((p, "a directory, not a mesh file"))
        elif not p.is_file():
            out.append((p, "not a regular file (a device, a socket or a broken link)"))
    if base != obj_dir:
        out += [
            (p, "the object's parts are read from its parts/ folder")
            for p in sorted(obj_dir.iterdir())
            if p.suffix.lower() in MESH_SUFFIXES
        ]
    return out


def shown(path: Path | str) -> str:
    """``path`` for a message: bytes that are not UTF-8 written as ``\\xff`` escapes."""
    return os.fsencode(path).decode("utf-8", "backslashreplace")


def read_meta(obj_dir: Path) -> ObjectMeta:
    path = obj_dir / "meta.json"
    return read_model(ObjectMeta, path) if path.exists() else ObjectMeta()


def _conditions(meta: ObjectMeta) -> list[str]:
    if meta.condition:
        return [meta.condition]
    if meta.conditions:
        return list(dict.fromkeys(meta.conditions))
    return [c for c in ("image", "manual") if meta.references.get(c)] or ["none"]


def _up_axis(meta: ObjectMeta, up_axis: str, meshes: list) -> tuple[str, str]:
    """``(axis, how it was decided)``: ``meta.json`` first, then the importer's ``up_axis``, then
    the geometry."""
    if meta.up_axis in ("y", "z"):
        return meta.up_axis, "meta.json up_axis"
    if meta.up_axis is None and up_axis in ("y", "z"):
        return up_axis, "--up-axis"
    guess = guess_up_axis(meshes)
    return guess.axis, f"auto: {guess.reason}"


def load_object(obj_dir: str | Path, default_source: str = "custom", up_axis: str = "auto") -> AssembledObject:
    """Read one object folder into an :class:`AssembledObject` (``meta`` carries ``conditions``
    and ``up_axis``: ``{"axis": "y"|"z", "how": ...}``, how the up axis was decided).

    ``up_axis`` (``auto``, ``z`` or ``y``) applies where ``meta.json`` names none."""
    obj_dir = Path(obj_dir)
    if up_axis not in UP_AXES:
        raise ValueError(f"up_axis must be one of {UP_AXES}, got {up_axis!r}")
    if not obj_dir.is_dir():
        raise FormatError(obj_dir, "object folder not found")
    meta = read_meta(obj_dir)
    meta_path = obj_dir / "meta.json"
    files = _part_files(obj_dir)
    meshes = [load_mesh(f) for f in files]
    for f, mesh in zip(files, meshes, strict=True):
        extent = np.ptp(np.asarray(mesh.vertices), axis=0)
        if not np.any(extent > 0):
            raise FormatError(f, "all vertices coincide; a part needs extent")
    axis, how = _up_axis(meta, up_axis, meshes)
    parts = [SourcePart(f.stem, y_up_to_z_up(m) if axis == "y" else m) for f, m in zip(files, meshes, strict=True)]
    names = {p.name for p in parts}
    for field_name, groups in (("equivalence", meta.equivalence), ("steps", meta.steps)):
        for group in groups or []:
            unknown = [n for n in group if n not in names]
            if unknown:
                raise FormatError(meta_path, f"{field_name} names unknown parts {unknown}; parts are {sorted(names)}")
    references: dict[str, list[Path]] = {}
    for cond, rels in meta.references.items():
        paths = []
        for rel in rels:
            p = obj_dir / rel
            if Path(rel).is_absolute() or ".." in Path(rel).parts:
                raise FormatError(meta_path, f"reference {rel!r} must be a path inside the object folder")
            if not p.is_file():
                raise FormatError(p, f"reference image listed in {meta_path.name} not found")
            paths.append(p)
        if paths:
            references[cond] = paths
    extra: dict[str, Any] = {
        "conditions": _conditions(meta),
        "folder": str(obj_dir),
        "up_axis": {"axis": axis, "how": how},
    }
    if meta.steps:
        extra["steps"] = meta.steps
    return AssembledObject(
        object_id=meta.object_id or obj_dir.name,
        source=meta.source or default_source,
        dataset=meta.dataset,
        category=meta.category,
        parts=parts,
        references=references,
        equivalence=meta.equivalence,
        meta=extra,
    )


def scan_folder(src: str | Path) -> list[FolderObject]:
    """The object folders of ``src`` (sorted), with ids and conditions read from ``meta.json``.

    Raises :class:`FormatError` for a missing source, an empty one, a bad ``meta.json`` or two
    objects with the same id.
    """
    src = Path(src)
    if not src.is_dir():
        raise FormatError(src, "source folder not found")
    dirs = sorted(p for p in src.iterdir() if p.is_dir() and not p.name.startswith("."))
    if not dirs:
        raise FormatError(src, "contains no object folders (one subfolder per object is expected)")
    found = []
    for d in dirs:
        if shown(d.name) != d.name:  # task ids, manifests and JSON need text
            raise FormatError(shown(d), "object folder name is not valid UTF-8; rename the folder")
    for d in dirs:
        meta = read_meta(d)
        ignored = unknown_keys(d)
        if ignored:
            warnings.warn(f"{d / 'meta.json'}: unknown keys {ignored} are ignored", UnknownMetaKeys, stacklevel=2)
        for path, why in skipped_paths(d):
            warnings.warn(f"{shown(path)}: skipped: {why}", SkippedPath, stacklevel=2)
        found.append(FolderObject(path=str(d), object_id=meta.object_id or d.name, conditions=_conditions(meta)))
    ids = [f.object_id for f in found]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise FormatError(src, f"several object folders have the object id(s) {dup}")
    return found
