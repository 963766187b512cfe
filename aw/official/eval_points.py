"""A converted suite's evaluation points: ``SUITE/eval_points/<task_id>.npz``.

Arrays (one sample)::

    part_ids            (P,)          part ids, sorted
    points              (P, 1000, 3)  evaluation points per part, in the part's body frame
    target_poses        (P, 7)        [tx, ty, tz, qw, qx, qy, qz] per part
    scale_divisor       ()            the divisor applied to every coordinate before distances
    equivalence_groups  (P,) int      group label per part (or a JSON text / list of id lists)

``aw-prepare official`` writes them from each sample's official ``evaluation.json``; scoring
reads them instead of sampling the task's meshes.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from aw.formats import FormatError

__all__ = ["N_POINTS", "EvalInputs", "read_eval_inputs", "write_eval_inputs", "eval_points_path", "suite_eval_inputs"]

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


def eval_points_path(suite_dir: str | Path, task_id: str) -> Path:
    return Path(suite_dir) / "eval_points" / f"{task_id}.npz"


def suite_eval_inputs(suite_dir: str | Path, task_id: str) -> EvalInputs | None:
    """The official evaluation points stored with a suite's task, or None for native tasks."""
    path = eval_points_path(suite_dir, task_id)
    return read_eval_inputs(path, task_id) if path.is_file() else None
