"""Paired reference effects: image-conditioned minus no-reference results on the same objects
(Appendix B, ``tab:analysis_reference``, ``fig:reference_analysis``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aw_eval.stats.bootstrap import DEFAULT_DRAWS, paired_object_bootstrap
from aw_eval.stats.design import Design

__all__ = ["paired_objects", "ReferenceEffect", "reference_effects"]

# Changes smaller than this are ties (PA is a ratio of small integers).
_TIE = 1e-12


def paired_objects(
    design: Design, source: str, treated: str = "image", control: str = "none"
) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Objects of ``source`` that have both conditions: ``(object_ids, treated (O, T), control (O, T))``
    where row ``o`` averages the object's tasks of that condition."""
    ids: list[str] = []
    rows_t, rows_c = [], []
    for oi, (s, oid) in enumerate(design.objects):
        if s != source:
            continue
        tmask = np.array([t.condition == treated for t in design.tasks]) & (design.task_object == oi)
        cmask = np.array([t.condition == control for t in design.tasks]) & (design.task_object == oi)
        if tmask.any() and cmask.any():
            ids.append(oid)
            rows_t.append(tmask / tmask.sum())
            rows_c.append(cmask / cmask.sum())
    n = design.n_tasks
    return ids, np.array(rows_t).reshape(-1, n), np.array(rows_c).reshape(-1, n)


@dataclass(frozen=True)
class ReferenceEffect:
    """One system's paired effect on one metric: mean difference, interval, up/down counts
    (objects that improve or worsen; ties excluded)."""

    system: int
    metric: str
    n_objects: int
    diff: float
    ci: tuple[float, float]
    up: int
    down: int


def reference_effects(
    design: Design,
    metrics: dict[str, np.ndarray],
    source: str = "partnet",
    *,
    treated: str = "image",
    control: str = "none",
    n_draws: int = DEFAULT_DRAWS,
    seed: int = 0,
    level: float = 0.95,
) -> list[ReferenceEffect]:
    """Per system and metric (``(S, T)`` values) the paired treated-minus-control effect on the
    objects of ``source`` with both conditions. Empty when there are no such objects.
    All systems and metrics share the same object resamples (same seed)."""
    ids, mt, mc = paired_objects(design, source, treated, control)
    if not ids:
        return []
    out = []
    for name, values in metrics.items():
        v = np.asarray(values, dtype=np.float64)
        diffs = v @ mt.T - v @ mc.T  # (S, O)
        mean, ci = paired_object_bootstrap(diffs, n_draws=n_draws, seed=seed, level=level)
        for s in range(v.shape[0]):
            out.append(
                ReferenceEffect(
                    s,
                    name,
                    len(ids),
                    float(mean[s]),
                    (float(ci[0, s]), float(ci[1, s])),
                    int(np.sum(diffs[s] > _TIE)),
                    int(np.sum(diffs[s] < -_TIE)),
                )
            )
    return out
