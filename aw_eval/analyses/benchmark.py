"""Benchmark quality per cell, source and Overall (eq. 3), resource means and run outcomes
(``tab:benchmark``, Table 1).

PA, SR and SR^a are means over all attempted tasks (an unscorable attempt counts 0) in percent;
SCD is the mean over scored attempts only, times 1000. Resource columns are arithmetic
per-evaluation means over the records that exist.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from aw_eval.study.table import Study

__all__ = ["quality", "resources", "outcomes", "cell_label"]

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
        for ci in range(len(d.cells)):
            members = d.task_cell == ci
            scd = vals["scd"][si, members]
            row["cells"].append(
                {
                    "pa": 100 * float(cw[ci] @ vals["pa"][si]),
                    "sr": 100 * float(cw[ci] @ vals["sr"][si]),
                    "sra": 100 * float(cw[ci] @ vals["sra"][si]),
                    "scd": 1000 * float(_nanmean_rows(scd[None], d.task_weight[members])[0]),
                    "n_scored": int(np.sum(~np.isnan(scd))),
                }
            )
        for k, src in enumerate(d.sources):
            row["sources"][src] = {m: 100 * float(sw[k] @ vals[m][si]) for m in ("pa", "sr", "sra")}
        row["overall"] = {m: 100 * float(d.weights @ vals[m][si]) for m in ("pa", "sr", "sra")}
        # SCD Overall: eq. 3 over the cell means of scored attempts (cells without any are dropped)
        cell_scd = np.array([c["scd"] for c in row["cells"]])
        cell_w = np.array([d.weights[d.task_cell == ci].sum() for ci in range(len(d.cells))])
        row["overall"]["scd"] = float(_nanmean_rows(cell_scd[None], cell_w)[0])
        row["n_scored"] = int(np.sum(~np.isnan(vals["scd"][si])))
        row["n_tasks"] = d.n_tasks
        out["systems"][name] = row
    return out


def _resource_values(study: Study, system: str) -> tuple[dict[str, list[float]], dict[str, list[str]]]:
    """The system's resource values per column, and where each time and call count came from."""
    cols: dict[str, list[float]] = {"time_min": [], "mcp_calls": [], "tokens_m": [], "cost_usd": []}
    src: dict[str, list[str]] = {"time_min": [], "mcp_calls": []}
    for tid in study.original_ids:
        rec = study.record(system, tid)
        info, sc = rec.info, rec.score
        if info is not None and info.wall_seconds is not None:
            cols["time_min"].append(info.wall_seconds / 60.0)
            src["time_min"].append("run.json")
        elif sc.has_trajectory:
            cols["time_min"].append(sc.end_t / 60.0)
            src["time_min"].append("trajectory")
        if info is not None and info.mcp_calls is not None:
            cols["mcp_calls"].append(float(info.mcp_calls))
            src["mcp_calls"].append("run.json")
        elif sc.has_trajectory:
            cols["mcp_calls"].append(float(len(sc.call_t)))
            src["mcp_calls"].append("trajectory")
        if info is not None and info.tokens is not None:
            tok = info.tokens.total
            if tok is None and info.tokens.input is not None and info.tokens.output is not None:
                tok = info.tokens.input + info.tokens.output
            if tok is not None:
                cols["tokens_m"].append(tok / 1e6)
        if info is not None and info.cost_usd is not None:
            cols["cost_usd"].append(info.cost_usd)
    return cols, src


def resources(study: Study) -> dict[str, Any]:
    """Per system: mean time (minutes), MCP calls, tokens (millions), cost (USD) over the
    original tasks, with the number of records behind each mean.

    Time and calls come from ``run.json`` (``wall_seconds``, ``mcp_calls``) and fall back to the
    trajectory (time of the end record or last call; number of recorded calls) when run.json
    lacks them; tokens and cost only from run.json.
    """
    out = {}
    for s in study.systems:
        cols, srcs = _resource_values(study, s)
        row: dict[str, dict[str, Any]] = {}
        for k, v in cols.items():
            row[k] = {"mean": float(np.mean(v)) if v else None, "n": len(v)}
        for k, where in srcs.items():
            row[k]["from_trajectory"] = int(sum(1 for x in where if x == "trajectory"))
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
