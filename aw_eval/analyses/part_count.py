"""Part-count bands within (source, category, condition) cells (``tab:source_complexity``):
fixed bands 2-5, 6-10 and 11-20 parts; objects outside them fall in ``1`` or ``>20``."""

from __future__ import annotations

from typing import Any

import numpy as np

from aw_eval.analyses.benchmark import cell_label
from aw_eval.study.table import Study

__all__ = ["BANDS", "band_of", "part_count_bands"]

BANDS = ("1", "2-5", "6-10", "11-20", ">20")


def band_of(n_parts: int) -> str:
    if n_parts <= 1:
        return "1"
    if n_parts <= 5:
        return "2-5"
    if n_parts <= 10:
        return "6-10"
    if n_parts <= 20:
        return "11-20"
    return ">20"


def part_count_bands(study: Study) -> dict[str, Any]:
    """Per system and cell: per band the number of tasks and mean PA/SR (percent)."""
    d = study.design
    out: dict[str, Any] = {"bands": list(BANDS), "systems": {}}
    if d is None:
        return out
    cells: dict[tuple[str, str, str], list[str]] = {}
    for t in d.tasks:
        cells.setdefault((t.source, t.category, t.condition), []).append(t.task_id)
    for s in study.systems:
        rows = []
        for (src, cat, cond), ids in cells.items():
            bands: dict[str, Any] = {}
            for b in BANDS:
                members = [i for i in ids if band_of(study.n_parts(i)) == b]
                if not members:
                    continue
                runs = [study.score(s, i) for i in members]
                bands[b] = {
                    "n": len(runs),
                    "pa": 100 * float(np.mean([r.pa for r in runs])),
                    "sr": 100 * float(np.mean([r.sr for r in runs])),
                }
            rows.append(
                {
                    "source": src,
                    "category": cat,
                    "condition": cond,
                    "label": f"{cell_label(src, cond)}" + (f" / {cat}" if cat else ""),
                    "bands": bands,
                }
            )
        out["systems"][s] = rows
    return out
