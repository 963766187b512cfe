"""Results per (source, condition, category) (``tab:ikea_categories`` for every source)."""

from __future__ import annotations

from typing import Any

import numpy as np

from aw_eval.analyses.benchmark import cell_label
from aw_eval.study.table import Study

__all__ = ["category_results"]


def category_results(study: Study) -> dict[str, Any]:
    """Per system and category: n, PA/SR/SR^a (percent, all attempts), SCD x1000 (scored only)."""
    d = study.design
    out: dict[str, Any] = {"systems": {}}
    if d is None:
        return out
    groups: dict[tuple[str, str, str], list[str]] = {}
    for t in d.tasks:
        groups.setdefault((t.source, t.condition, t.category or "-"), []).append(t.task_id)
    for s in study.systems:
        rows = []
        for (src, cond, cat), ids in groups.items():
            runs = [study.score(s, i) for i in ids]
            scd = [r.scd for r in runs if r.scored]
            rows.append(
                {
                    "source": src,
                    "condition": cond,
                    "category": cat,
                    "label": cell_label(src, cond),
                    "n": len(runs),
                    "pa": 100 * float(np.mean([r.pa for r in runs])),
                    "sr": 100 * float(np.mean([r.sr for r in runs])),
                    "sra": 100 * float(np.mean([r.sra for r in runs])),
                    "scd": 1000 * float(np.mean(scd)) if scd else None,
                }
            )
        out["systems"][s] = rows
    return out
