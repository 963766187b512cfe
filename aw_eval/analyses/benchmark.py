"""Benchmark quality per cell, source and Overall (eq. 3), resource means and run outcomes
(``tab:benchmark``, Table 1).

PA, SR and SR^a are means over all attempted tasks (an unscorable attempt counts 0) in percent;
SCD is the mean over scored attempts only, times 1000. Resource columns are arithmetic
per-evaluation means over the records that exist.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from aw_eval.stats.design import Design
from aw_eval.study.table import RunRecord, Study

__all__ = ["quality", "overall", "resources", "outcomes", "cell_label", "first_stage"]

_SHORT_SOURCE = {"partnet": "PartNet", "ikea_manual": "IKEA", "assemblybench": "AB", "fantastic_breaks": "FB"}
_SHORT_COND = {"none": "NR", "image": "IR", "manual": "M"}


def cell_label(source: str, condition: str) -> str:
    """``PartNet NR``, ``IKEA M``, ...; custom names as given."""
    return f"{_SHORT_SOURCE.get(source, source)} {_SHORT_COND.get(condition, condition)}"


def _nanmean_rows(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted mean over the last axis of ``values: (S, T)`` ignoring NaN (NaN if none)."""
    ok = ~np.isnan(values)
    w = np.where(ok, weights[None, :], 0.0)
    tot = w.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(tot > 0, np.nansum(np.where(ok, values, 0.0) * w, axis=1) / np.where(tot > 0, tot, 1), np.nan)


def _cell_scd(d: Design, scd: np.ndarray) -> np.ndarray:
    """``(C,)`` mean SCD x1000 of each cell over its scored tasks (``scd: (T,)``, NaN unscored)."""
    return np.array(
        [
            1000 * float(_nanmean_rows(scd[None, d.task_cell == ci], d.task_weight[d.task_cell == ci])[0])
            for ci in range(len(d.cells))
        ]
    )


def overall(d: Design, vals: Mapping[str, np.ndarray]) -> dict[str, float]:
    """Overall (eq. 3) of one system from its per-task values ``vals["pa"|"sr"|"sra"|"scd"]: (T,)``
    (fractions, 0/1, raw SCD with NaN where unscored): PA, SR, SR^a in percent over all tasks
    (unscored count 0), SCD x1000 by eq. 3 over the cell means of scored tasks (cells without any
    are dropped)."""
    out = {m: 100 * float(d.weights @ np.nan_to_num(vals[m], nan=0.0)) for m in ("pa", "sr", "sra")}
    cell_w = np.array([d.weights[d.task_cell == ci].sum() for ci in range(len(d.cells))])
    out["scd"] = float(_nanmean_rows(_cell_scd(d, vals["scd"])[None], cell_w)[0])
    return out


def quality(study: Study) -> dict[str, Any]:
    """Per system: each cell's n/PA/SR/SR^a/SCD, each source's, and Overall.

    Returns ``{"cells": [...], "sources": [...], "systems": {name: {...}}}`` with percent values
    (SCD x1000).
    """
    d = study.design
    if d is None:
        return {"cells": [], "sources": [], "systems": {}}
    vals = {m: study.values(m) for m in ("pa", "sr", "sra", "scd")}
    cw = d.cell_weights()  # (C, T)
    sw = d.source_weights()  # (K, T)
    out: dict[str, Any] = {
        "cells": [
            {"source": s, "condition": c, "label": cell_label(s, c), "n_tasks": int(np.sum(d.task_cell == i))}
            for i, (s, c) in enumerate(d.cells)
        ],
        "sources": list(d.sources),
        "systems": {},
    }
    for si, name in enumerate(study.systems):
        row: dict[str, Any] = {"cells": [], "sources": {}, "overall": {}}
        cell_scd = _cell_scd(d, vals["scd"][si])
        for ci in range(len(d.cells)):
            row["cells"].append(
                {
                    "pa": 100 * float(cw[ci] @ vals["pa"][si]),
                    "sr": 100 * float(cw[ci] @ vals["sr"][si]),
                    "sra": 100 * float(cw[ci] @ vals["sra"][si]),
                    "scd": float(cell_scd[ci]),
                    "n_scored": int(np.sum(~np.isnan(vals["scd"][si, d.task_cell == ci]))),
                }
            )
        for k, src in enumerate(d.sources):
            row["sources"][src] = {m: 100 * float(sw[k] @ vals[m][si]) for m in ("pa", "sr", "sra")}
        row["overall"] = overall(d, {m: v[si] for m, v in vals.items()})
        row["n_scored"] = int(np.sum(~np.isnan(vals["scd"][si])))
        row["n_tasks"] = d.n_tasks
        out["systems"][name] = row
    return out


RESOURCE_KEYS = ("time_min", "mcp_calls", "tokens_m", "cost_usd")
MAX_STAGES = 8  # a chain of runs each started from the one before (a loop in the records stops here)


def _own_resources(rec: RunRecord) -> dict[str, tuple[float, str] | None]:
    """One run's own figures ``key -> (value, source)`` (None where not recorded)."""
    info, sc = rec.info, rec.score
    out: dict[str, tuple[float, str] | None] = dict.fromkeys(RESOURCE_KEYS)
    if info is not None and info.wall_seconds is not None:
        out["time_min"] = (info.wall_seconds / 60.0, "run.json")
    elif sc.has_trajectory:
        out["time_min"] = (sc.end_t / 60.0, "trajectory")
    if info is not None and info.mcp_calls is not None:
        out["mcp_calls"] = (float(info.mcp_calls), "run.json")
    elif sc.has_trajectory:
        out["mcp_calls"] = (float(len(sc.call_t)), "trajectory")
    if info is not None and info.tokens is not None:
        tok = info.tokens.total
        if tok is None and info.tokens.input is not None and info.tokens.output is not None:
            tok = info.tokens.input + info.tokens.output
        if tok is not None:
            out["tokens_m"] = (tok / 1e6, "run.json")
    if info is not None and info.cost_usd is not None:
        out["cost_usd"] = (info.cost_usd, "run.json")
    return out


