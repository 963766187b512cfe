"""Interaction dynamics (Appendix C.1; ``fig:behavior`` (a-c), ``tab:interaction_stages``).

Each evaluation's interval from its first to its last environment call is cut into ten
equal-width bins. Activity shares are computed within each active evaluation-bin (calls of a kind
over all calls in the bin; grouping and episode control stay in the denominator) and averaged
over evaluations with the benchmark weights (eq. 3), renormalized over the evaluations active in
the bin; empty bins are omitted.

Manipulation magnitudes: every pose-changing manipulation is one operation; its magnitude is the
largest over the affected parts (group edits count by their largest part). Operations whose
rotation is below 0.5 degrees enter the translation summary (centroid displacement over the
largest-part diagonal), the others the rotation summary (degrees). Per bin (or third), the
median within each evaluation, then the weighted median across evaluations that have such
operations; missing operations are never counted as zero.

Revisit: per evaluation, the fraction of edits that touch a part an earlier edit touched; the
table reports its weighted median over evaluations with at least one edit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from aw_eval.stats import weighted_median
from aw_eval.study.episode import KIND_NAMES, ROTATION_CUTOFF_DEG
from aw_eval.study.table import Study

__all__ = ["N_BINS", "EvalCalls", "call_positions", "activity_shares", "magnitude_summary", "stage_summary", "dynamics"]

N_BINS = 10


@dataclass(frozen=True)
class EvalCalls:
    """One evaluation's call log: ``call_t (C,)``, ``call_kind (C,)``, edits (``E``) and weight."""

    call_t: np.ndarray
    call_kind: np.ndarray
    edit_call: np.ndarray
    edit_translation: np.ndarray
    edit_rotation_deg: np.ndarray
    edit_revisit: np.ndarray
    weight: float


def call_positions(call_t: np.ndarray) -> np.ndarray:
    """Normalized position in [0, 1] of every call between the first and the last call
    (all 0 when they coincide)."""
    t = np.asarray(call_t, dtype=np.float64)
    if len(t) == 0:
        return t
    t0, t1 = t.min(), t.max()
    if t1 <= t0:
        return np.zeros_like(t)
    return (t - t0) / (t1 - t0)


def _bins(pos: np.ndarray, n_bins: int) -> np.ndarray:
    return np.minimum((pos * n_bins).astype(np.int64), n_bins - 1)


def activity_shares(evals: Sequence[EvalCalls], n_bins: int = N_BINS) -> tuple[np.ndarray, np.ndarray]:
    """``(n_bins, 4)`` weighted mean call shares per kind (NaN rows for bins no evaluation uses)
    and ``(n_bins,)`` number of active evaluations per bin."""
    n_kinds = len(KIND_NAMES)
    num = np.zeros((n_bins, n_kinds))
    den = np.zeros(n_bins)
    active = np.zeros(n_bins, dtype=np.int64)
    for ev in evals:
        if len(ev.call_t) == 0:
            continue
        b = _bins(call_positions(ev.call_t), n_bins)
        counts = np.zeros((n_bins, n_kinds))
        np.add.at(counts, (b, ev.call_kind.astype(np.int64)), 1.0)
        tot = counts.sum(axis=1)
        on = tot > 0
        num[on] += ev.weight * counts[on] / tot[on, None]
        den[on] += ev.weight
        active += on
    with np.errstate(invalid="ignore", divide="ignore"):
        shares = np.where(den[:, None] > 0, num / np.where(den > 0, den, 1)[:, None], np.nan)
    return shares, active


def _edit_groups(ev: EvalCalls, group_of_call: np.ndarray, n_groups: int) -> list[tuple[list[float], list[float]]]:
    """Per group: (translation magnitudes, rotation magnitudes) of the edits whose call is in it."""
    out: list[tuple[list[float], list[float]]] = [([], []) for _ in range(n_groups)]
    for k, ci in enumerate(ev.edit_call):
        g = int(group_of_call[ci])
        if g < 0:
            continue
        if ev.edit_rotation_deg[k] < ROTATION_CUTOFF_DEG:
            out[g][0].append(float(ev.edit_translation[k]))
        else:
            out[g][1].append(float(ev.edit_rotation_deg[k]))
    return out


