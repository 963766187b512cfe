"""The official AssemblyWorldBench package: per-sample evaluation inputs.

Layout (see docs/datasets.md for the assumptions)::

    PKG/manifest.json        {"samples": [{"sample_id", "source", "condition", "object_id",
                              "category", "n_parts", "weight", "eval"}...]} (or a bare list);
                              "eval" defaults to eval/<sample_id>.npz
    PKG/eval/<sample_id>.npz (or .json with the same keys)
        part_ids            (P,)          part ids, sorted
        points              (P, 1000, 3)  evaluator points per part, in the baked initial geometry
        target_poses        (P, 7)        [tx, ty, tz, qw, qx, qy, qz] per part
        scale_divisor       ()            evaluation scale divisor (baked units)
        equivalence_groups  (P,) int group label per part, or a JSON text / list of id lists

Scoring a state: target points of part i = apply(target_poses[i], points[i]) / divisor,
predicted points = apply(pose_i, points[i]) / divisor, exactly as for this project's suites.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from aw.formats import FormatError

__all__ = ["N_POINTS", "EvalInputs", "Sample", "OfficialPackage", "read_eval_inputs", "write_eval_inputs"]

N_POINTS = 1000
_ALIASES = {
    "points": ("points", "part_points", "clouds", "part_pcs"),
    "target_poses": ("target_poses", "targets", "gt_poses"),
    "scale_divisor": ("scale_divisor", "divisor", "scale"),
    "equivalence_groups": ("equivalence_groups", "groups", "group_ids", "equivalence"),
}


@dataclass
class EvalInputs:
    """One sample's evaluation inputs (all checked)."""

    sample_id: str
    part_ids: list[str]
    points: np.ndarray  # (P, 1000, 3)
    target_poses: np.ndarray  # (P, 7) as published (the evaluator normalizes quaternions)
    divisor: float
    groups: list[list[str]]  # equivalence groups (every part in exactly one group), sorted

    @property
    def n_parts(self) -> int:
        return len(self.part_ids)

    def group_labels(self) -> np.ndarray:
        """``(P,)`` int: the index of each part's group."""
        lab = np.empty(self.n_parts, dtype=np.int64)
        index = {p: i for i, p in enumerate(self.part_ids)}
        for g, members in enumerate(self.groups):
            for m in members:
                lab[index[m]] = g
        return lab

    def centroids(self) -> np.ndarray:
        """``(P, 3)`` centroids of the official points (baked frame): they are area-weighted
        surface samples, so their mean stands in for the surface centroid of a mesh."""
        return self.points.mean(axis=1)

    def size_ratio(self) -> float:
        """Largest over smallest part PCA-box diagonal, measured on the official points."""
        from aw.prepare.geometry import part_size_ratio

        return part_size_ratio(list(self.points))

    def task_geometry(self):
        """The evaluator's geometry (``aw_eval.TaskGeometry.from_points``) of this sample."""
        from aw_eval import TaskGeometry

        return TaskGeometry.from_points(self.part_ids, self.points, self.target_poses, self.divisor, self.groups)


def _get(data: dict[str, Any], key: str, where: Path) -> Any:
    for name in _ALIASES.get(key, (key,)):
        if name in data:
            return data[name]
    raise FormatError(where, f"{key}: missing (keys: {sorted(data)})")


def _groups(raw: Any, part_ids: list[str], where: Path) -> list[list[str]]:
    arr = np.asarray(raw) if not isinstance(raw, (str, list)) else None
    if isinstance(raw, (str, bytes)) or (arr is not None and arr.dtype.kind in "US" and arr.ndim == 0):
        try:
            raw = json.loads(str(raw if arr is None else arr.item()))
        except ValueError:
            raise FormatError(where, "equivalence_groups: not valid JSON text") from None
        arr = None
    if arr is not None and arr.dtype.kind in "iu":
        if arr.shape != (len(part_ids),):
            raise FormatError(where, f"equivalence_groups: expected one label per part ({len(part_ids)}), got shape {arr.shape}")
        by: dict[int, list[str]] = {}
        for p, g in zip(part_ids, arr.tolist()):
            by.setdefault(int(g), []).append(p)
        groups = list(by.values())
    else:
        if arr is not None:
            raw = arr.tolist()
        if not isinstance(raw, list) or not all(isinstance(g, list) for g in raw):
            raise FormatError(where, "equivalence_groups: expected group labels (P,) or a list of part-id lists")
        groups = [[str(x) for x in g] for g in raw]
        seen = [p for g in groups for p in g]
        unknown = sorted(set(seen) - set(part_ids))
        if unknown:
            raise FormatError(where, f"equivalence_groups: unknown part ids {unknown}")
        dup = sorted({p for p in seen if seen.count(p) > 1})
        if dup:
            raise FormatError(where, f"equivalence_groups: parts in several groups {dup}")
        groups += [[p] for p in part_ids if p not in set(seen)]  # unlisted parts are singletons
    return sorted((sorted(g) for g in groups if g), key=lambda g: g[0])


