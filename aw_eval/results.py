"""Result types of the evaluator: a registration, one checkpoint's scores, a batch's."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aw_eval.starts import N_PCA_STARTS

__all__ = ["Registration", "ScoreResult", "BatchScores", "start_label"]


def start_label(start_index: int) -> tuple[str, int]:
    """``("pca", k)`` for the k-th PCA start, ``("part", i)`` for the same-ID start of part i."""
    if start_index < N_PCA_STARTS:
        return "pca", int(start_index)
    return "part", int(start_index - N_PCA_STARTS)


@dataclass
class Registration:
    """One rigid transform of the whole prediction: ``x -> rotation @ x + translation``."""

    scd: float  # the best objective
    rotation: np.ndarray  # (3, 3)
    translation: np.ndarray  # (3,)
    start_index: int  # 0..23 PCA starts, 24 + i same-ID start of part i
    objectives: np.ndarray | None = None  # (S,) best objective per start (None when pruned)

    @property
    def start_kind(self) -> str:
        return start_label(self.start_index)[0]

    @property
    def start_part(self) -> int:
        """Index of the cube rotation (PCA start) or of the part (same-ID start)."""
        return start_label(self.start_index)[1]


@dataclass
class ScoreResult:
    """Scores of one checkpoint; ``part_errors`` and ``assignment`` are ``(P,)`` in part order."""

    pa: float
    sr: bool
    scd: float
    sra: bool
    part_errors: np.ndarray
    assignment: np.ndarray
    reg_rotation: np.ndarray
    reg_translation: np.ndarray
    start_index: int
    mode: str = "exact"

    @property
    def start_kind(self) -> str:
        return start_label(self.start_index)[0]

    @property
    def start_part(self) -> int:
        return start_label(self.start_index)[1]


@dataclass
class BatchScores:
    """Scores of ``N`` checkpoints of one task (``P`` scored parts). Identical rows were scored once.

    ``part_errors (N, P)``, ``assignment (N, P)`` (target index matched to each predicted part),
    ``pa (N,)`` float, ``sr (N,)`` bool, ``scd (N,)``, ``sra (N,)`` bool,
    ``reg_rotation (N, 3, 3)``, ``reg_translation (N, 3)``, ``start_index (N,)``.
    """

    part_errors: np.ndarray
    assignment: np.ndarray
    pa: np.ndarray
    sr: np.ndarray
    scd: np.ndarray
    sra: np.ndarray
    reg_rotation: np.ndarray
    reg_translation: np.ndarray
    start_index: np.ndarray
    mode: str = "exact"
    n_unique: int = 0
    stats: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.pa.shape[0])

    @property
    def start_kind(self) -> np.ndarray:
        return np.where(self.start_index < N_PCA_STARTS, "pca", "part")

    def row(self, i: int) -> ScoreResult:
        return ScoreResult(
            pa=float(self.pa[i]),
            sr=bool(self.sr[i]),
            scd=float(self.scd[i]),
            sra=bool(self.sra[i]),
            part_errors=self.part_errors[i].copy(),
            assignment=self.assignment[i].copy(),
            reg_rotation=self.reg_rotation[i].copy(),
            reg_translation=self.reg_translation[i].copy(),
            start_index=int(self.start_index[i]),
            mode=self.mode,
        )

    @classmethod
    def empty(cls, n_parts: int, mode: str) -> BatchScores:
        """No rows, for a task of ``n_parts`` scored parts."""
        return cls(
            part_errors=np.zeros((0, n_parts)),
            assignment=np.zeros((0, n_parts), dtype=np.int64),
            pa=np.zeros(0),
            sr=np.zeros(0, dtype=bool),
            scd=np.zeros(0),
            sra=np.zeros(0, dtype=bool),
            reg_rotation=np.zeros((0, 3, 3)),
            reg_translation=np.zeros((0, 3)),
            start_index=np.zeros(0, dtype=np.int64),
            mode=mode,
        )

    @classmethod
    def stack(
        cls, rows: list[ScoreResult], mode: str, n_unique: int, stats: dict[str, Any] | None = None
    ) -> BatchScores:
        p = len(rows[0].part_errors) if rows else 0
        return cls(
            part_errors=np.array([r.part_errors for r in rows]).reshape(len(rows), p),
            assignment=np.array([r.assignment for r in rows], dtype=np.int64).reshape(len(rows), p),
            pa=np.array([r.pa for r in rows], dtype=np.float64),
            sr=np.array([r.sr for r in rows], dtype=bool),
            scd=np.array([r.scd for r in rows], dtype=np.float64),
            sra=np.array([r.sra for r in rows], dtype=bool),
            reg_rotation=np.array([r.reg_rotation for r in rows]).reshape(len(rows), 3, 3),
            reg_translation=np.array([r.reg_translation for r in rows]).reshape(len(rows), 3),
            start_index=np.array([r.start_index for r in rows], dtype=np.int64),
            mode=mode,
            n_unique=n_unique,
            stats=dict(stats or {}),
        )
