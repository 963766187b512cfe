"""SCD concentration: the share of summed SCD held by the largest ``k = ceil(0.05 N)`` values
(Appendix B.2, ``tab:scd_tail``). Over scored attempts; SCD x1000."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from aw_eval.analyses.benchmark import cell_label
from aw_eval.study.table import Study

__all__ = ["TAIL_FRACTION", "scd_concentration", "scd_tail"]

TAIL_FRACTION = 0.05


def scd_concentration(scd, fraction: float = TAIL_FRACTION) -> dict[str, Any] | None:
    """N, mean, median, k, contribution (%) of the top k and the mean without them (x1000).

    ``scd: (N,)`` raw values (NaN entries are ignored); None when nothing is left."""
    v = np.asarray(scd, dtype=np.float64)
    v = v[~np.isnan(v)]
    n = len(v)
    if n == 0:
        return None
    k = math.ceil(fraction * n)
    order = np.sort(v)[::-1]
    total = float(v.sum())
    rest = order[k:]
    return {
        "n": n,
        "mean": 1000 * float(v.mean()),
        "median": 1000 * float(np.median(v)),
        "k": k,
        "contribution": 100 * float(order[:k].sum()) / total if total > 0 else float("nan"),
        "remaining_mean": 1000 * float(rest.mean()) if len(rest) else float("nan"),
    }


def scd_tail(study: Study) -> dict[str, Any]:
    """Per system and (source, condition) cell, and per (source, category, condition)."""
    out: dict[str, Any] = {"systems": {}}
    d = study.design
    if d is None:
        return out
    for s in study.systems:
        rows = []
        groups: dict[tuple[str, str, str], list[str]] = {}
        for t in d.tasks:
            groups.setdefault((t.source, t.condition, ""), []).append(t.task_id)
            if t.category:
                groups.setdefault((t.source, t.condition, t.category), []).append(t.task_id)
        for (src, cond, cat), ids in groups.items():
            runs = [study.score(s, i) for i in ids]
            stats = scd_concentration([r.scd for r in runs])
            if stats is None:
                continue
            # how many of the tail runs never moved a part at all
            scored = [r for r in runs if r.scored]
            tail = sorted(scored, key=lambda r: -r.scd)[: stats["k"]]
            stats["tail_never_moved"] = int(sum(1 for r in tail if r.moved.size and not r.moved.any()))
            rows.append(
                {
                    "source": src,
                    "condition": cond,
                    "category": cat,
                    "label": cell_label(src, cond) + (f" / {cat}" if cat else ""),
                    **stats,
                }
            )
        out["systems"][s] = rows
    return out
