"""Robustness variants paired with their original tasks (Appendix E, ``tab:robustness_paired``).

Variants are manifest entries with ``variant`` in layout / distractor / missing and a
``base_task_id``. Distractor tasks are scored without the added part (the evaluator excludes it
from registration, matching and scoring); missing-part tasks are scored on the retained parts at
the original scale, so their PA is retained-part PA and their SR is retained-part completeness.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from aw_eval.analyses.benchmark import cell_label
from aw_eval.stats import CONDITION_ORDER, SOURCE_ORDER
from aw_eval.study.table import Study

__all__ = ["VARIANT_KINDS", "robustness"]

VARIANT_KINDS = ("layout", "distractor", "missing")


def _order_key(e) -> tuple:
    src = SOURCE_ORDER.index(e.source) if e.source in SOURCE_ORDER else len(SOURCE_ORDER)
    cond = CONDITION_ORDER.index(e.condition) if e.condition in CONDITION_ORDER else len(CONDITION_ORDER)
    return (src, e.source, cond, e.object_id, e.task_id)


def robustness(study: Study) -> dict[str, Any]:
    """Per system: one row per original task with variants (PA %, SR per cell), and per variant
    kind and source the mean PA/SR of the variants next to their paired originals."""
    variants: dict[str, dict[str, list[str]]] = {}
    for e in study.entries:
        if e.variant != "original" and e.base_task_id:
            variants.setdefault(e.base_task_id, {}).setdefault(e.variant, []).append(e.task_id)
    out: dict[str, Any] = {"kinds": list(VARIANT_KINDS), "systems": {}}
    if not variants:
        return out
    known = {e.task_id for e in study.entries}
    for s in study.systems:
        rows = []
        pooled: dict[tuple[str, str], dict[str, list[float]]] = {}
        for base in sorted((b for b in variants if b in known), key=lambda b: _order_key(study.entry(b))):
            be = study.entry(base)
            orig = study.score(s, base)
            row: dict[str, Any] = {
                "base_task_id": base,
                "source": be.source,
                "condition": be.condition,
                "label": cell_label(be.source, be.condition),
                "object_id": be.object_id,
                "original": {"pa": 100 * orig.pa, "sr": orig.sr, "status": orig.status},
            }
            for kind in VARIANT_KINDS:
                cells = []
                for tid in sorted(variants[base].get(kind, [])):
                    r = study.score(s, tid)
                    cells.append({"task_id": tid, "pa": 100 * r.pa, "sr": r.sr, "status": r.status})
                    p = pooled.setdefault((kind, be.source), {"pa": [], "sr": [], "orig_pa": [], "orig_sr": []})
                    p["pa"].append(r.pa)
                    p["sr"].append(r.sr)
                    p["orig_pa"].append(orig.pa)
                    p["orig_sr"].append(orig.sr)
                row[kind] = cells
            rows.append(row)
        summary = [
            {
                "kind": k,
                "source": src,
                "n": len(v["pa"]),
                "pa": 100 * float(np.mean(v["pa"])),
                "sr": 100 * float(np.mean(v["sr"])),
                "original_pa": 100 * float(np.mean(v["orig_pa"])),
                "original_sr": 100 * float(np.mean(v["orig_sr"])),
            }
            for (k, src), v in sorted(pooled.items())
        ]
        out["systems"][s] = {"rows": rows, "summary": summary}
    return out
