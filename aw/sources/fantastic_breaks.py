"""Fantastic Breaks: scanned broken objects, each a broken piece and its restoration fragment.

Layout under ``root``::

    <class>/<object>/model_b_0.ply    the broken object (part "broken")
                     model_r_0.ply    the restoration fragment (part "restoration")
                     model_c.ply      the complete object (not needed for assembly; noted in meta)
                     meta_0.npz       per-break metadata (its small arrays are kept in meta)

Both pieces are in the assembled frame. Objects are keyed ``<class>/<object>``; a different
break than ``_0`` is chosen with ``break_index``. No reference material (condition ``none``).
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from aw.assembly import AssembledObject, SourcePart
from aw.formats import FormatError
from aw.sources.meshdata import load_part_mesh, natural_key

__all__ = ["SOURCE", "load_object", "read_meta", "catalog"]

SOURCE = "fantastic_breaks"


def read_meta(path: str | Path) -> dict[str, Any]:
    """``meta_<k>.npz`` as a dict: arrays of at most 64 values as lists, larger ones as their shape."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(path, "meta file not found")
    try:
        with np.load(path, allow_pickle=False) as npz:
            out: dict[str, Any] = {}
            for key in npz.files:
                a = npz[key]
                if a.size <= 64 and a.dtype.kind in "biufUS":
                    out[key] = a.tolist()
                else:
                    out[key] = {"shape": list(a.shape), "dtype": str(a.dtype)}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise FormatError(path, f"cannot be read as .npz ({type(exc).__name__}: {exc})") from None
    return out


def load_object(root: str | Path, key: str, break_index: int = 0) -> AssembledObject:
    """The object ``root/<class>/<object>`` as a two-part assembled object."""
    root = Path(root)
    folder = root / key
    if not folder.is_dir():
        raise FormatError(folder, "object folder not found")
    broken = load_part_mesh(folder / f"model_b_{break_index}.ply", "broken piece (model_b)")
    restoration = load_part_mesh(folder / f"model_r_{break_index}.ply", "restoration fragment (model_r)")
    meta: dict[str, Any] = {"key": key, "break_index": break_index}
    meta_path = folder / f"meta_{break_index}.npz"
    if meta_path.exists():
        meta["npz"] = read_meta(meta_path)
    meta["complete_model"] = str(folder / "model_c.ply") if (folder / "model_c.ply").is_file() else None
    cls, _, obj = key.partition("/")
    return AssembledObject(
        object_id=f"{cls}_{obj}".lower().replace("/", "_"),
        source=SOURCE,
        dataset="fantastic_breaks",
        category=cls.lower(),
        parts=[SourcePart("broken", broken), SourcePart("restoration", restoration)],
        meta=meta,
    )


def catalog(root: str | Path):
    """Every ``<class>/<object>`` folder holding ``model_b_0.ply`` and ``model_r_0.ply``."""
    from aw.sources.compose import CatalogEntry

    root = Path(root)
    if not root.is_dir():
        raise FormatError(root, "Fantastic Breaks folder not found")
    out = []
    for d in sorted(root.glob("*/*"), key=lambda p: natural_key(str(p))):
        if d.is_dir() and (d / "model_b_0.ply").is_file() and (d / "model_r_0.ply").is_file():
            key = d.relative_to(root).as_posix()
            cls, _, obj = key.partition("/")
            out.append(
                CatalogEntry(
                    SOURCE,
                    f"{cls}_{obj}".lower(),
                    cls.lower(),
                    2,
                    "aw.sources.fantastic_breaks:load_object",
                    (str(root), key),
                )
            )
    return out
