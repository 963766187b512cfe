"""IKEA-Manual: furniture with per-part meshes and the real IKEA assembly manuals.

Layout under ``root`` (the dataset folder)::

    main_data.json                       a list of objects (or {"data": [...]}) with
        category, name, parts_ct, steps, connection_relation,
        geometric_equivalence_relation, assembly_tree
    parts/<category>/<name>/<i>.obj      one mesh per part i = 0..parts_ct-1, assembled frame, Y up
                                         (parts/<name>/<i>.obj is accepted too)
    manual_img/<category>/<name>/*.png   the manual's pages in order (also looked for under
                                         pages/, manual/, manual_imgs/, images/; or pass pages_dir)

Part names are the part indices as strings (``"0"``, ``"1"``, ...), as in ``steps`` and
``geometric_equivalence_relation``. Step entries may name sub-assemblies as comma-joined ids
(``"0,1"``); the parts each step adds are kept as ``meta["steps"]``.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from aw.assembly import AssembledObject, SourcePart, y_up_to_z_up
from aw.formats import FormatError
from aw.formats.strict_json import read_json
from aw.sources.meshdata import MESH_SUFFIXES, image_files, load_part_mesh

__all__ = ["SOURCE", "read_main_data", "find_entry", "object_key", "load_object", "catalog", "step_parts"]

SOURCE = "ikea_manual"
_PAGE_DIRS = ("manual_img", "manual_imgs", "pages", "manual", "images")


def read_main_data(root: str | Path) -> list[dict[str, Any]]:
    """The object records of ``main_data.json`` (checked to be objects with a name and category)."""
    path = Path(root) / "main_data.json"
    if not path.is_file():
        raise FormatError(path, "main_data.json not found")
    data = read_json(path)
    if isinstance(data, dict):
        data = data.get("data", data.get("objects"))
    if not isinstance(data, list):
        raise FormatError(path, 'expected a list of objects (or {"data": [...]})')
    for k, rec in enumerate(data):
        if not isinstance(rec, dict):
            raise FormatError(path, f"[{k}]: expected an object, got {type(rec).__name__}")
        for key in ("name", "category"):
            if not isinstance(rec.get(key), str) or not rec.get(key):
                raise FormatError(path, f"[{k}].{key}: missing or not a string")
    return data


def object_key(rec: dict[str, Any]) -> str:
    return f"{rec['category']}/{rec['name']}"


def find_entry(data: list[dict[str, Any]], key: str, path: Path) -> tuple[int, dict[str, Any]]:
    """The record named ``key`` (``"<category>/<name>"``, or a bare name when unique)."""
    hits = [(k, r) for k, r in enumerate(data) if object_key(r) == key]
    if not hits and "/" not in key:
        hits = [(k, r) for k, r in enumerate(data) if r["name"] == key]
    if len(hits) != 1:
        raise FormatError(path, f"{'no' if not hits else 'several'} object(s) named {key!r}")
    return hits[0]


def _names(value: Any) -> list[str]:
    """Part names in a step or relation entry: ints, strings, comma-joined sub-assemblies."""
    if isinstance(value, (list, tuple)):
        return [n for v in value for n in _names(v)]
    if isinstance(value, bool):
        return []
    if isinstance(value, int):
        return [str(value)]
    if isinstance(value, float) and value.is_integer():
        return [str(int(value))]
    if isinstance(value, str):
        return re.findall(r"\d+", value)
    return []


def step_parts(rec: dict[str, Any], n_parts: int, where: Path, k: int) -> list[list[str]]:
    """The parts each step adds (first appearance), from ``steps[*].parts`` (or the step itself
    when a step is a plain list)."""
    steps = rec.get("steps") or []
    if not isinstance(steps, list):
        raise FormatError(where, f"[{k}].steps: expected a list")
    out, seen = [], set()
    for s, step in enumerate(steps):
        raw = step.get("parts", []) if isinstance(step, dict) else step
        names = _names(raw)
        bad = [n for n in names if not 0 <= int(n) < n_parts]
        if bad:
            raise FormatError(where, f"[{k}].steps[{s}].parts: unknown part ids {bad} (parts_ct is {n_parts})")
        new = [n for n in dict.fromkeys(names) if n not in seen]
        seen.update(new)
        if new:
            out.append(new)
    return out


def _part_dir(root: Path, rec: dict[str, Any]) -> Path:
    for d in (root / "parts" / rec["category"] / rec["name"], root / "parts" / rec["name"]):
        if d.is_dir():
            return d
    raise FormatError(root / "parts" / rec["category"] / rec["name"], "part mesh folder not found")


def _pages(root: Path, rec: dict[str, Any], pages_dir: str | Path | None) -> list[Path]:
    if pages_dir is not None:
        bases = [Path(pages_dir)]
    else:
        bases = [root / d for d in _PAGE_DIRS]
    for base in bases:
        for d in (base / rec["category"] / rec["name"], base / rec["name"]):
            found = image_files(d)
            if found:
                return found
    return []


def load_object(root: str | Path, key: str, pages_dir: str | Path | None = None) -> AssembledObject:
    """One IKEA-Manual object (``key`` = ``"<category>/<name>"``) as an assembled object (Z up)
    with its manual pages as ``references["manual"]``."""
    root = Path(root)
    path = root / "main_data.json"
    k, rec = find_entry(read_main_data(root), key, path)
    n = rec.get("parts_ct")
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise FormatError(path, f"[{k}].parts_ct: expected a positive integer, got {n!r}")
    part_dir = _part_dir(root, rec)
    files = {p.stem: p for p in part_dir.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES}
    missing = [str(i) for i in range(n) if str(i) not in files]
    if missing:
        raise FormatError(part_dir, f"part meshes {missing} missing (parts_ct of {object_key(rec)} is {n})")
    extra = sorted(set(files) - {str(i) for i in range(n)})
    if extra:
        raise FormatError(part_dir, f"mesh files {extra} are not parts 0..{n - 1} (parts_ct is {n})")
    parts = [SourcePart(str(i), y_up_to_z_up(load_part_mesh(files[str(i)], f"part {i}"))) for i in range(n)]

    equivalence = None
    rel = rec.get("geometric_equivalence_relation")
    if rel:
        if not isinstance(rel, list):
            raise FormatError(path, f"[{k}].geometric_equivalence_relation: expected a list of groups")
        groups = []
        for g, group in enumerate(rel):
            names = list(dict.fromkeys(_names(group)))
            bad = [x for x in names if not 0 <= int(x) < n]
            if bad:
                raise FormatError(path, f"[{k}].geometric_equivalence_relation[{g}]: unknown part ids {bad}")
            if len(names) > 1:
                groups.append(names)
        equivalence = _merge_groups(groups) or None

    steps = step_parts(rec, n, path, k)
    meta: dict[str, Any] = {"name": rec["name"], "key": object_key(rec), "parts_ct": n}
    if steps:
        meta["steps"] = steps
    for field_name in ("connection_relation", "assembly_tree"):
        if field_name in rec:
            meta[field_name] = rec[field_name]
    references = {}
    pages = _pages(root, rec, pages_dir)
    if pages:
        references["manual"] = pages
    else:
        meta["references"] = "missing: pages will be rendered from steps"
    return AssembledObject(
        object_id=f"{rec['category']}_{rec['name']}".lower(),
        source=SOURCE,
        dataset="ikea_manual",
        category=rec["category"].lower(),
        parts=parts,
        references=references,
        equivalence=equivalence,
        meta=meta,
    )


def _merge_groups(groups: list[list[str]]) -> list[list[str]]:
    """Union of overlapping groups (the relation may list pairs)."""
    merged: list[set[str]] = []
    for g in groups:
        s = set(g)
        overlapping = [m for m in merged if m & s]
        for m in overlapping:
            s |= m
            merged.remove(m)
        merged.append(s)
    return sorted((sorted(m, key=int) for m in merged), key=lambda g: int(g[0]))


def catalog(root: str | Path, pages_dir: str | Path | None = None):
    """Every object of ``main_data.json`` as :class:`aw.sources.compose.CatalogEntry` records."""
    from aw.sources.compose import CatalogEntry

    root = Path(root)
    out = []
    path = root / "main_data.json"
    for k, rec in enumerate(read_main_data(root)):
        n = rec.get("parts_ct")
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise FormatError(path, f"[{k}].parts_ct: expected a positive integer, got {n!r}")
        args = (str(root), object_key(rec)) + ((str(pages_dir),) if pages_dir is not None else ())
        out.append(
            CatalogEntry(
                SOURCE,
                f"{rec['category']}_{rec['name']}".lower(),
                rec["category"].lower(),
                n,
                "aw.sources.ikea_manual:load_object",
                args,
            )
        )
    return out
