"""Every analysis of a study in one JSON-ready document: the body of ``scores.json``
(schema ``assemblyworld.scores``, version 1; see ``docs/scoring.md``)."""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass
from typing import Any

import numpy as np

from aw_eval import analyses
from aw_eval.analyses.failures import (
    CLASSES,
    classify_parts,
    far_from_assembled,
    placed_as_recorded,
    placed_parts,
)
from aw_eval.report.published import published_section
from aw_eval.settings import ProtocolSettings
from aw_eval.study.table import Study

__all__ = ["SCHEMA", "SCHEMA_VERSION", "AnalysisSettings", "build_results", "protocol_of"]

SCHEMA = "assemblyworld.scores"
SCHEMA_VERSION = 1


@dataclass(frozen=True)
class AnalysisSettings:
    seed: int = 0
    n_draws: int = 10_000
    n_permutations: int = 100_000


def _f(x):
    """Float for JSON (NaN -> None)."""
    if x is None:
        return None
    x = float(x)
    return None if not np.isfinite(x) else x


def _run_entry(study: Study, system: str, task_id: str, protocol: ProtocolSettings, suite_dir: str) -> dict[str, Any]:
    rec = study.record(system, task_id)
    r = rec.score
    info = rec.info
    entry: dict[str, Any] = {
        "system": system,
        "task_id": task_id,
        "status": r.status,
        # still being recorded when scored (a live lock): left out (status "running"), or, with
        # --allow-running, scored at its last state
        "running": rec.running is not None,
        "problems": list(r.problems),
        "final_from": r.final_from,
        "end_reason": r.end_reason,
        "truncated": r.truncated,
        "n_checkpoints": r.n_checkpoints,
        "n_calls": int(len(r.call_t)),
        "n_edits": int(len(r.edit_call)),
        "final_mode": r.final_mode or None,
        "checkpoint_mode": r.checkpoint_mode or None,
        "pa": 100 * r.pa,
        "sr": r.sr,
        "sra": r.sra,
        "scd": _f(r.scd),
        "part_errors": [_f(e) for e in r.part_errors],
        "assignment": [int(a) for a in r.assignment],
        "run_json": None
        if info is None
        else {
            "ended": info.ended,
            "wall_seconds": info.wall_seconds,
            "mcp_calls": info.mcp_calls,
            "tokens": None if info.tokens is None else info.tokens.model_dump(),
            "cost_usd": info.cost_usd,
            "declared_complete": info.declared_complete,
        },
        "run_json_problem": rec.info_problem,
    }
    if r.scored and r.n_parts:
        cl = classify_parts(r.part_errors, r.centred_cd, r.offset, r.moved)
        entry["part_classes"] = [CLASSES[c] for c in cl]
        entry["centred_cd"] = [_f(x) for x in r.centred_cd]
        entry["offset"] = [_f(x) for x in r.offset]
        entry["moved"] = [bool(x) for x in r.moved]
        facts = study.facts.get(task_id)
        ids = facts.part_ids if facts else []
        heap = far_from_assembled(r, ids, threshold=protocol.threshold, sra_threshold=protocol.sra_threshold)
        if heap is not None and suite_dir and rec.run_dir is not None and facts is not None:
            # unless most parts sit in place as recorded and the registration was pulled off them
            recorded = placed_as_recorded(suite_dir, str(rec.run_dir), r.final_from, task_id, ids, facts.divisor)
            if recorded is not None:
                placed = placed_parts(*recorded, facts.divisor, protocol.threshold)
                heap = far_from_assembled(
                    r, ids, threshold=protocol.threshold, sra_threshold=protocol.sra_threshold, placed=placed
                )
        if heap is not None:  # a high score on a state far from assembled: the report says why
            entry["far_from_assembled"] = heap
    return entry


def protocol_of(doc: dict[str, Any]) -> ProtocolSettings:
    """The protocol a ``scores.json`` document was scored with: the paper's, with its overrides."""
    over = dict(doc["settings"].get("protocol_overrides") or {})
    known = {k: v for k, v in over.items() if k in ProtocolSettings.__dataclass_fields__}
    try:
        return ProtocolSettings(**known)
    except (TypeError, ValueError):
        return ProtocolSettings()


PARTIAL_STATUSES = ("error", "task_error")


def build_results(
    study: Study,
    settings: AnalysisSettings,
    *,
    suite_dir: str = "",
    runs_dir: str = "",
    score_stats: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Run every analysis; returns the ``scores.json`` document."""
    tasks = []
    for e in study.entries:
        f = study.facts.get(e.task_id)
        tasks.append(
            {
                "task_id": e.task_id,
                "source": e.source,
                "condition": e.condition,
                "object_id": e.object_id,
                "category": e.category,
                "variant": e.variant,
                "base_task_id": e.base_task_id,
                "weight": e.weight,
                "n_parts": study.n_parts(e.task_id),
                "part_size_ratio": _f(f.part_size_ratio) if f else None,
            }
        )
    protocol = protocol_of({"settings": study.settings})
    runs = [_run_entry(study, s, e.task_id, protocol, suite_dir) for s in study.systems for e in study.entries]
    by_status: dict[str, list[dict[str, str]]] = {}
    for r in runs:
        if r["status"] != "scored":
            by_status.setdefault(r["status"], []).append(
                {"system": r["system"], "task_id": r["task_id"], "problems": r["problems"]}
            )
    doc: dict[str, Any] = {
        "format": SCHEMA,
        "format_version": SCHEMA_VERSION,
        "generated_at": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "suite": {
            "name": study.suite_name,
            "dir": suite_dir,
            "n_tasks": len(study.entries),
            "n_original": len(study.original_ids),
        },
        "runs_dir": runs_dir,
        "settings": {
            **study.settings,
            "seed": settings.seed,
            "bootstrap_draws": settings.n_draws,
            "permutations": settings.n_permutations,
        },
        "scoring": score_stats or {},
        "systems": list(study.systems),
        "roles": analyses.system_roles(study),
        "tasks": tasks,
        "runs": runs,
        "unscored_runs": by_status,
        # Runs the tool failed to score (the evaluator raised, a task's geometry did not load): the
        # aggregates count them 0, so the study is incomplete, not a measurement of those runs.
        "partial": any(st in by_status for st in PARTIAL_STATUSES),
        "unknown_runs": study.unknown_runs,
        "running_runs": [
            {"system": s, "task_id": t, "recorded_by": rec.running, "scored": rec.score.scored}
            for (s, t), rec in sorted(study.runs.items())
            if rec.running is not None
        ],
        "quality": analyses.quality(study),
        "resources": analyses.resources(study),
        "outcomes": analyses.outcomes(study),
        "uncertainty": analyses.uncertainty(
            study, n_draws=settings.n_draws, n_permutations=settings.n_permutations, seed=settings.seed
        ),
        "thresholds": analyses.threshold_sweep(study),
        "failures": analyses.failure_analysis(study),
        "dynamics": analyses.dynamics(study),
        "curves": analyses.quality_curves(study),
        "pa_decreases": analyses.pa_decreases(study),
        "scd_tail": analyses.scd_tail(study),
        "part_scale": analyses.part_scale(study),
        "part_count": analyses.part_count_bands(study),
        "categories": analyses.category_results(study),
        "completion": analyses.completion_reports(study),
        "robustness": analyses.robustness(study),
        "published": published_section(suite_dir),
    }
    return doc
