"""Within-object part-size ratios per source (Appendix B.2, ``tab:part_scale``): the largest
over the smallest part PCA bounding-box diagonal (unique mesh vertices), one value per object."""

from __future__ import annotations

from typing import Any

import numpy as np

from aw_eval.stats import ordered_sources
from aw_eval.study.table import Study

__all__ = ["ratio_summary", "part_scale"]


def ratio_summary(ratios) -> dict[str, Any]:
    """N, median, interquartile range, 90th percentile and % above 10 of ``ratios: (N,)``."""
    r = np.asarray(ratios, dtype=np.float64)
    if len(r) == 0:
        return {"n": 0, "median": None, "q1": None, "q3": None, "p90": None, "above_10": None}
    q1, med, q3, p90 = np.percentile(r, [25, 50, 75, 90])
    return {
        "n": int(len(r)),
        "median": float(med),
        "q1": float(q1),
        "q3": float(q3),
        "p90": float(p90),
        "above_10": 100 * float(np.mean(r > 10)),
    }


def part_scale(study: Study) -> dict[str, Any]:
    """Per source (original tasks, each object once)."""
    per_source: dict[str, dict[str, float]] = {}
    for e in study.entries:
        if e.variant != "original":
            continue
        f = study.facts.get(e.task_id)
        if f is None or not np.isfinite(f.part_size_ratio):
            continue
        per_source.setdefault(e.source, {}).setdefault(e.object_id, f.part_size_ratio)
    return {s: ratio_summary(list(per_source[s].values())) for s in ordered_sources(per_source)}
