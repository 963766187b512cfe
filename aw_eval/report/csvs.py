"""``tasks.csv`` (one row per system and task) and ``checkpoints.csv`` (one row per scored
checkpoint)."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

from aw.formats.io import atomic_path
from aw_eval.study.table import Study

__all__ = ["TASK_COLUMNS", "CHECKPOINT_COLUMNS", "write_task_csv", "write_checkpoint_csv"]

TASK_COLUMNS = [
    "system",
    "task_id",
    "source",
    "condition",
    "object_id",
    "category",
    "variant",
    "base_task_id",
    "n_parts",
    "status",
    "final_from",
    "end_reason",
    "ended",
    "truncated",
    "n_checkpoints",
    "pa",
    "sr",
    "sra",
    "scd",
    "n_correct",
    "wall_seconds",
    "mcp_calls",
    "tokens",
    "cost_usd",
    "declared_complete",
    "problems",
]
CHECKPOINT_COLUMNS = ["system", "task_id", "seq", "t", "pa", "sr", "sra", "scd", "n_correct", "n_parts"]


def _num(x) -> str:
    if x is None:
        return ""
    if isinstance(x, bool):
        return str(int(x))
    if isinstance(x, float):
        return "" if math.isnan(x) else repr(x)
    return str(x)


def write_task_csv(study: Study, path: Path) -> int:
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(TASK_COLUMNS)
        n = 0
        for s in study.systems:
            for e in study.entries:
                rec = study.record(s, e.task_id)
                r, info = rec.score, rec.info
                tokens = None
                if info is not None and info.tokens is not None:
                    tokens = info.tokens.total
                    if tokens is None and info.tokens.input is not None and info.tokens.output is not None:
                        tokens = info.tokens.input + info.tokens.output
                row: dict[str, Any] = {
                    "system": s,
                    "task_id": e.task_id,
                    "source": e.source,
                    "condition": e.condition,
                    "object_id": e.object_id,
                    "category": e.category,
                    "variant": e.variant,
                    "base_task_id": e.base_task_id,
                    "n_parts": study.n_parts(e.task_id),
                    "status": r.status,
                    "final_from": r.final_from,
                    "end_reason": r.end_reason,
                    # a run still being recorded has no run.json yet: "running" says why
                    "ended": "running" if rec.running is not None else (info.ended if info is not None else None),
                    "truncated": r.truncated,
                    "n_checkpoints": r.n_checkpoints,
                    "pa": float(r.pa),
                    "sr": float(r.sr),
                    "sra": float(r.sra),
                    "scd": float(r.scd),
                    "n_correct": int(round(r.pa * r.n_parts)) if r.n_parts else 0,
                    "wall_seconds": info.wall_seconds if info is not None else None,
                    "mcp_calls": info.mcp_calls if info is not None else None,
                    "tokens": tokens,
                    "cost_usd": info.cost_usd if info is not None else None,
                    "declared_complete": info.declared_complete if info is not None else None,
                    "problems": "; ".join(r.problems + ([rec.info_problem] if rec.info_problem else [])),
                }
                w.writerow([_num(row[c]) for c in TASK_COLUMNS])
                n += 1
    return n


def write_checkpoint_csv(study: Study, path: Path) -> int:
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CHECKPOINT_COLUMNS)
        n = 0
        for s in study.systems:
            for e in study.entries:
                r = study.score(s, e.task_id)
                for i in range(r.n_checkpoints):
                    n_correct = int(round(float(r.ck_pa[i]) * r.n_parts))
                    w.writerow(
                        [
                            s,
                            e.task_id,
                            int(r.ck_seq[i]),
                            repr(float(r.ck_t[i])),
                            repr(float(r.ck_pa[i])),
                            _num(float(r.ck_sr[i])),
                            _num(float(r.ck_sra[i])),
                            _num(float(r.ck_scd[i])),
                            n_correct,
                            r.n_parts,
                        ]
                    )
                    n += 1
    return n