def _refused_calls(study: Study, system: str) -> list[int]:
    """Per run that says it: the calls its harness refused before they reached aw-serve
    (``run.json`` ``extra.refused_calls``)."""
    out = []
    for tid in study.original_ids:
        info = study.record(system, tid).info
        if info is not None and isinstance(info.extra.get("refused_calls"), int):
            out.append(int(info.extra["refused_calls"]))
    return out


def first_stage(study: Study, system: str, task_id: str) -> tuple[str | None, bool]:
    """The system whose run of ``task_id`` this run started from (``run.json``
    ``extra.initial_poses`` naming ``.../<system>/<task_id>/final.json``: composed refinement
    arms, ``aw-run --initial-poses RUNS/<system>``), and whether the start came from elsewhere
    (a run outside this study, a poses file). ``(None, False)``: a run from the task's layout."""
    info = study.record(system, task_id).info
    given = info.extra.get("initial_poses") if info is not None else None
    if not given:
        return None, False
    path = Path(str(given))
    if path.name == "final.json" and path.parent.name == task_id:
        owner = path.parent.parent.parts
        for s in study.systems:
            parts = tuple(s.split("/"))
            if s != system and owner[-len(parts) :] == parts:
                return s, False
    return None, True


def _run_resources(study: Study, system: str, task_id: str) -> tuple[dict[str, tuple[float, str] | None], bool, bool]:
    """``(figures, composed, left_out)``: a run's figures with those of the runs it started from
    added (``composed``), and whether a stage's figures are missing from them (``left_out``)."""
    total = _own_resources(study.record(system, task_id))
    composed = left_out = False
    seen, current = {system}, system
    for _ in range(MAX_STAGES):
        before, elsewhere = first_stage(study, current, task_id)
        left_out |= elsewhere
        if before is None or before in seen:
            break
        seen.add(before)
        stage = _own_resources(study.record(before, task_id))
        composed = True
        for k, v in total.items():
            add = stage[k]
            if v is None:
                continue
            if add is None:
                left_out = True
            else:
                total[k] = (v[0] + add[0], v[1])
        current = before
    return total, composed, left_out


def resources(study: Study) -> dict[str, Any]:
    """Per system: mean time (minutes), MCP calls, tokens (millions), cost (USD) over the
    original tasks, with the number of records behind each mean.

    Time and calls come from ``run.json`` (``wall_seconds``, ``mcp_calls``) and fall back to the
    trajectory (time of the end record or last call; number of recorded calls) when run.json
    lacks them; tokens and cost only from run.json. A run started from another run's final state
    (a composed refinement arm) counts both stages: ``composed`` says how many figures of a mean
    add an earlier stage, ``stages_left_out`` how many leave one out (its run is not in this
    study, or the start was a poses file); each key appears only where it is not zero.
    ``mcp_calls.refused_by_harness`` sums the calls that run.json says the harness refused before
    they reached aw-serve (Inspect checks arguments itself; they are part of ``mcp_calls``), over
    the runs that say it.
    """
    out = {}
    for s in study.systems:
        cols: dict[str, list[float]] = {k: [] for k in RESOURCE_KEYS}
        srcs: dict[str, list[str]] = {"time_min": [], "mcp_calls": []}
        composed = dict.fromkeys(RESOURCE_KEYS, 0)
        left_out = dict.fromkeys(RESOURCE_KEYS, 0)
        for tid in study.original_ids:
            figures, is_composed, is_short = _run_resources(study, s, tid)
            for k, v in figures.items():
                if v is None:
                    continue
                cols[k].append(v[0])
                if k in srcs:
                    srcs[k].append(v[1])
                composed[k] += is_composed
                left_out[k] += is_short
        row: dict[str, dict[str, Any]] = {}
        for k, vals in cols.items():
            row[k] = {"mean": float(np.mean(vals)) if vals else None, "n": len(vals)}
            if composed[k]:
                row[k]["composed"] = composed[k]
            if left_out[k]:
                row[k]["stages_left_out"] = left_out[k]
        for k, src in srcs.items():
            row[k]["from_trajectory"] = int(sum(1 for x in src if x == "trajectory"))
        refused = _refused_calls(study, s)
        row["mcp_calls"]["refused_by_harness"] = {"total": int(sum(refused)), "n": len(refused)}
        out[s] = row
    return out


def outcomes(study: Study) -> dict[str, Any]:
    """Per system, how runs ended: ``finished``, ``timeout``, ``error`` (any other ending),
    ``missing``, ``unreadable``, and ``errors_timeouts`` (everything but finished)."""
    out = {}
    for s in study.systems:
        counts = {"finished": 0, "timeout": 0, "error": 0, "missing": 0, "unreadable": 0}
        for tid in study.original_ids:
            rec = study.record(s, tid)
            sc = rec.score
            if sc.status in ("missing", "unreadable"):
                counts[sc.status] += 1
                continue
            ended = rec.info.ended if rec.info is not None else (sc.end_reason or "interrupted")
            if ended == "finished":
                counts["finished"] += 1
            elif ended == "timeout":
                counts["timeout"] += 1
            else:
                counts["error"] += 1
        counts["errors_timeouts"] = counts["timeout"] + counts["error"] + counts["missing"] + counts["unreadable"]
        out[s] = counts
    return out
