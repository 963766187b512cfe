"""Per-run and per-task results of a study, and their on-disk form (one ``.npz`` each).

A :class:`RunScore` is everything the statistics and analyses need from one (system, task) run,
computed once by the per-task job and cached. Arrays are stored as NumPy arrays, everything else
as one JSON document inside the same ``.npz`` (no pickles: ``allow_pickle=False``).
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import orjson

from aw.formats.io import write_bytes_atomic
from aw.formats.strict_json import parse_json

__all__ = [
    "RunScore",
    "TaskFacts",
    "save_npz",
    "load_npz",
    "STATUS_SCORED",
    "STATUS_MISSING",
    "STATUS_RUNNING",
    "STATUS_UNREADABLE",
]

STATUS_SCORED = "scored"
STATUS_MISSING = "missing"
STATUS_UNREADABLE = "unreadable"
STATUS_RUNNING = "running"  # still being recorded (a live lock), left out: aw-score --allow-running scores it


@dataclass
class TaskFacts:
    """Geometry facts of one task: scored part count, part-size ratio, evaluation divisor."""

    task_id: str
    n_parts: int
    part_size_ratio: float
    divisor: float
    part_ids: list[str]
    seconds_geometry: float = 0.0  # wall time of loading (or computing) the geometry


@dataclass
class RunScore:
    """One run's scores (``P`` scored parts, ``N`` checkpoints, ``C`` calls, ``E`` edits).

    Final state: ``pa`` (fraction), ``sr``, ``sra`` (0/1), ``scd`` (NaN when not scored),
    ``part_errors (P,)`` matched part CDs, ``assignment (P,)`` target index of each predicted part,
    ``centred_cd (P,)`` and ``offset (P,)`` (failure-class diagnostics), ``moved (P,)``,
    ``reg_rotation (3, 3)`` and ``reg_translation (3,)`` the saved registration (normalized
    prediction onto the normalized target; empty in caches written before it was kept).
    Checkpoints: ``ck_*`` arrays of length ``N``, ``ck_part_errors``/``ck_assignment (N, P)``,
    ``ck_reg_rotation (N, 3, 3)`` and ``ck_reg_translation (N, 3)``;
    ``ck_drop_*`` ``(D,)`` describe the PA decreases (:mod:`aw_eval.study.decreases`).
    Calls and edits: see :class:`aw_eval.study.episode.EpisodeArrays`.
    """

    system: str
    task_id: str
    status: str
    problems: list[str] = field(default_factory=list)
    final_from: str | None = None
    end_reason: str | None = None
    truncated: bool = False
    has_trajectory: bool = False
    end_t: float = 0.0
    final_mode: str = ""
    checkpoint_mode: str = ""
    seconds_checkpoints: float = 0.0  # wall time of this run's checkpoint scoring (informational)
    seconds_final: float = 0.0  # wall time of its final-state scoring
    pa: float = 0.0
    sr: float = 0.0
    sra: float = 0.0
    scd: float = float("nan")
    part_errors: np.ndarray = field(default_factory=lambda: np.zeros(0))
    assignment: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    centred_cd: np.ndarray = field(default_factory=lambda: np.zeros(0))
    offset: np.ndarray = field(default_factory=lambda: np.zeros(0))
    moved: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    reg_rotation: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    reg_translation: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    ck_seq: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    ck_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ck_pa: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ck_sr: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ck_sra: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ck_scd: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ck_part_errors: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    ck_assignment: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=np.int64))
    ck_reg_rotation: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    ck_reg_translation: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    ck_drop_index: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    ck_drop_assignment_changed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    ck_drop_persist_alignment: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    ck_drop_persist_both: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    call_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    call_kind: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int8))
    call_ok: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    edit_call: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    edit_translation: np.ndarray = field(default_factory=lambda: np.zeros(0))
    edit_rotation_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))
    edit_revisit: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    @property
    def scored(self) -> bool:
        return self.status == STATUS_SCORED

    @property
    def n_parts(self) -> int:
        return int(len(self.part_errors))

    @property
    def n_checkpoints(self) -> int:
        return int(len(self.ck_seq))

    @classmethod
    def unscored(cls, system: str, task_id: str, status: str, problems: list[str]) -> RunScore:
        """A missing or unreadable run: PA = SR = SR^a = 0, SCD undefined."""
        return cls(system=system, task_id=task_id, status=status, problems=list(problems))


def _split(obj) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    meta, arrays = {}, {}
    for f in fields(obj):
        v = getattr(obj, f.name)
        if isinstance(v, np.ndarray):
            arrays[f.name] = v
        else:
            meta[f.name] = v
    return meta, arrays


def save_npz(path: str | Path, obj: RunScore | TaskFacts) -> None:
    """Write atomically (temporary file, then rename): an interrupted run leaves no half file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta, arrays = _split(obj)
    meta_bytes = orjson.dumps({"kind": type(obj).__name__, **meta}, option=orjson.OPT_SERIALIZE_NUMPY)
    buf = io.BytesIO()
    # the members by name (Any: numpy's stubs would check each name against savez's own keywords)
    members: dict[str, Any] = {"__meta__": np.frombuffer(meta_bytes, dtype=np.uint8), **arrays}
    np.savez_compressed(buf, **members)
    write_bytes_atomic(path, buf.getvalue())  # a full disk leaves no partial entry and names this one


def load_npz(path: str | Path) -> RunScore | TaskFacts:
    """Read what :func:`save_npz` wrote; raises ``ValueError`` on a damaged file."""
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = parse_json(z["__meta__"].tobytes())
            arrays = {k: z[k] for k in z.files if k != "__meta__"}
    except (OSError, KeyError, ValueError) as exc:  # JsonError is a ValueError
        raise ValueError(f"{path}: damaged cache entry ({exc})") from None
    kind = meta.pop("kind", None)
    cls = {"RunScore": RunScore, "TaskFacts": TaskFacts}.get(kind)
    if cls is None:
        raise ValueError(f"{path}: unknown cache entry kind {kind!r}")
    for k in ("scd",):
        if k in meta and meta[k] is None:
            meta[k] = float("nan")
    return cls(**meta, **arrays)
