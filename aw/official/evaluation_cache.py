"""The official per-sample evaluation inputs: ``cache/<slug>/evaluation.json``.

Written by assembly-world-agent ``evaluation/cache.py`` (``cache_entry``), read and checked by
assembly-world-bench ``scoring.py`` (``evaluation_inputs``)::

    {"version": 1,
     "key": {"sample_id", "identity" (= config.json identity), "initial_sha256" (initial archive),
             "parts" (P), "preparation_protocol" (= identity.protocol),
             "evaluation_protocol": "assembly-evaluation-v1",
             "similarity": {"policy": "geometry", "threshold": 0.0001, ...description}},
     "provenance": {"created_at", "code_commit", "dataset"},          (not read by the scorer)
     "part_ids": [P sorted part ids],
     "scale_divisor": d,
     "points": {part id: 1000 x [x, y, z]}     in the part's body frame (the episode's mesh frame)
     "gt_poses": {part id: [x, y, z, qw, qx, qy, qz]},                 target body pose
     "equivalence": {"groups": [[part ids]...], "protocol": = key.similarity, ...diagnostics}}

Scoring a state: target points ``(points @ R(gt)^T + t(gt)) / d``, predicted points the same
with the state's body pose; ``d`` divides every coordinate before any distance.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aw.formats.strict_json import read_json
from aw.official.errors import EvaluationCacheError

__all__ = [
    "CACHE_FILE",
    "EVALUATION_PROTOCOL",
    "PREPARATION_PROTOCOL",
    "POINTS_PER_PART",
    "SIMILARITY_POLICY",
    "SIMILARITY_THRESHOLD",
    "similarity_protocol",
    "EvaluationInputs",
    "read_evaluation",
    "write_evaluation",
    "write_json",
]

CACHE_FILE = "evaluation.json"
EVALUATION_PROTOCOL = "assembly-evaluation-v1"  # assembly-world-bench common.py PROTOCOL
PREPARATION_PROTOCOL = "assembly-preparation-v1"  # assembly-world-agent models.py PROTOCOL_VERSION
POINTS_PER_PART = 1000
SIMILARITY_POLICY = "geometry"
SIMILARITY_THRESHOLD = 0.0001


def similarity_protocol(threshold: float = SIMILARITY_THRESHOLD) -> dict[str, Any]:
    """The ``key.similarity`` object the official preparation writes for its geometry policy
    (assembly-world-agent ``similarity.py`` ``SimilarityConfig.protocol``): the scorer reads only
    ``policy`` and ``threshold``; the other entries describe how the groups were found."""
    return {
        "policy": SIMILARITY_POLICY,
        "threshold": threshold,
        "distance": "sum of bidirectional mean squared nearest-neighbor distances",
        "scale": "shared largest part vertex-PCA AABB diagonal = 1",
        "sampling": "4096 area-weighted candidates, 1000 FPS; preparation sampling seed",
        "alignment": "24 proper PCA starts; symmetric ICP; SE(3) only; no pose seeds",
        "max_iterations": 100,
        "improvement_tolerance": 1e-9,
        "grouping": "connected components of CD <= threshold",
    }


@dataclass
class EvaluationInputs:
    """One sample's checked evaluation inputs.

    ``points`` ``(P, 1000, 3)`` and ``target_poses`` ``(P, 7)`` follow ``part_ids`` (sorted);
    ``groups`` is the equivalence partition as written (lists of part ids)."""

    sample_id: str
    part_ids: list[str]
    points: np.ndarray
    target_poses: np.ndarray
    divisor: float
    groups: list[list[str]]
    key: dict[str, Any] = field(default_factory=dict)
    equivalence: dict[str, Any] = field(default_factory=dict)
    provenance: dict[str, Any] | None = None

    @property
    def n_parts(self) -> int:
        return len(self.part_ids)

    def group_labels(self) -> np.ndarray:
        """``(P,)`` int: each part's group index."""
        index = {p: i for i, p in enumerate(self.part_ids)}
        labels = np.empty(self.n_parts, dtype=np.int64)
        for g, members in enumerate(self.groups):
            labels[[index[m] for m in members]] = g
        return labels


def _fail(path: Path, problem: str) -> EvaluationCacheError:
    return EvaluationCacheError(path, problem)


