"""The scorer: each sample's recorded final state scored by the protocol, ``aw-score``'s own code.

A sample's score is what ``aw-score SUITE RUNS`` computes for its run folder: the same per-task
job (:func:`aw_eval.study.score_task`, final state in ``exact`` mode), so the numbers are
identical. Its value holds ``pa`` (fraction of parts correct), ``sr`` and ``sra`` (0 or 1) and
``scd`` (raw; NaN when the state could not be scored); the explanation lists every part's error.
The task's metrics aggregate them as Table 1 does (Overall, eq. 3: sources weighted equally,
PartNet's two conditions averaged first): PA, SR, SR^a in percent, SCD x1000. Inspect averages a
sample's epochs before the metrics, so with several epochs the metrics are the mean over epochs.
"""

from __future__ import annotations

import math
from pathlib import Path

import anyio
import numpy as np
from inspect_ai.scorer import Metric, SampleScore, Score, Scorer, Target, Value, metric, scorer
from inspect_ai.solver import TaskState

from assemblyworld.episode import RUN_DIR_KEY
from aw.formats.suite import suite_paths
from aw_eval.analyses.benchmark import overall
from aw_eval.stats.design import Design, TaskMeta
from aw_eval.study import STATUS_SCORED, RunRequest, RunScore, ScoreSettings, TaskJob, score_task

__all__ = ["score_run", "explanation", "overall_pa", "overall_sr", "overall_sra", "overall_scd", "assembly_score"]

FINAL_ONLY_EXACT = ScoreSettings(final_mode="exact", final_only=True)  # aw-score's tables score final states so


def score_run(suite_dir: Path, task_id: str, run_dir: Path, system: str) -> tuple[RunScore, list[str]]:
    """``(score, scored part ids)`` of one run folder, computed as ``aw-score`` computes it."""
    task_dir, targets = suite_paths(suite_dir, task_id)
    job = TaskJob(task_id, str(task_dir), str(targets), (RunRequest(system, str(run_dir)),), FINAL_ONLY_EXACT)
    out = score_task(job)
    return out.results[0], (out.facts.part_ids if out.facts is not None else [])


def explanation(run: RunScore, part_ids: list[str], threshold: float = 0.01) -> str:
    """One line of totals, then one line per part: its error and the target part it was matched to."""
    lines = [
        f"PA {100 * run.pa:.1f}% ({int(round(run.pa * len(part_ids)))}/{len(part_ids)} parts), SR {int(run.sr)}, "
        f"SR^a {int(run.sra)}, SCD x1000 {1000 * run.scd:.3f}; final state from {run.final_from}"
        + (f", episode end: {run.end_reason}" if run.end_reason else "")
    ]
    for k, pid in enumerate(part_ids):
        err = float(run.part_errors[k])
        target = part_ids[int(run.assignment[k])]
        mark = "correct" if err <= threshold else "wrong"
        lines.append(f"{pid} -> {target}: CD {err:.6g} ({mark})")
    lines += [f"note: {p}" for p in run.problems]
    return "\n".join(lines)


def _eq3(key: str) -> Metric:
    """The eq. 3 aggregate of ``key`` over the scored samples (their metadata gives the design)."""

    def compute(scores: list[SampleScore]) -> Value:
        metas: list[TaskMeta] = []
        vals: dict[str, list[float]] = {m: [] for m in ("pa", "sr", "sra", "scd")}
        for s in scores:
            md = s.sample_metadata or {}
            value = s.score.value
            if not isinstance(value, dict):
                continue
            metas.append(
                TaskMeta(
                    task_id=str(s.sample_id),
                    source=str(md.get("source", "custom")),
                    condition=str(md.get("condition", "none")),
                    object_id=str(md.get("object_id", s.sample_id)),
                    weight=float(md.get("weight", 1.0)),
                )
            )
            for m in vals:
                x = value.get(m)
                vals[m].append(float("nan") if x is None else float(x))
        if not metas:
            return float("nan")
        agg = overall(Design.from_tasks(metas), {m: np.asarray(v, dtype=np.float64) for m, v in vals.items()})
        return agg[key]

    return compute


@metric
def overall_pa() -> Metric:
    """Overall PA (eq. 3), percent."""
    return _eq3("pa")


@metric
def overall_sr() -> Metric:
    """Overall SR (eq. 3), percent."""
    return _eq3("sr")


@metric
def overall_sra() -> Metric:
    """Overall SR^a (eq. 3), percent."""
    return _eq3("sra")


@metric
def overall_scd() -> Metric:
    """Overall SCD x1000 (eq. 3 over the cells' means of scored samples)."""
    return _eq3("scd")


@scorer(metrics=[overall_pa(), overall_sr(), overall_sra(), overall_scd()])
def assembly_score(suite_dir: Path) -> Scorer:
    """Score the sample's recorded final state (see the module doc)."""

    async def score(state: TaskState, target: Target) -> Score:
        run_dir = state.store.get(RUN_DIR_KEY)
        if not run_dir:
            raise RuntimeError(f"{state.sample_id}: no episode was recorded (the solver did not run)")
        task_id = str(state.sample_id)
        run, part_ids = await anyio.to_thread.run_sync(score_run, suite_dir, task_id, Path(run_dir), "inspect")
        if run.status != STATUS_SCORED:
            raise RuntimeError(f"{task_id}: the recording in {run_dir} could not be scored: {'; '.join(run.problems)}")
        return Score(
            value={"pa": run.pa, "sr": run.sr, "sra": run.sra, "scd": None if math.isnan(run.scd) else run.scd},
            answer=state.output.completion or None,
            explanation=explanation(run, part_ids),
            metadata={"run_dir": str(run_dir), "final_from": run.final_from, "end_reason": run.end_reason},
        )

    return score
