"""Bootstrap intervals, paired system differences with Holm-corrected randomization tests, and
paired reference effects (Appendix B.1; ``tab:analysis_overview``, ``tab:analysis_paired``,
``tab:analysis_reference``, ``fig:reference_analysis``)."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from aw_eval.stats import (
    DEFAULT_DRAWS,
    DEFAULT_PERMUTATIONS,
    draw_weights,
    object_counts,
    pairwise_tests,
    percentile_interval,
    reference_effects,
    smallest_pvalue,
)
from aw_eval.study.table import Study

__all__ = ["system_order", "uncertainty"]

TEST_METRICS = ("sr", "pa")


def system_order(study: Study) -> list[int]:
    """System indices by Overall SR, then PA, descending (ties by name): the tables' row order."""
    d = study.design
    if d is None:
        return list(range(len(study.systems)))
    sr = d.weights @ study.values("sr").T
    pa = d.weights @ study.values("pa").T
    return sorted(range(len(study.systems)), key=lambda i: (-round(sr[i], 12), -round(pa[i], 12), study.systems[i]))


def uncertainty(
    study: Study,
    *,
    n_draws: int = DEFAULT_DRAWS,
    n_permutations: int = DEFAULT_PERMUTATIONS,
    seed: int = 0,
    level: float = 0.95,
) -> dict[str, Any]:
    """Overview intervals, all pairwise comparisons and reference effects, in percent.

    The bootstrap draws are made once (seed ``seed``) and shared by every system, metric and
    paired difference; randomization uses seed ``seed + 1``, reference effects ``seed + 2``.
    """
    d = study.design
    out: dict[str, Any] = {
        "n_draws": n_draws,
        "n_permutations": n_permutations,
        "seed": seed,
        "level": level,
        "overview": {},
        "pairs": [],
        "reference": [],
    }
    if d is None:
        return out
    order = system_order(study)
    out["order"] = [study.systems[i] for i in order]
    metrics = {m: study.values(m) for m in TEST_METRICS}
    w = draw_weights(d, object_counts(d, n_draws, np.random.default_rng(seed)))
    for m, v in metrics.items():
        draws = w @ v.T
        ci = percentile_interval(draws, level)
        point = d.weights @ v.T
        for i, s in enumerate(study.systems):
            out["overview"].setdefault(s, {})[m] = {
                "value": 100 * float(point[i]),
                "ci": [100 * float(ci[0, i]), 100 * float(ci[1, i])],
            }
    pairs = [(order[i], order[j]) for i, j in itertools.combinations(range(len(order)), 2)]
    if pairs:
        tests = pairwise_tests(d, metrics, w, pairs=pairs, n_permutations=n_permutations, seed=seed + 1, level=level)
        by = {(t.a, t.b, t.metric): t for t in tests}
        out["family_size"] = len(tests)
        # what the study can show at all: the smallest p_Holm any data could give (the best p times
        # the family size); above 1 - level, no difference can be declared however large
        out["n_objects"] = len(d.objects)
        out["min_p_holm"] = min(1.0, len(tests) * smallest_pvalue(len(d.objects), n_permutations))
        for a, b in pairs:
            row: dict[str, Any] = {"a": study.systems[a], "b": study.systems[b]}
            for m in TEST_METRICS:
                t = by[(a, b, m)]
                row[m] = {"diff": 100 * t.diff, "ci": [100 * t.ci[0], 100 * t.ci[1]], "p": t.p, "p_holm": t.p_holm}
            out["pairs"].append(row)
    for source in d.sources:
        conds = {c for s, c in d.cells if s == source}
        if not {"none", "image"} <= conds:
            continue
        effects = reference_effects(
            d, {"pa": metrics["pa"], "sr": metrics["sr"]}, source, n_draws=n_draws, seed=seed + 2, level=level
        )
        rows: dict[str, dict[str, Any]] = {}
        for e in effects:
            r = rows.setdefault(
                study.systems[e.system], {"system": study.systems[e.system], "source": source, "n_objects": e.n_objects}
            )
            r[e.metric] = {"diff": 100 * e.diff, "ci": [100 * e.ci[0], 100 * e.ci[1]], "up": e.up, "down": e.down}
        out["reference"] += [rows[study.systems[i]] for i in order if study.systems[i] in rows]
    return out