def read_evaluation(
    path: str | Path,
    *,
    sample_id: str | None = None,
    identity: dict | None = None,
    initial_sha256: str | None = None,
    parts: int | None = None,
) -> EvaluationInputs:
    """Read and check an ``evaluation.json``. The keyword arguments are what the package says of
    the sample (config identity, initial archive digest, part count); each one given must match
    the file's key, as the official scorer requires."""
    path = Path(path)
    if not path.is_file():
        raise _fail(path, "evaluation inputs not found")
    value = read_json(path, error=EvaluationCacheError)
    if not isinstance(value, dict) or not {
        "version",
        "key",
        "part_ids",
        "points",
        "gt_poses",
        "scale_divisor",
        "equivalence",
    } <= set(value):
        raise _fail(
            path, "expected an object with version, key, part_ids, points, gt_poses, scale_divisor, equivalence"
        )
    key, equivalence = value["key"], value["equivalence"]
    if value["version"] != 1 or not isinstance(key, dict) or not isinstance(equivalence, dict):
        raise _fail(path, f"version {value['version']!r} (expected 1), or key/equivalence not objects")
    required = (
        "sample_id",
        "identity",
        "initial_sha256",
        "parts",
        "preparation_protocol",
        "evaluation_protocol",
        "similarity",
    )
    missing = [k for k in required if k not in key]
    if missing:
        raise _fail(path, f"key: missing {missing}")
    if key["evaluation_protocol"] != EVALUATION_PROTOCOL:
        raise _fail(
            path, f"key.evaluation_protocol is {key['evaluation_protocol']!r}, expected {EVALUATION_PROTOCOL!r}"
        )
    similarity = key["similarity"]
    if (
        not isinstance(similarity, dict)
        or similarity.get("policy") != SIMILARITY_POLICY
        or similarity.get("threshold") != SIMILARITY_THRESHOLD
    ):
        raise _fail(
            path, f"key.similarity must be the {SIMILARITY_POLICY!r} policy at threshold {SIMILARITY_THRESHOLD}"
        )
    if equivalence.get("protocol") != similarity:
        raise _fail(path, "equivalence.protocol differs from key.similarity")
    if not isinstance(key["identity"], dict) or key["preparation_protocol"] != key["identity"].get("protocol"):
        raise _fail(path, "key.preparation_protocol differs from key.identity.protocol")
    for name, want in (
        ("sample_id", sample_id),
        ("identity", identity),
        ("initial_sha256", initial_sha256),
        ("parts", parts),
    ):
        if want is not None and key[name] != want:
            raise _fail(path, f"key.{name} is {key[name]!r}, the package says {want!r}")
    ids = value["part_ids"]
    if (
        not isinstance(ids, list)
        or not ids
        or not all(isinstance(p, str) for p in ids)
        or ids != sorted(set(ids))
        or len(ids) != key["parts"]
    ):
        raise _fail(path, f"part_ids must be {key['parts']!r} distinct sorted strings")
    groups = equivalence.get("groups")
    if (
        not isinstance(groups, list)
        or any(not isinstance(g, list) or not g for g in groups)
        or sorted(p for g in groups for p in g) != ids
    ):
        raise _fail(path, "equivalence.groups must partition part_ids into non-empty groups")
    divisor = value["scale_divisor"]
    if isinstance(divisor, bool) or not isinstance(divisor, (int, float)) or not math.isfinite(divisor) or divisor <= 0:
        raise _fail(path, f"scale_divisor must be a positive finite number, got {divisor!r}")
    points, poses = [], []
    for pid in ids:
        try:
            cloud = np.asarray(value["points"][pid], dtype=np.float64)
            pose = np.asarray(value["gt_poses"][pid], dtype=np.float64)
        except (KeyError, TypeError, ValueError):
            raise _fail(path, f"points/gt_poses of part {pid!r}: missing or not numeric") from None
        if cloud.shape != (POINTS_PER_PART, 3) or pose.shape != (7,):
            raise _fail(
                path,
                f"part {pid!r}: points {cloud.shape} / gt_poses {pose.shape}, expected ({POINTS_PER_PART}, 3) / (7,)",
            )
        if not np.isfinite(cloud).all() or not np.isfinite(pose).all():
            raise _fail(path, f"part {pid!r}: non-finite points or pose")
        if np.linalg.norm(pose[3:]) == 0:
            raise _fail(path, f"part {pid!r}: gt_poses quaternion is zero")
        points.append(cloud)
        poses.append(pose)
    return EvaluationInputs(
        key["sample_id"],
        list(ids),
        np.stack(points),
        np.stack(poses),
        float(divisor),
        [list(g) for g in groups],
        key,
        equivalence,
        value.get("provenance"),
    )


def write_json(path: str | Path, value: Any) -> None:
    """JSON as the official tools write it: indent 2, no NaN, trailing newline, atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(value, fh, indent=2, allow_nan=False)
            fh.write("\n")
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_evaluation(path: str | Path, inputs: EvaluationInputs) -> None:
    """Write ``inputs`` as an ``evaluation.json``; ``inputs.key`` must hold the official key."""
    groups = [list(g) for g in inputs.groups]
    equivalence = dict(inputs.equivalence, groups=groups, protocol=inputs.key.get("similarity"))
    value = {
        "version": 1,
        "key": inputs.key,
        **({"provenance": inputs.provenance} if inputs.provenance is not None else {}),
        "part_ids": list(inputs.part_ids),
        "scale_divisor": float(inputs.divisor),
        "points": {
            p: np.asarray(c, dtype=np.float64).tolist() for p, c in zip(inputs.part_ids, inputs.points, strict=True)
        },
        "gt_poses": {
            p: np.asarray(q, dtype=np.float64).tolist()
            for p, q in zip(inputs.part_ids, inputs.target_poses, strict=True)
        },
        "equivalence": equivalence,
    }
    write_json(path, value)
