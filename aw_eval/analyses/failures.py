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
    "placed_as_recorded",
    "placed_parts",
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
PULLED_GAP = 0.25  # parts placed as recorded minus PA from which the one registration was pulled off them


def placed_parts(
    meshes: Sequence[Any], poses: np.ndarray, target_poses: np.ndarray, divisor: float, threshold: float
) -> np.ndarray:
    """``(P,)`` bool: the parts that lie at their targets as placed in ``poses (P, 7)``, before
    any registration: each part's Chamfer distance to its own target part (normalized units) is
    at most ``threshold``. Decided by a bound that needs no samples: a surface point moves by at
    most its triangle's largest vertex displacement ``m`` between the two poses (the displacement
    is affine in the point), so both Chamfer terms are at most ``(m / d) ** 2``."""
    from aw.pose import poses_to_matrices

    now, target = poses_to_matrices(poses), poses_to_matrices(target_poses)
    out = np.zeros(len(meshes), dtype=bool)
    for i, m in enumerate(meshes):
        v = np.asarray(m.vertices, dtype=np.float64)
        a = v @ now[i, :3, :3].T + now[i, :3, 3]
        b = v @ target[i, :3, :3].T + target[i, :3, 3]
        worst = float(np.sqrt(((a - b) ** 2).sum(axis=1)).max()) / divisor
        out[i] = 2.0 * worst**2 <= threshold
    return out


def placed_as_recorded(
    suite_dir: str, run_dir: str, final_from: str | None, task_id: str, part_ids: Sequence[str], divisor: float
) -> tuple[list[Any], np.ndarray, np.ndarray] | None:
    """``(meshes, final poses (P, 7), target poses (P, 7))`` of a scored run's final state as
    recorded (``final_from`` says where its scoring took it), for :func:`placed_parts`; None when
    the task has no meshes (an official package) or a file cannot be read again."""
    from pathlib import Path

    from aw.formats import FormatError, read_final, read_targets, read_task, read_trajectory
    from aw.formats.suite import suite_paths
    from aw.meshes import load_task_meshes

    try:
        task_dir, targets_path = suite_paths(suite_dir, task_id)
        task, targets = read_task(task_dir), read_targets(targets_path)
        by_id = dict(zip(task.part_ids, load_task_meshes(task), strict=True))
        if final_from == "final.json":
            final = read_final(Path(run_dir) / "final.json").poses
        else:
            final = read_trajectory(Path(run_dir) / "trajectory.jsonl").final_poses()
        poses = np.array([final[p] for p in part_ids], dtype=np.float64)
        target = np.array([targets.parts[p].pose for p in part_ids], dtype=np.float64)
        return [by_id[p] for p in part_ids], poses, target
    except (FormatError, OSError, ValueError, KeyError):
        return None


DISPLACED_SHARE = 0.5  # a state is far from assembled when at least this share of parts is displaced


def far_from_assembled(
    r: RunScore,
    part_ids: Sequence[str],
    *,
    threshold: float = CORRECT_CD,
    sra_threshold: float = 0.02,
    offset_cutoff: float = OFFSET_CUTOFF,
    placed: np.ndarray | None = None,
) -> dict[str, Any] | None:
    """Why a final state far from assembled scores well, as data for the report's note; None
    unless the run's PA is at least ``HIGH_PA`` or its SR^a holds while at least
    ``DISPLACED_SHARE`` of its parts are displaced: their centroids more than ``offset_cutoff`` (Table
    A-11's translation cutoff, in largest-part diagonals) from their matched targets
    after the registration. A heap of parts around the object's middle is such a state: the one
    registration fits it as well as it can, and parts whose targets lie near the middle pass.
    ``placed (P,)``: the parts at their targets as recorded (:func:`placed_parts`); when their
    share exceeds PA by ``PULLED_GAP`` the state is partly assembled and the registration pulled
    off it by parts left away, which the card says instead (None: not known).

    Returns ``n_parts``, ``displaced`` (part ids), ``passed`` (per passing part: ``part``,
    ``cd`` its matched Chamfer distance, ``offset``), ``pa``, ``sr``, ``sra``, ``scd`` and the
    ``threshold``, ``sra_threshold`` and ``offset_cutoff`` used. ``part_ids``: the scored parts, in the run's order."""
    if not r.scored or not r.n_parts or r.sr or len(r.offset) != r.n_parts or len(part_ids) != r.n_parts:
        return None
    errors, offset = np.asarray(r.part_errors, dtype=np.float64), np.asarray(r.offset, dtype=np.float64)
    displaced = offset > offset_cutoff
    if displaced.mean() < DISPLACED_SHARE or not (r.pa >= HIGH_PA or r.sra):
        return None
    if placed is not None and len(placed) == r.n_parts and placed.mean() - r.pa >= PULLED_GAP:
        return None
    passing = np.flatnonzero(errors <= threshold)
    return {
        "n_parts": int(r.n_parts),
        "displaced": [part_ids[int(i)] for i in np.flatnonzero(displaced)],
        "passed": [{"part": part_ids[int(i)], "cd": float(errors[i]), "offset": float(offset[i])} for i in passing],
        "pa": float(r.pa),
        "sr": float(r.sr),
        "sra": float(r.sra),
        "scd": float(r.scd),
        "threshold": threshold,
        "sra_threshold": sra_threshold,
        "offset_cutoff": offset_cutoff,
    }
