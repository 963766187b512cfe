"""AssemblyBench: industrial assemblies with rendered step diagrams and per-view, per-step poses.

Layout under ``root`` (see docs/datasets.md for the assumptions)::

    <category>/<object>/
      parts/<name>.obj|ply|stl|glb        one mesh per part, in the part's own frame
      diagrams/*.png                      one rendered diagram per step, in natural order
                                          (diagrams/view_<v>/*.png: the first view is used)
      poses/view_<v>/step_<s>.json        {"<name>": [tx, ty, tz, qw, qx, qy, qz], ...}: the
                                          parts present after step s, as seen in view v
      poses.json                          alternative: [[{name: pose}, ...steps], ...views]
                                          (or {"views": that list})
      meta.json                           optional: category, up_axis ("z" default or "y"),
                                          equivalence (lists of part names)

A pose maps the part mesh into the view: ``R(q) v + t``. The final step's first view places
every part, so it defines the assembled object; earlier steps give ``meta["steps"]`` (the parts
each step adds). The diagrams are the ``manual`` reference (one per step).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from aw.assembly import AssembledObject, SourcePart, y_up_to_z_up
from aw.formats import FormatError
from aw.formats.strict_json import read_json
from aw.pose import quat_to_matrix
from aw.sources.meshdata import MESH_SUFFIXES, image_files, load_part_mesh, natural_key

__all__ = ["SOURCE", "read_poses", "load_object", "catalog"]

SOURCE = "assemblybench"
_VIEW = re.compile(r"^view_?(\d+)$")
_STEP = re.compile(r"^step_?(\d+)$")


def _check_pose_map(raw: Any, path: Path, field: str) -> dict[str, np.ndarray]:
    if not isinstance(raw, dict) or not raw:
        raise FormatError(path, f"{field}: expected a non-empty object {{part name: [tx, ty, tz, qw, qx, qy, qz]}}")
    out = {}
    for name, pose in raw.items():
        try:
            p = np.asarray(pose, dtype=np.float64)
        except (TypeError, ValueError):
            raise FormatError(path, f"{field}.{name}: not a list of numbers") from None
        if p.shape != (7,):
            raise FormatError(
                path, f"{field}.{name}: expected [tx, ty, tz, qw, qx, qy, qz], got shape {tuple(p.shape)}"
            )
        if not np.isfinite(p).all():
            raise FormatError(path, f"{field}.{name}: non-finite values")
        qn = np.linalg.norm(p[3:])
        if qn < 1e-6:
            raise FormatError(path, f"{field}.{name}: zero quaternion")
        p[3:] /= qn
        out[str(name)] = p
    return out


def read_poses(obj_dir: str | Path) -> tuple[list[list[dict[str, np.ndarray]]], Path]:
    """Poses ``[view][step] -> {part name: (7,)}`` and the file (or folder) they came from."""
    obj_dir = Path(obj_dir)
    single = obj_dir / "poses.json"
    folder = obj_dir / "poses"
    if single.is_file():
        raw = read_json(single)
        if isinstance(raw, dict):
            raw = raw.get("views")
        if not isinstance(raw, list) or not raw or not all(isinstance(v, list) and v for v in raw):
            raise FormatError(single, "views: expected a non-empty list of views, each a non-empty list of steps")
        return [
            [_check_pose_map(s, single, f"views[{v}][{k}]") for k, s in enumerate(view)] for v, view in enumerate(raw)
        ], single
    if not folder.is_dir():
        raise FormatError(folder, "poses: neither poses/ nor poses.json found")
    views = sorted((int(m.group(1)), d) for d in folder.iterdir() if d.is_dir() and (m := _VIEW.match(d.name)))
    if not views:
        raise FormatError(folder, "poses: no view_<v> folders")
    out = []
    for _view, d in views:
        steps = sorted((int(m.group(1)), f) for f in d.iterdir() if f.suffix == ".json" and (m := _STEP.match(f.stem)))
        if not steps:
            raise FormatError(d, "poses: no step_<s>.json files")
        out.append([_check_pose_map(read_json(f), f, "poses") for _, f in steps])
    return out, folder


def _diagrams(obj_dir: Path) -> list[Path]:
    d = obj_dir / "diagrams"
    found = image_files(d)
    if found:
        return found
    if d.is_dir():
        views = sorted((p for p in d.iterdir() if p.is_dir()), key=lambda p: natural_key(p.name))
        if views:
            return image_files(views[0])
    return []


def load_object(root: str | Path, key: str, object_id: str | None = None) -> AssembledObject:
    """The assembly ``root/<category>/<object>`` (``key``) as an assembled object (its id is the
    folder name unless ``object_id`` is given)."""
    root = Path(root)
    obj_dir = root / key
    if not obj_dir.is_dir():
        raise FormatError(obj_dir, "object folder not found")
    meta_path = obj_dir / "meta.json"
    info = read_json(meta_path) if meta_path.is_file() else {}
    if not isinstance(info, dict):
        raise FormatError(meta_path, "expected an object")
    up = info.get("up_axis", "z")
    if up not in ("z", "y"):
        raise FormatError(meta_path, f"up_axis: expected 'z' or 'y', got {up!r}")
    part_dir = obj_dir / "parts"
    if not part_dir.is_dir():
        raise FormatError(part_dir, "parts: folder not found")
    files = {p.stem: p for p in sorted(part_dir.iterdir()) if p.is_file() and p.suffix.lower() in MESH_SUFFIXES}
    if not files:
        raise FormatError(part_dir, "parts: no part meshes")
    views, pose_src = read_poses(obj_dir)
    final = views[0][-1]
    missing = sorted(set(files) - set(final), key=natural_key)
    unknown = sorted(set(final) - set(files), key=natural_key)
    if missing or unknown:
        raise FormatError(
            pose_src, f"final step of view 0: poses missing for parts {missing}, poses for unknown parts {unknown}"
        )
    names = sorted(files, key=natural_key)
    parts = []
    for name in names:
        mesh = load_part_mesh(files[name], f"part {name}")
        p = final[name]
        v = np.asarray(mesh.vertices) @ quat_to_matrix(p[3:]).T + p[:3]
        mesh = trimesh.Trimesh(v, np.asarray(mesh.faces), process=False)
        parts.append(SourcePart(name, y_up_to_z_up(mesh) if up == "y" else mesh))

    steps, seen = [], set()
    for k, step in enumerate(views[0]):
        bad = sorted(set(step) - set(files))
        if bad:
            raise FormatError(pose_src, f"view 0, step {k}: poses for unknown parts {bad}")
        new = [n for n in names if n in step and n not in seen]
        seen.update(new)
        if new:
            steps.append(new)
    diagrams = _diagrams(obj_dir)
    meta: dict[str, Any] = {"key": key, "steps": steps, "n_views": len(views), "n_steps": len(views[0])}
    if diagrams and len(diagrams) != len(views[0]):
        meta["diagram_count_mismatch"] = {"diagrams": len(diagrams), "steps": len(views[0])}
    equivalence = info.get("equivalence")
    if equivalence is not None:
        if not isinstance(equivalence, list) or not all(isinstance(g, list) for g in equivalence):
            raise FormatError(meta_path, "equivalence: expected a list of lists of part names")
        bad = sorted({str(n) for g in equivalence for n in g} - set(files))
        if bad:
            raise FormatError(meta_path, f"equivalence: unknown parts {bad}")
        equivalence = [[str(n) for n in g] for g in equivalence if len(g) > 1] or None
    cat = info.get("category") or (Path(key).parts[0] if len(Path(key).parts) > 1 else "")
    return AssembledObject(
        object_id=object_id or Path(key).name,
        source=SOURCE,
        dataset="assemblybench",
        category=str(cat).lower(),
        parts=parts,
        references={"manual": diagrams} if diagrams else {},
        equivalence=equivalence,
        meta=meta,
    )


def catalog(root: str | Path):
    """Every ``<category>/<object>`` folder with a ``parts/`` folder; part counts are the mesh files."""
    from aw.sources.compose import CatalogEntry

    root = Path(root)
    if not root.is_dir():
        raise FormatError(root, "AssemblyBench folder not found")
    out = []
    for d in sorted(root.glob("*/*"), key=lambda p: natural_key(str(p))):
        if not (d / "parts").is_dir():
            continue
        n = sum(1 for p in (d / "parts").iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)
        key = d.relative_to(root).as_posix()
        out.append(
            CatalogEntry(
                SOURCE, d.name, d.parent.name.lower(), n, "aw.sources.assemblybench:load_object", (str(root), key)
            )
        )
    ids = [e.object_id for e in out]
    if len(set(ids)) != len(ids):  # the same object name in two categories: qualify by category
        out = [
            CatalogEntry(
                e.source,
                f"{e.category}_{e.object_id}",
                e.category,
                e.n_parts,
                e.loader,
                (*e.args, f"{e.category}_{e.object_id}"),
            )
            for e in out
        ]
    return out