def _load_raw(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise FormatError(path, "evaluation inputs not found")
    if path.suffix == ".json":
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (ValueError, UnicodeDecodeError) as exc:
            raise FormatError(path, f"not valid JSON ({exc})") from None
        if not isinstance(data, dict):
            raise FormatError(path, "expected a JSON object")
        return data
    try:
        with np.load(path, allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise FormatError(path, f"cannot be read as .npz ({type(exc).__name__}: {exc})") from None


def read_eval_inputs(path: str | Path, sample_id: str = "") -> EvalInputs:
    """Read and check one sample's evaluation inputs (``.npz`` or ``.json``)."""
    path = Path(path)
    data = _load_raw(path)
    ids_raw = np.asarray(_get(data, "part_ids", path))
    if ids_raw.ndim != 1 or len(ids_raw) == 0:
        raise FormatError(path, f"part_ids: expected a non-empty list, got shape {ids_raw.shape}")
    part_ids = [str(x) for x in ids_raw.tolist()]
    if part_ids != sorted(set(part_ids)):
        raise FormatError(path, "part_ids: must be unique and sorted")
    n = len(part_ids)
    raw_points = _get(data, "points", path)
    try:
        points = np.asarray(raw_points, dtype=np.float64)
    except (TypeError, ValueError):
        raise FormatError(path, "points: not numeric") from None
    if points.shape != (n, N_POINTS, 3):
        raise FormatError(path, f"points: expected shape ({n}, {N_POINTS}, 3), got {points.shape}")
    if not np.isfinite(points).all():
        raise FormatError(path, "points: non-finite values")
    raw_targets = _get(data, "target_poses", path)
    try:
        targets = np.asarray(raw_targets, dtype=np.float64)
    except (TypeError, ValueError):
        raise FormatError(path, "target_poses: not numeric") from None
    if targets.shape != (n, 7):
        raise FormatError(path, f"target_poses: expected shape ({n}, 7) [tx, ty, tz, qw, qx, qy, qz], got {targets.shape}")
    if not np.isfinite(targets).all():
        raise FormatError(path, "target_poses: non-finite values")
    qn = np.linalg.norm(targets[:, 3:], axis=1)
    if np.any(qn < 1e-9):
        raise FormatError(path, f"target_poses: zero quaternion for part {part_ids[int(np.argmin(qn))]}")
    div = np.asarray(_get(data, "scale_divisor", path))
    if div.size != 1 or not np.issubdtype(div.dtype, np.number) or not np.isfinite(div).all() or float(div.reshape(())) <= 0:
        raise FormatError(path, f"scale_divisor: expected one positive number, got {div.tolist()!r}")
    try:
        raw_groups = _get(data, "equivalence_groups", path)
    except FormatError:
        raw_groups = [[p] for p in part_ids]
    groups = _groups(raw_groups, part_ids, path)
    return EvalInputs(sample_id or path.stem, part_ids, points, targets, float(div.reshape(())), groups)


def write_eval_inputs(path: str | Path, inputs: EvalInputs) -> None:
    """Write ``inputs`` as an ``.npz`` in the package layout (group labels per part)."""
    np.savez(
        Path(path),
        part_ids=np.asarray(inputs.part_ids),
        points=np.asarray(inputs.points, dtype=np.float64),
        target_poses=np.asarray(inputs.target_poses, dtype=np.float64),
        scale_divisor=np.float64(inputs.divisor),
        equivalence_groups=inputs.group_labels(),
    )


@dataclass
class Sample:
    sample_id: str
    source: str
    condition: str
    object_id: str
    category: str
    n_parts: int
    weight: float
    eval_path: Path


class OfficialPackage:
    """An official benchmark package: its samples and their evaluation inputs."""

    def __init__(self, root: str | Path):
        self.root = Path(root)
        path = self.root / "manifest.json"
        if not path.is_file():
            raise FormatError(path, "package manifest not found")
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (ValueError, UnicodeDecodeError) as exc:
            raise FormatError(path, f"not valid JSON ({exc})") from None
        recs = data.get("samples") if isinstance(data, dict) else data
        if not isinstance(recs, list) or not recs:
            raise FormatError(path, "samples: expected a non-empty list")
        self.samples: dict[str, Sample] = {}
        for k, rec in enumerate(recs):
            if not isinstance(rec, dict) or not isinstance(rec.get("sample_id"), str) or not rec["sample_id"]:
                raise FormatError(path, f"samples[{k}].sample_id: missing")
            sid = rec["sample_id"]
            if sid in self.samples:
                raise FormatError(path, f"samples[{k}].sample_id: {sid!r} appears twice")
            rel = rec.get("eval") or f"eval/{sid}.npz"
            if Path(rel).is_absolute() or ".." in Path(rel).parts:
                raise FormatError(path, f"samples[{k}].eval: must be a path inside the package")
            cond = rec.get("condition", "none")
            if cond not in ("none", "image", "manual"):
                raise FormatError(path, f"samples[{k}].condition: expected none, image or manual, got {cond!r}")
            self.samples[sid] = Sample(
                sid, str(rec.get("source", "official")), cond, str(rec.get("object_id", sid)), str(rec.get("category", "")),
                int(rec.get("n_parts", 0) or 0), float(rec.get("weight", 1.0)), self.root / rel,
            )

    def eval_inputs(self, sample_id: str) -> EvalInputs:
        if sample_id not in self.samples:
            raise KeyError(f"sample {sample_id!r} is not in {self.root / 'manifest.json'}")
        s = self.samples[sample_id]
        inputs = read_eval_inputs(s.eval_path, sample_id)
        if s.n_parts and s.n_parts != inputs.n_parts:
            raise FormatError(s.eval_path, f"part_ids: {inputs.n_parts} parts, the package manifest says {s.n_parts}")
        return inputs
