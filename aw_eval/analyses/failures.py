"""Geometric failure classes of incorrect parts (Appendix C.2, ``tab:failure_counts``).

With the saved global alignment and equivalent-part matching, every part gets the first class
that applies, in this order:

1. correct: matched part CD <= 0.01;
2. never moved: its pose never changed during the episode;
3. far displaced: centroid offset > 3 largest-part diagonals;
4. translation-dominated: centred CD <= 0.01 and offset > 0.1;
5. near-threshold: centred CD <= 0.01 and offset <= 0.1;
6. orientation-dominated: centred CD > 0.01 and offset <= 0.1;
7. mixed: anything else.

Offsets are in normalized units (the largest part's PCA box diagonal is 1); centred CD is the
part's CD after moving its centroid onto the matched target's. Fractions are of incorrect parts:
part-pooled (every incorrect part counts once) and task-pooled (per failed task, then averaged).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from aw_eval.study.model import RunScore
from aw_eval.study.table import Study

__all__ = [
    "CLASSES",
    "classify_parts",
    "translation_fractions",
    "failure_analysis",
    "far_from_assembled",
    "OFFSET_GRID",
    "CENTRED_GRID",
]

CLASSES = (
    "correct",
    "never_moved",
    "far_displaced",
    "translation_dominated",
    "near_threshold",
    "orientation_dominated",
    "mixed",
)
CORRECT_CD = 0.01
FAR_OFFSET = 3.0
OFFSET_CUTOFF = 0.1
CENTRED_CUTOFF = 0.01
OFFSET_GRID = (0.05, 0.1, 0.2)
CENTRED_GRID = (0.005, 0.01, 0.02)
TRANSLATION = CLASSES.index("translation_dominated")


def classify_parts(
    errors: np.ndarray,
    centred_cd: np.ndarray,
    offset: np.ndarray,
    moved: np.ndarray,
    *,
    correct_cd: float = CORRECT_CD,
    far: float = FAR_OFFSET,
    offset_cutoff: float = OFFSET_CUTOFF,
    centred_cutoff: float = CENTRED_CUTOFF,
) -> np.ndarray:
    """Class index (into :data:`CLASSES`) of every part; all inputs ``(P,)``."""
    e, c, o = (np.asarray(x, dtype=np.float64) for x in (errors, centred_cd, offset))
    moved = np.asarray(moved, dtype=bool)
    conditions = [
        e <= correct_cd,
        ~moved,
        o > far,
        (c <= centred_cutoff) & (o > offset_cutoff),
        (c <= centred_cutoff) & (o <= offset_cutoff),
        (c > centred_cutoff) & (o <= offset_cutoff),
    ]
    return np.select(conditions, np.arange(len(conditions)), default=len(conditions)).astype(np.int64)


def translation_fractions(classes: Sequence[np.ndarray]) -> tuple[float, float, int, int]:
    """(part-pooled %, task-pooled %, failed tasks, wrong parts) of translation-dominated parts
    among incorrect parts, over the runs whose ``classes`` hold an incorrect part."""
    wrong_total = 0
    trans_total = 0
    per_task = []
    for cl in classes:
        wrong = cl != 0
        n = int(wrong.sum())
        if n == 0:
            continue
        t = int(np.sum(cl == TRANSLATION))
        wrong_total += n
        trans_total += t
        per_task.append(t / n)
    if wrong_total == 0:
        return float("nan"), float("nan"), 0, 0
    return 100 * trans_total / wrong_total, 100 * float(np.mean(per_task)), len(per_task), wrong_total


def failure_analysis(study: Study) -> dict[str, Any]:
    """Per system: class counts of incorrect parts, the default translation fractions and the
    3x3 sensitivity grid (offset cutoff x centred-CD cutoff). Original tasks with a scored final
    state only; unscored runs are counted apart."""
    out: dict[str, Any] = {
        "classes": list(CLASSES),
        "offset_grid": list(OFFSET_GRID),
        "centred_grid": list(CENTRED_GRID),
        "systems": {},
    }
    for s in study.systems:
        runs = [study.score(s, t) for t in study.original_ids]
        scored = [r for r in runs if r.scored and r.n_parts > 0]
        default = [classify_parts(r.part_errors, r.centred_cd, r.offset, r.moved) for r in scored]
        counts = np.zeros(len(CLASSES), dtype=np.int64)
        for cl in default:
            counts += np.bincount(cl, minlength=len(CLASSES))
        part, task, n_failed, n_wrong = translation_fractions(default)
        grid = []
        for oc in OFFSET_GRID:
            row = []
            for cc in CENTRED_GRID:
                cls = [
                    classify_parts(r.part_errors, r.centred_cd, r.offset, r.moved, offset_cutoff=oc, centred_cutoff=cc)
                    for r in scored
                ]
                p, t, _, _ = translation_fractions(cls)
                row.append({"part_pooled": p, "task_pooled": t})
            grid.append(row)
        finite = [g["part_pooled"] for row in grid for g in row if np.isfinite(g["part_pooled"])]
        out["systems"][s] = {
            "failed_tasks": n_failed,
            "wrong_parts": n_wrong,
            "unscored_runs": len(runs) - len(scored),
            "class_counts": {c: int(n) for c, n in zip(CLASSES, counts, strict=True)},
            "translation_part_pooled": part,
            "translation_task_pooled": task,
            "grid": grid,
            "grid_range": [min(finite), max(finite)] if finite else None,
        }
    return out


HIGH_PA = 0.25  # a PA from which a state far from assembled gets a note on why it scores
DISPLACED_SHARE = 0.5  # a state is far from assembled when at least this share of parts is displaced


def far_from_assembled(
    r: RunScore,
    part_ids: Sequence[str],
    *,
    threshold: float = CORRECT_CD,
    sra_threshold: float = 0.02,
    offset_cutoff: float = OFFSET_CUTOFF,
) -> dict[str, Any] | None:
    """Why a final state far from assembled scores well, as data for the report's note; None
    unless the run's PA is at least ``HIGH_PA`` or its SR^a holds while at least
    ``DISPLACED_SHARE`` of its parts are displaced: their centroids more than ``offset_cutoff`` (Table
    A-11's translation cutoff, in largest-part diagonals) from their matched targets
    after the registration. A heap of parts around the object's middle is such a state: the one
    registration fits it as well as it can, and parts whose targets lie near the middle pass.

    Returns ``n_parts``, ``displaced`` (part ids), ``passed`` (per passing part: ``part``,
    ``cd`` its matched Chamfer distance, ``offset``), ``pa``, ``sr``, ``sra``, ``scd`` and the
    ``threshold``, ``sra_threshold`` and ``offset_cutoff`` used. ``part_ids``: the scored parts, in the run's order."""
    if not r.scored or not r.n_parts or r.sr or len(r.offset) != r.n_parts or len(part_ids) != r.n_parts:
        return None
    errors, offset = np.asarray(r.part_errors, dtype=np.float64), np.asarray(r.offset, dtype=np.float64)
    displaced = offset > offset_cutoff
    if displaced.mean() < DISPLACED_SHARE or not (r.pa >= HIGH_PA or r.sra):
        return None
    passing = np.flatnonzero(errors <= threshold)
    return {
        "n_parts": int(r.n_parts),
        "displaced": [part_ids[i] for i in np.flatnonzero(displaced)],
        "passed": [{"part": part_ids[i], "cd": float(errors[i]), "offset": float(offset[i])} for i in passing],
        "pa": float(r.pa),
        "sr": float(r.sr),
        "sra": float(r.sra),
        "scd": float(r.scd),
        "threshold": threshold,
        "sra_threshold": sra_threshold,
        "offset_cutoff": offset_cutoff,
    }
