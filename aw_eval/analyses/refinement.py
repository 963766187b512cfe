"""The bidirectional refinement study (the paper's Table "Bidirectional refinement" and its
appendix): the four arms under the fracture protocol (:mod:`aw_eval.fracture`: shared samples,
anchor-aligned), and paired per-object changes.

Reads ``RUNS/refinement_study.json`` (written by ``aw-run --refinement-study``) for the arms'
systems. Each run's final state is its trajectory's last recorded state (``final.json`` when the
trajectory cannot be read); a run whose ``run.json`` says it did not finish counts as failed. The table averages over the tasks where every arm finished (the
matched comparison); failed runs are listed per arm. Paired changes compare one arm with another
task by task: PA improved / degraded / unchanged, and shape CD likewise (lower is better), a
difference within ``TOLERANCE`` counting as unchanged.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from aw.formats import FormatError, read_final, read_manifest, read_run_info, read_targets, read_task, read_trajectory
from aw.formats.suite import suite_paths
from aw.meshes import load_task_meshes
from aw.prepare.official_protocol import fracture_samples
from aw.refine.runs import fracture_identity
from aw.runner.refinement_study import ARMS, STUDY_FILE
from aw_eval.fracture import SEED, fracture_metrics_from_samples

__all__ = ["ARM_LABELS", "PAIRS", "TOLERANCE", "paired_changes", "refinement_study"]

TOLERANCE = 1e-8
ARM_LABELS = {
    "agent": "Agent",
    "refiner": "Refiner",
    "agent_refiner": "Agent -> Refiner",
    "refiner_agent": "Refiner -> Agent",
}
# (arm, baseline, metric): the paper's paired comparisons
PAIRS = (
    ("agent_refiner", "refiner", "pa"),
    ("agent_refiner", "agent", "pa"),
    ("refiner_agent", "refiner", "pa"),
    ("refiner_agent", "refiner", "cd"),
)
SCATTER = (("agent", "agent_refiner"), ("refiner", "refiner_agent"))


def _final_poses(run_dir: Path) -> dict[str, list[float]] | None:
    try:
        return read_trajectory(run_dir / "trajectory.jsonl").final_poses()
    except FormatError:
        pass
    try:
        return dict(read_final(run_dir / "final.json").poses)
    except FormatError:
        return None


def paired_changes(
    after: np.ndarray, before: np.ndarray, higher_is_better: bool, tol: float = TOLERANCE
) -> dict[str, int]:
    """Counts of tasks where ``after`` improved on, degraded from, or equals ``before`` (within ``tol``)."""
    d = np.asarray(after, float) - np.asarray(before, float)
    if not higher_is_better:
        d = -d
    return {
        "improved": int((d > tol).sum()),
        "degraded": int((d < -tol).sum()),
        "unchanged": int((np.abs(d) <= tol).sum()),
    }


def refinement_study(suite_dir: str | Path, runs_dir: str | Path) -> dict[str, Any] | None:
    """The study's document (None when ``RUNS/refinement_study.json`` is absent)."""
    suite_dir, runs_dir = Path(suite_dir), Path(runs_dir)
    path = runs_dir / STUDY_FILE
    if not path.is_file():
        return None
    try:
        study = json.loads(path.read_text())
        systems = {a["arm"]: a["system"] for a in study["arms"]}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        return {"error": f"{path}: unreadable ({exc})"}
    missing = [a for a in ARMS if a not in systems]
    if missing:
        return {"error": f"{path}: arms missing: {', '.join(missing)}"}
    rows: dict[str, dict[str, Any]] = {}
    failures: dict[str, dict[str, str]] = {a: {} for a in ARMS}
    chosen = set(study.get("tasks") or [])  # the tasks the study ran (all originals if it does not say)
    for entry in read_manifest(suite_dir).tasks:
        if entry.variant != "original" or (chosen and entry.task_id not in chosen):
            continue
        tid = entry.task_id
        task_dir, targets_path = suite_paths(suite_dir, tid)
        try:
            task = read_task(task_dir)
            targets = read_targets(targets_path)
        except FormatError as exc:
            for a in ARMS:
                failures[a][tid] = f"task unreadable: {exc}"
            continue
        ids = sorted(task.part_ids)  # the protocol's part order
        order = [task.part_ids.index(p) for p in ids]
        loaded = load_task_meshes(task)
        meshes = [(np.asarray(loaded[i].vertices, dtype=np.float64), np.asarray(loaded[i].faces)) for i in order]
        dataset, sample_id = fracture_identity(suite_dir, task)
        samples = fracture_samples(meshes, ids, dataset, sample_id, SEED)
        target = np.array([targets.parts[p].pose for p in ids])
        divisor, divisor_from = _divisor(suite_dir, tid, meshes, target, targets.scale)
        row: dict[str, Any] = {"divisor": divisor, "divisor_from": divisor_from, "arms": {}}
        for arm in ARMS:
            run_dir = runs_dir / systems[arm] / tid
            if (run_dir / "run.json").is_file():  # optional, as for aw-score; when present, it says how the run ended
                try:
                    info = read_run_info(run_dir / "run.json")
                except FormatError as exc:
                    failures[arm][tid] = str(exc)
                    continue
                if info.ended != "finished":
                    failures[arm][tid] = (
                        f"{info.ended}: {(info.error or '').strip().splitlines()[0] if info.error else ''}"
                    )
                    continue
            poses = _final_poses(run_dir)
            if poses is None or set(poses) != set(ids):
                failures[arm][tid] = "no run" if not run_dir.is_dir() else "no readable final state"
                continue
            m = fracture_metrics_from_samples(samples, np.array([poses[p] for p in ids]), target, divisor)
            row["arms"][arm] = {"re": m.re, "te": m.te, "pa": m.pa, "cd": m.cd, "anchor": ids[m.anchor]}
        rows[tid] = row
    matched = [t for t, r in rows.items() if all(a in r["arms"] for a in ARMS)]

    def values(arm: str, metric: str) -> np.ndarray:
        return np.array([rows[t]["arms"][arm][metric] for t in matched], dtype=float)

    table = {}
    for arm in ARMS:
        table[arm] = {
            "system": systems[arm],
            "n": len(matched),
            "failed": len(failures[arm]),
            **({k: float(values(arm, k).mean()) for k in ("re", "te", "pa", "cd")} if matched else {}),
        }
    pairs = []
    for arm, base, metric in PAIRS:
        counts = paired_changes(values(arm, metric), values(base, metric), metric == "pa") if matched else {}
        pairs.append({"arm": arm, "baseline": base, "metric": metric, **counts})
    scatter = [
        {"before": b, "after": a, "tasks": matched, "x": values(b, "cd").tolist(), "y": values(a, "cd").tolist()}
        for b, a in SCATTER
    ]
    return {
        "study_file": str(path),
        "agent": study.get("agent"),
        "refiner": study.get("refiner"),
        "arms": {a: {"system": systems[a], "label": ARM_LABELS[a]} for a in ARMS},
        "tasks": len(rows),
        "matched": matched,
        "table": table,
        "pairs": pairs,
        "scatter": scatter,
        "tolerance": TOLERANCE,
        "failures": failures,
        "per_task": rows,
    }


def _divisor(suite_dir: Path, task_id: str, meshes, target: np.ndarray, scale: float) -> tuple[float, str]:
    """The fracture protocol's divisor: ``fracture_divisor`` from ``eval_points/<task>.npz``
    (official preparation), else ``max(s, e)``: ``s`` the targets' scale (source -> task), ``e``
    the largest axis-aligned extent of any part posed at its target (the source extent measured
    in the assembled frame: an approximation of ``max(1, e_source) * s``)."""
    path = suite_dir / "eval_points" / f"{task_id}.npz"
    if path.is_file():
        with np.load(path, allow_pickle=False) as npz:
            if "fracture_divisor" in npz.files:
                return float(npz["fracture_divisor"]), "eval_points"
    from aw.prepare.official_protocol import moved

    extent = max(float(np.ptp(moved(v, p), axis=0).max()) for (v, _), p in zip(meshes, target))
    return max(float(scale), extent), "targets scale and assembled extent"
