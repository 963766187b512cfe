"""Helpers for the aw-score tests: designs shaped like the paper's benchmark and synthetic studies
built directly from per-part error arrays (no evaluator)."""

from __future__ import annotations

import numpy as np

from aw_eval.stats import Design, TaskMeta

BLOCKS = (
    ("partnet", ("none", "image")),
    ("ikea_manual", ("manual",)),
    ("assemblybench", ("manual",)),
    ("fantastic_breaks", ("none",)),
)


def paper_design(n_objects: int = 20) -> Design:
    """100 tasks over 80 objects: PartNet none+image share objects, the others one condition."""
    tasks = []
    for source, conds in BLOCKS:
        for o in range(n_objects):
            for c in conds:
                tasks.append(TaskMeta(f"{source}-o{o:02d}-{c}", source, c, f"o{o:02d}"))
    return Design.from_tasks(tasks)


def sr_row(design: Design, successes: dict[tuple[str, str], set[int]]) -> np.ndarray:
    """Per-task SR (0/1): task of object ``oNN`` in cell (source, condition) succeeds if NN is listed."""
    return np.array(
        [1.0 if int(t.object_id[1:]) in successes.get((t.source, t.condition), set()) else 0.0 for t in design.tasks]
    )


def first_k(design: Design, counts: dict[tuple[str, str], int]) -> np.ndarray:
    """SR row where the first ``k`` objects of every cell succeed (nested across conditions)."""
    return sr_row(design, {cell: set(range(k)) for cell, k in counts.items()})


# ---- synthetic studies (no evaluator): RunScores from per-part error arrays -----------------

from aw.formats import RunInfo, SuiteEntry  # noqa: E402
from aw_eval.study import RunRecord, RunScore, Study  # noqa: E402


def paper_entries(n_objects: int = 20, n_parts: int = 4) -> list[SuiteEntry]:
    out = []
    for source, conds in BLOCKS:
        for o in range(n_objects):
            for c in conds:
                out.append(
                    SuiteEntry(
                        task_id=f"{source}-o{o:02d}-{c}",
                        source=source,
                        condition=c,
                        object_id=f"o{o:02d}",
                        category="chair" if o % 2 else "table",
                        n_parts=n_parts,
                    )
                )
    return out


def run_from_errors(
    system: str,
    task_id: str,
    errors,
    *,
    scd: float | None = None,
    centred=None,
    offset=None,
    moved=None,
    status: str = "scored",
    **kw,
) -> RunScore:
    """A scored run whose final part errors are ``errors``; PA/SR follow the protocol threshold."""
    if status != "scored":
        return RunScore.unscored(system, task_id, status, [status])
    e = np.asarray(errors, dtype=float)
    p = len(e)
    ok = e <= 0.01
    r = RunScore(
        system=system,
        task_id=task_id,
        status="scored",
        final_from="final.json",
        end_reason="finished",
        has_trajectory=True,
        pa=float(ok.mean()),
        sr=float(ok.all()),
        scd=float(e.mean() if scd is None else scd),
        part_errors=e,
        assignment=np.arange(p),
        centred_cd=np.zeros(p) if centred is None else np.asarray(centred, float),
        offset=np.zeros(p) if offset is None else np.asarray(offset, float),
        moved=np.ones(p, bool) if moved is None else np.asarray(moved, bool),
    )
    r.sra = float(r.scd < 0.02)
    for k, v in kw.items():
        setattr(r, k, v)
    return r


def make_study(entries: list[SuiteEntry], runs: dict[tuple[str, str], RunScore], infos=None, facts=None) -> Study:
    systems = sorted({s for s, _ in runs})
    records = {}
    for s in systems:
        for e in entries:
            sc = runs.get((s, e.task_id)) or RunScore.unscored(s, e.task_id, "missing", ["no run"])
            records[(s, e.task_id)] = RunRecord(sc, (infos or {}).get((s, e.task_id)))
    return Study("synthetic", entries, systems, records, facts or {})


def table1_study() -> Study:
    """Astra and Qwen with the per-source SR of the paper's Table 1 (20 objects per source)."""
    entries = paper_entries()
    counts = {
        "Astra": {
            "partnet-none": 3,
            "partnet-image": 8,
            "ikea_manual-manual": 13,
            "assemblybench-manual": 11,
            "fantastic_breaks-none": 18,
        },
        "Qwen": {
            "partnet-none": 1,
            "partnet-image": 0,
            "ikea_manual-manual": 0,
            "assemblybench-manual": 2,
            "fantastic_breaks-none": 7,
        },
    }
    runs = {}
    for s, cnt in counts.items():
        for e in entries:
            o = int(e.object_id[1:])
            win = o < cnt[f"{e.source}-{e.condition}"]
            errors = [0.001, 0.002, 0.003, 0.004] if win else [0.001, 0.5, 0.002, 0.9]
            runs[(s, e.task_id)] = run_from_errors(s, e.task_id, errors)
    infos = {
        (s, e.task_id): RunInfo(system=s, task_id=e.task_id, wall_seconds=360.0, mcp_calls=90, cost_usd=2.0)
        for s in counts
        for e in entries
    }
    return make_study(entries, runs, infos)
