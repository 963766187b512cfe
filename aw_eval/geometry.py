"""Per-task geometry, computed once and cached: the only task input scoring needs.

A :class:`TaskGeometry` holds, for the scored parts (distractors excluded) in task order, the
evaluation clouds in the baked frame, the target poses, the scale divisor and the equivalence
groups. A checkpoint is then only an array of part poses ``(P, 7)``.

It is plain data (NumPy arrays, tuples, a frozen settings object), so it pickles to any worker
process; derived structures (normalized target points, KD-trees) are rebuilt lazily per process.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh
from numpy.typing import ArrayLike

from aw.formats import FormatError
from aw.formats.strict_json import parse_json
from aw.pose import apply_pose, as_finite, pca_frame, quat_to_matrix
from aw_eval.settings import PROTOCOL_VERSION, ProtocolSettings

if TYPE_CHECKING:  # imported where it is built: the kernels are loaded on first use
    from aw_eval.kernels import TaskIndex

__all__ = [
    "TaskGeometry",
    "Checkpoint",
    "GroupsLike",
    "load_task_geometry",
    "part_divisor",
    "default_cache_dir",
    "normalize_groups",
]

# Equivalence groups as given by a caller: each group a collection of part ids or part indices.
GroupsLike = Iterable[Iterable[str | int | np.integer]]


def default_cache_dir() -> Path:
    """``$AW_CACHE_DIR`` if set, else ``~/.cache/assemblyworld/geometry``."""
    env = os.environ.get("AW_CACHE_DIR")
    return Path(env) if env else Path.home() / ".cache" / "assemblyworld" / "geometry"


def part_divisor(vertices: np.ndarray) -> float:
    """Diagonal of the PCA-aligned bounding box of the unique ``vertices (v, 3)`` of one part."""
    v = np.unique(np.asarray(vertices, dtype=np.float64), axis=0)
    origin, axes = pca_frame(v)
    local = (v - origin) @ axes
    return float(np.linalg.norm(local.max(axis=0) - local.min(axis=0)))


def normalize_groups(groups: GroupsLike, part_ids: Sequence[str]) -> tuple[tuple[int, ...], ...]:
    """Groups given as part ids or indices -> a partition of ``range(P)`` as sorted index tuples,
    ordered by first member; parts not named form singletons. Raises ``ValueError`` on unknown,
    repeated or mixed-up entries."""
    p = len(part_ids)
    pos = {pid: k for k, pid in enumerate(part_ids)}
    seen: set[int] = set()
    out: list[tuple[int, ...]] = []
    for g in groups:
        idx = []
        for item in g:
            if isinstance(item, (int, np.integer)) and not isinstance(item, bool):
                k = int(item)
                if not 0 <= k < p:
                    raise ValueError(f"group index {k} out of range for {p} parts")
            elif isinstance(item, str):
                if item not in pos:
                    raise ValueError(f"group names unknown or unscored part {item!r}")
                k = pos[item]
            else:
                raise ValueError(f"group members must be part ids or indices, got {item!r}")
            if k in seen:
                raise ValueError(f"part {part_ids[k]!r} appears in more than one group")
            seen.add(k)
            idx.append(k)
        if idx:
            out.append(tuple(sorted(idx)))
    out += [(k,) for k in range(p) if k not in seen]
    return tuple(sorted(out, key=lambda g: g[0]))


@dataclass
class TaskGeometry:
    """Everything scoring needs about one task.

    - ``part_ids``: scored part ids in task order (``P`` of them);
    - ``clouds (P, n, 3)``: evaluation samples of the baked meshes (baked frame, not normalized);
    - ``target_poses (P, 7)``: wire-form target poses;
    - ``divisor``: scale divisor (normalized = baked / divisor);
    - ``groups``: equivalence groups, a partition of ``range(P)``;
    - ``all_part_ids``: every part of the task (distractors included), to map pose dicts;
    - ``equivalence_hint``: the dataset's groups, stored for information only;
    - ``key``: cache key (hash of meshes, targets, divisor override and settings).
    """

    part_ids: tuple[str, ...]
    clouds: np.ndarray
    target_poses: np.ndarray
    divisor: float
    groups: tuple[tuple[int, ...], ...]
    settings: ProtocolSettings = field(default_factory=ProtocolSettings)
    all_part_ids: tuple[str, ...] = ()
    equivalence_hint: tuple[tuple[str, ...], ...] | None = None
    key: str = ""
    _derived: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.part_ids = tuple(str(p) for p in self.part_ids)
        self.clouds = np.ascontiguousarray(as_finite(self.clouds, (3,), "clouds"))
        self.target_poses = as_finite(self.target_poses, (7,), "target_poses")
        p = len(self.part_ids)
        if p < 1 or len(set(self.part_ids)) != p:
            raise ValueError("part_ids must be non-empty and unique")
        if self.clouds.ndim != 3 or self.clouds.shape[0] != p or self.clouds.shape[1] < 1:
            raise ValueError(f"clouds must have shape ({p}, n, 3), got {self.clouds.shape}")
        if self.target_poses.shape != (p, 7):
            raise ValueError(f"target_poses must have shape ({p}, 7), got {self.target_poses.shape}")
        if not (np.isfinite(self.divisor) and self.divisor > 0):
            raise ValueError(f"divisor must be a positive finite number, got {self.divisor!r}")
        self.divisor = float(self.divisor)
        self.groups = normalize_groups(self.groups, self.part_ids)
        if not self.all_part_ids:
            self.all_part_ids = self.part_ids
        self.all_part_ids = tuple(self.all_part_ids)
        missing = [pid for pid in self.part_ids if pid not in self.all_part_ids]
        if missing:
            raise ValueError(f"all_part_ids lacks scored parts {missing}")

    def __getstate__(self) -> dict[str, Any]:  # derived caches (KD-trees) are per process
        state = dict(self.__dict__)
        state["_derived"] = {}
        return state

    @property
    def n_parts(self) -> int:
        return len(self.part_ids)

    @property
    def n_points(self) -> int:
        """Samples per part."""
        return int(self.clouds.shape[1])

    @property
    def centroids(self) -> np.ndarray:
        """``(P, 3)`` sample centroids in the baked frame."""
        centroids: np.ndarray = self.clouds.mean(axis=1)
        return centroids

    @property
    def group_ids(self) -> list[list[str]]:
        return [[self.part_ids[i] for i in g] for g in self.groups]

    def target_parts(self) -> np.ndarray:
        """``(P, n, 3)`` normalized target points (cached)."""
        if "target_parts" not in self._derived:
            self._derived["target_parts"] = apply_pose(self.target_poses, self.clouds) / self.divisor
        parts: np.ndarray = self._derived["target_parts"]
        return parts

    def target_rotations(self) -> np.ndarray:
        """``(P, 3, 3)`` rotation matrices of the target poses (cached)."""
        if "target_rotations" not in self._derived:
            rot = quat_to_matrix(self.target_poses[:, 3:])
            rot.flags.writeable = False
            self._derived["target_rotations"] = rot
        rotations: np.ndarray = self._derived["target_rotations"]
        return rotations

    def target_frame(self) -> tuple[np.ndarray, np.ndarray]:
        """The start frame of the joined normalized target (:func:`aw_eval.starts.start_frame`, cached)."""
        if "target_frame" not in self._derived:
            from aw_eval.starts import start_frame

            self._derived["target_frame"] = start_frame(self.index().target)
        frame: tuple[np.ndarray, np.ndarray] = self._derived["target_frame"]
        return frame

    def index(self) -> TaskIndex:
        """The task's search structures (:class:`aw_eval.kernels.TaskIndex`), built once per process."""
        if "index" not in self._derived:
            from aw_eval.kernels import TaskIndex

            self._derived["index"] = TaskIndex(
                self.target_parts(), self.clouds, self.target_poses, self.divisor, self.target_rotations()
            )
        index: TaskIndex = self._derived["index"]
        return index

    def checkpoint(self, poses: ArrayLike) -> Checkpoint:
        """One checkpoint ``poses (P, 7)`` checked, with its rotations and clouds computed once."""
        arr = self.check_poses(poses)
        if arr.ndim != 2:
            raise ValueError(f"one checkpoint has poses (P, 7), got {arr.shape}")
        rotations = quat_to_matrix(arr[:, 3:])
        rotations.flags.writeable = False
        parts = apply_pose(arr, self.clouds, rotations) / self.divisor
        return Checkpoint(arr, rotations, parts, np.ascontiguousarray(parts.reshape(-1, 3)))

    def pred_parts(self, poses: ArrayLike) -> np.ndarray:
        """``(P, n, 3)`` normalized predicted points for ``poses (P, 7)``."""
        return self.checkpoint(poses).parts

    def check_poses(self, poses: ArrayLike) -> np.ndarray:
        """Validated ``(P, 7)`` or ``(N, P, 7)`` float64 poses (quaternions must be non-zero)."""
        arr = as_finite(poses, (7,), "poses")
        if arr.ndim < 2 or arr.shape[-2] != self.n_parts:
            raise ValueError(f"poses must have shape (..., {self.n_parts}, 7) for this task, got {arr.shape}")
        if np.any(np.linalg.norm(arr[..., 3:], axis=-1) < 1e-9):
            raise ValueError("poses contain a zero quaternion")
        return arr

    def poses_from_dict(self, poses: dict[str, Sequence[float]]) -> np.ndarray:
        """``(P, 7)`` scored-part poses from a dict keyed by part id (extra distractor ids allowed)."""
        unknown = [k for k in poses if k not in self.all_part_ids]
        if unknown:
            raise ValueError(f"poses name parts not in this task: {unknown}")
        missing = [pid for pid in self.part_ids if pid not in poses]
        if missing:
            raise ValueError(f"poses lack scored parts {missing}")
        return self.check_poses(np.asarray([poses[pid] for pid in self.part_ids], dtype=np.float64))

    @classmethod
    def from_points(
        cls,
        part_ids: Sequence[str],
        clouds: np.ndarray,
        target_poses: np.ndarray,
        divisor: float,
        groups: GroupsLike | None = None,
        settings: ProtocolSettings | None = None,
        all_part_ids: Sequence[str] | None = None,
    ) -> TaskGeometry:
        """Geometry from given clouds ``(P, n, 3)`` (baked frame), e.g. an official benchmark's own
        point clouds, divisor and groups. ``groups=None`` computes them (fast path)."""
        settings = settings or ProtocolSettings()
        geom = cls(tuple(part_ids), clouds, target_poses, divisor, (), settings, tuple(all_part_ids or part_ids))
        if groups is None:
            from aw_eval.equivalence import equivalence_groups

            geom.groups = normalize_groups(equivalence_groups(geom.clouds, geom.divisor, settings), geom.part_ids)
        else:
            geom.groups = normalize_groups(groups, geom.part_ids)
        h = hashlib.sha256()
        for arr in (geom.clouds, geom.target_poses, np.array([geom.divisor])):
            h.update(np.ascontiguousarray(arr).tobytes())
        h.update(json.dumps([list(g) for g in geom.groups]).encode())
        h.update(settings.fingerprint().encode())
        geom.key = h.hexdigest()[:32]
        return geom

    # --- cache -------------------------------------------------------------------------------

    def save(self, path: Path) -> None:
        """Write this geometry as ``.npz`` atomically (temp file + rename)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        labels = np.empty(self.n_parts, dtype=np.int64)
        for g_index, g in enumerate(self.groups):
            labels[list(g)] = g_index
        meta = {
            "part_ids": list(self.part_ids),
            "settings": self.settings.to_dict(),
            "protocol_version": PROTOCOL_VERSION,
            "key": self.key,
        }
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as fh:
                np.savez(
                    fh,
                    clouds=self.clouds,
                    target_poses=self.target_poses,
                    divisor=np.array(self.divisor),
                    group_labels=labels,
                    meta=np.array(json.dumps(meta)),
                )
            os.replace(tmp, path)
        except OSError as exc:  # a full disk: the error names the cache entry
            Path(tmp).unlink(missing_ok=True)
            raise OSError(exc.errno, exc.strerror, str(path)) from None
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise

    @classmethod
    def load(cls, path: Path, **extra: Any) -> TaskGeometry:
        with np.load(Path(path), allow_pickle=False) as z:
            meta = parse_json(str(z["meta"]))
            labels = z["group_labels"]
            groups = tuple(tuple(np.flatnonzero(labels == g).tolist()) for g in np.unique(labels))
            return cls(
                tuple(meta["part_ids"]),
                z["clouds"],
                z["target_poses"],
                float(z["divisor"]),
                groups,
                ProtocolSettings(**meta["settings"]),
                key=meta["key"],
                **extra,
            )


@dataclass(frozen=True)
class Checkpoint:
    """One checkpoint of a task, in the forms scoring uses (made by :meth:`TaskGeometry.checkpoint`):
    ``poses (P, 7)``, their ``rotations (P, 3, 3)``, the predicted clouds ``parts (P, n, 3)``
    (normalized: baked clouds moved by the poses, over the divisor) and ``points (P n, 3)`` joined."""

    poses: np.ndarray
    rotations: np.ndarray
    parts: np.ndarray
    points: np.ndarray


def _file_digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def load_task_geometry(
    task_dir: str | Path,
    targets_path: str | Path,
    cache_dir: str | Path | None = None,
    settings: ProtocolSettings | None = None,
    use_cache: bool = True,
) -> TaskGeometry:
    """The cached :class:`TaskGeometry` of a task (computed and stored on a cache miss).

    ``cache_dir`` defaults to :func:`default_cache_dir`. The key hashes the scored parts' mesh
    file bytes, ids and target poses, the divisor override and ``settings``; a changed mesh or
    target gives a new entry. Raises :class:`aw.formats.FormatError` for unreadable or
    inconsistent task/targets files.
    """
    from aw.formats import read_targets, read_task
    from aw.meshes import load_mesh

    settings = settings or ProtocolSettings()
    task = read_task(task_dir)
    targets = read_targets(targets_path)
    task_ids = task.part_ids
    if set(targets.parts) != set(task_ids):
        raise FormatError(Path(targets_path), "targets do not name exactly the task's parts")
    if targets.task_id != task.task_id:
        raise FormatError(Path(targets_path), f"targets are for task {targets.task_id!r}, not {task.task_id!r}")
    scored = [pid for pid in task_ids if not targets.parts[pid].distractor]
    if not scored:
        raise FormatError(Path(targets_path), "every part is a distractor: nothing to score")
    mesh_paths = {p.id: Path(task_dir) / p.mesh for p in task.parts}
    target_poses = np.asarray([targets.parts[pid].pose for pid in scored], dtype=np.float64)
    hint = None
    if targets.equivalence_hint:
        hint = tuple(tuple(g) for g in targets.equivalence_hint)

    h = hashlib.sha256()
    h.update(settings.fingerprint().encode())
    for pid in scored:
        h.update(pid.encode() + b"\0" + _file_digest(mesh_paths[pid]).encode())
    h.update(target_poses.tobytes())
    h.update(repr(targets.eval_divisor).encode())
    key = h.hexdigest()[:32]
    extra = {"all_part_ids": tuple(task_ids), "equivalence_hint": hint}

    cache_path = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    entry = cache_path / f"{key}.npz"
    if use_cache and entry.is_file():
        try:
            geom = TaskGeometry.load(entry, **extra)
            if geom.key == key and geom.part_ids == tuple(scored):
                return geom
        except (OSError, ValueError, KeyError):
            pass  # a damaged entry is recomputed and overwritten

    meshes = [load_mesh(mesh_paths[pid]) for pid in scored]
    geom = geometry_from_meshes(scored, meshes, target_poses, settings, divisor=targets.eval_divisor, **extra)
    geom.key = key
    if use_cache:
        geom.save(entry)
    return geom


def geometry_from_meshes(
    part_ids: Sequence[str],
    meshes: Sequence[trimesh.Trimesh],
    target_poses: np.ndarray,
    settings: ProtocolSettings | None = None,
    divisor: float | None = None,
    groups: GroupsLike | None = None,
    **extra: Any,
) -> TaskGeometry:
    """Geometry from baked meshes (no cache): samples + FPS, divisor (unless given), groups."""
    from aw_eval.equivalence import equivalence_groups
    from aw_eval.sampling import part_clouds

    settings = settings or ProtocolSettings()
    if divisor is None:
        divisor = max(part_divisor(np.asarray(m.vertices)) for m in meshes)
    clouds = part_clouds(list(meshes), settings)
    if groups is None:
        groups = equivalence_groups(clouds, divisor, settings)
    ids = tuple(part_ids)
    geom = TaskGeometry(ids, clouds, target_poses, divisor, normalize_groups(groups, ids), settings, **extra)
    if not geom.key:
        h = hashlib.sha256()
        h.update(settings.fingerprint().encode())
        for m in meshes:
            h.update(np.ascontiguousarray(m.vertices, dtype=np.float64).tobytes())
            h.update(np.ascontiguousarray(m.faces, dtype=np.int64).tobytes())
        h.update(np.ascontiguousarray(target_poses, dtype=np.float64).tobytes())
        h.update(repr(divisor).encode())
        geom.key = h.hexdigest()[:32]
    return geom
