"""A suite's evaluation points: ``SUITE/eval_points/<task_id>.npz``.

Arrays (one task; written by ``aw-prepare --protocol official`` and ``aw-prepare official``)::

    part_ids            (P,)          part ids, sorted
    points              (P, 1000, 3)  evaluation points per part, in the part's body frame
    target_poses        (P, 7)        [tx, ty, tz, qw, qx, qy, qz] per part
    scale_divisor       ()            divides every coordinate before any distance
    equivalence_groups  (P,) int      each part's equivalence group label

Other arrays may be present (the preparation adds provenance); this reader ignores them.
Scoring takes a task's geometry from this file whenever it exists.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from aw.formats import FormatError
from aw.official.evaluation_cache import EvaluationInputs

__all__ = ["N_POINTS", "EvalInputs", "read_eval_inputs", "write_eval_inputs", "eval_points_path", "suite_eval_inputs"]

N_POINTS = 1000
_KEYS = ("part_ids", "points", "target_poses", "scale_divisor", "equivalence_groups")


class EvalInputs(EvaluationInputs):
    """One task's checked evaluation points (the official inputs' fields; ``groups`` lists part
    ids per group, sorted), with the measures the preparation reads off them."""

    def centroids(self) -> np.ndarray:
        """``(P, 3)`` mean of each part's points (area-weighted surface samples, so close to the
        surface centroid of its mesh)."""
        return self.points.mean(axis=1)

    def size_ratio(self) -> float:
        """Largest over smallest part PCA-box diagonal, measured on the points."""
        from aw.prepare.geometry import part_size_ratio

        return part_size_ratio(list(self.points))


def read_eval_inputs(path: str | Path, sample_id: str = "") -> EvalInputs:
    """Read and check one ``.npz`` of evaluation points."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(path, "evaluation points not found")
    try:
        with np.load(path, allow_pickle=False) as npz:
            missing = [k for k in _KEYS if k not in npz.files]
            if missing:
                raise FormatError(path, f"arrays missing: {missing}")
            raw = {k: npz[k] for k in _KEYS}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        if isinstance(exc, FormatError):
            raise
        raise FormatError(path, f"cannot be read as .npz ({type(exc).__name__}: {exc})") from None
    ids = raw["part_ids"]
    if ids.ndim != 1 or len(ids) == 0 or ids.dtype.kind not in "US":
        raise FormatError(path, f"part_ids: expected a non-empty list of strings, got {ids.dtype} {ids.shape}")
    part_ids = [str(x) for x in ids.tolist()]
    if part_ids != sorted(set(part_ids)):
        raise FormatError(path, "part_ids: must be distinct and sorted")
    n = len(part_ids)
    shapes = {"points": (n, N_POINTS, 3), "target_poses": (n, 7), "scale_divisor": (), "equivalence_groups": (n,)}
    for key, shape in shapes.items():
        if raw[key].shape != shape or raw[key].dtype.kind not in "iuf":
            raise FormatError(path, f"{key}: expected numbers of shape {shape}, got {raw[key].dtype} {raw[key].shape}")
    points, targets = raw["points"].astype(np.float64), raw["target_poses"].astype(np.float64)
    divisor = float(raw["scale_divisor"])
    if not (np.isfinite(points).all() and np.isfinite(targets).all() and np.isfinite(divisor)) or divisor <= 0:
        raise FormatError(path, "points, target_poses and scale_divisor must be finite, the divisor positive")
    norms = np.linalg.norm(targets[:, 3:], axis=1)
    if np.any(norms == 0):
        raise FormatError(path, f"target_poses: zero quaternion for part {part_ids[int(np.argmin(norms))]}")
    if raw["equivalence_groups"].dtype.kind not in "iu":
        raise FormatError(path, "equivalence_groups: expected integer group labels")
    by_label: dict[int, list[str]] = {}
    for pid, label in zip(part_ids, raw["equivalence_groups"].tolist(), strict=True):
        by_label.setdefault(int(label), []).append(pid)
    groups = sorted(by_label.values(), key=lambda g: g[0])
    return EvalInputs(sample_id or path.stem, part_ids, points, targets, divisor, groups)


def write_eval_inputs(path: str | Path, inputs: EvaluationInputs) -> None:
    """Write ``inputs`` as an ``.npz`` of the layout above."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
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
    """A suite task's evaluation points, or None when it has none (then its meshes are sampled)."""
    path = eval_points_path(suite_dir, task_id)
    return read_eval_inputs(path, task_id) if path.is_file() else None