def _summaries(evals: Sequence[EvalCalls], groups: list[np.ndarray], n_groups: int) -> dict[str, list[Any]]:
    """Weighted medians across evaluations of per-evaluation medians, per group."""
    trans: list[list[tuple[float, float]]] = [[] for _ in range(n_groups)]
    rot: list[list[tuple[float, float]]] = [[] for _ in range(n_groups)]
    for ev, g in zip(evals, groups, strict=True):
        for gi, (t, r) in enumerate(_edit_groups(ev, g, n_groups)):
            if t:
                trans[gi].append((float(np.median(t)), ev.weight))
            if r:
                rot[gi].append((float(np.median(r)), ev.weight))

    def wm(items):
        return weighted_median([v for v, _ in items], [w for _, w in items]) if items else None

    return {
        "translation": [wm(x) for x in trans],
        "rotation_deg": [wm(x) for x in rot],
        "n_translation": [len(x) for x in trans],
        "n_rotation": [len(x) for x in rot],
    }


def magnitude_summary(evals: Sequence[EvalCalls], n_bins: int = N_BINS) -> dict[str, list[Any]]:
    """Per bin: weighted median of per-evaluation median translation and rotation magnitudes."""
    groups = [_bins(call_positions(ev.call_t), n_bins) for ev in evals]
    return _summaries(evals, groups, n_bins)


def stage_summary(evals: Sequence[EvalCalls]) -> dict[str, Any]:
    """Early (first third) and late (last third) magnitudes, and the revisit fraction."""
    groups = []
    for ev in evals:
        pos = call_positions(ev.call_t)
        g = np.full(len(pos), -1, dtype=np.int64)
        g[pos <= 1 / 3] = 0
        g[pos >= 2 / 3] = 1
        groups.append(g)
    s = _summaries(evals, groups, 2)
    rev = [(float(np.mean(ev.edit_revisit)), ev.weight) for ev in evals if len(ev.edit_revisit)]
    return {
        "translation_early": s["translation"][0],
        "translation_late": s["translation"][1],
        "rotation_early": s["rotation_deg"][0],
        "rotation_late": s["rotation_deg"][1],
        "revisit": 100 * weighted_median([v for v, _ in rev], [w for _, w in rev]) if rev else None,
        "n_evaluations": sum(1 for ev in evals if len(ev.call_t)),
    }


def _evals(study: Study, system: str, task_ids: Sequence[str], weights: np.ndarray) -> list[EvalCalls]:
    out = []
    for tid, w in zip(task_ids, weights, strict=True):
        r = study.score(system, tid)
        if not r.scored or len(r.call_t) == 0:
            continue
        out.append(
            EvalCalls(
                r.call_t, r.call_kind, r.edit_call, r.edit_translation, r.edit_rotation_deg, r.edit_revisit, float(w)
            )
        )
    return out


def dynamics(study: Study, n_bins: int = N_BINS) -> dict[str, Any]:
    """Per system: activity shares and magnitudes per bin, and early/late stages (all evaluations,
    and split by final success)."""
    d = study.design
    out: dict[str, Any] = {"n_bins": n_bins, "kinds": list(KIND_NAMES), "systems": {}}
    if d is None:
        return out
    for s in study.systems:
        evals = _evals(study, s, d.task_ids, d.weights)
        shares, active = activity_shares(evals, n_bins)
        sr = {t: study.score(s, t).sr for t in d.task_ids}
        ok_ids = [t for t in d.task_ids if sr[t] == 1.0]
        bad_ids = [t for t in d.task_ids if sr[t] != 1.0]
        widx = dict(zip(d.task_ids, d.weights, strict=True))
        out["systems"][s] = {
            "shares": [[None if np.isnan(x) else float(x) for x in row] for row in shares],
            "active": active.tolist(),
            "magnitudes": magnitude_summary(evals, n_bins),
            "stages": stage_summary(evals),
            "stages_successful": stage_summary(_evals(study, s, ok_ids, np.array([widx[t] for t in ok_ids]))),
            "stages_failed": stage_summary(_evals(study, s, bad_ids, np.array([widx[t] for t in bad_ids]))),
        }
    return out
