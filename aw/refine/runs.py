"""Refining a suite's tasks into run directories that ``aw-score`` reads like any system's.

For each task: the request is built from the task's public files (part meshes, their shared
samples), the start state is the task's layout or a given poses file (a run's ``final.json``),
the refiner runs in a child process, and ``RUNS/<system>/<task_id>/`` gets ``trajectory.jsonl``
(the start state in the header, one ``refine`` call carrying the refined poses, the end line),
``final.json`` and ``run.json`` (``extra.refiner``, ``extra.initial_poses``, and
``extra.returned_start``: whether the answer equals the start within
:data:`aw.refine.base.SAME_AS_START`). A refiner that
fails or answers wrongly leaves the start state as the run's final state and ``ended:
"error"`` with the one-line reason; the other tasks go on.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from aw.formats import (
    EndReason,
    FinalState,
    FormatError,
    RunInfo,
    Task,
    TrajectoryCall,
    TrajectoryEnd,
    TrajectoryHeader,
    TrajectoryWriter,
    read_manifest,
    read_task,
    write_final,
    write_run_info,
)
from aw.formats.poses import initial_poses_file, read_initial_poses
from aw.formats.run import ExistingRuns, existing_runs
from aw.formats.suite import suite_paths
from aw.refine.base import RefineRequest, RefinerError, identity_poses, returned_start
from aw.refine.plugins import RefinerSpec, run_refiner

__all__ = ["RefineConfig", "build_request", "fracture_identity", "refine_suite", "refine_task"]

DEFAULT_TIMEOUT_S = 300.0


def fracture_identity(suite_dir: str | Path | None, task: Task) -> tuple[str, str]:
    """``(dataset, sample id)`` naming the shared samples' random streams: those the official
    preparation stored in ``SUITE/eval_points/<task>.npz`` (only these two names are read), else
    the task's ``dataset`` and ``object_id``."""
    if suite_dir is not None:
        path = Path(suite_dir) / "eval_points" / f"{task.task_id}.npz"
        if path.is_file():
            try:
                with np.load(path, allow_pickle=False) as npz:
                    if "dataset" in npz.files and "sample_id" in npz.files:
                        return str(npz["dataset"]), str(npz["sample_id"])
            except (OSError, ValueError) as exc:
                raise FormatError(path, f"cannot be read as .npz ({exc})") from None
    return task.dataset, task.object_id


def build_request(
    task: Task,
    suite_dir: str | Path | None,
    initial: dict[str, list[float]] | None,
    *,
    seed: int = 42,
    steps: int = 20,
    options: dict[str, Any] | None = None,
) -> RefineRequest:
    """The request for ``task`` (public files only), starting from ``initial`` (part id -> pose)
    or the layout."""
    from aw.meshes import load_task_meshes
    from aw.prepare.official_protocol import fracture_samples

    meshes = [(np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces)) for m in load_task_meshes(task)]
    dataset, sample_id = fracture_identity(suite_dir, task)
    points = fracture_samples(meshes, task.part_ids, dataset, sample_id, seed)
    start = identity_poses(len(task.parts)) if initial is None else np.array([initial[p] for p in task.part_ids], float)
    return RefineRequest(
        task.task_id,
        task.part_ids,
        points,
        meshes,
        [str(task.mesh_path(p).resolve()) for p in task.part_ids],
        start,
        initial is not None,
        seed,
        steps,
        dict(options or {}),
    )


def _utc() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def refine_task(
    spec: RefinerSpec,
    task: Task,
    suite_dir: str | Path | None,
    run_dir: Path,
    system: str,
    *,
    start_file: Path | None = None,
    timeout_s: float = DEFAULT_TIMEOUT_S,
    seed: int = 42,
    steps: int = 20,
    options: dict[str, Any] | None = None,
) -> RunInfo:
    """Refine one task into ``run_dir`` (replaced); returns its ``run.json`` (also written)."""
    if run_dir.exists():
        shutil.rmtree(run_dir)
    run_dir.mkdir(parents=True)
    started = _utc()
    t0 = time.monotonic()
    extra: dict[str, Any] = {"refiner": spec.name, "timeout_seconds": timeout_s, "seed": seed, "steps": steps}
    if spec.command is not None:
        extra["refiner_command"] = list(spec.command)
    if start_file is not None:
        extra["initial_poses"] = str(start_file.resolve())
    error = None
    initial = read_initial_poses(start_file, task.task_id, task.part_ids) if start_file is not None else None
    request = build_request(task, suite_dir, initial, seed=seed, steps=steps, options=options)
    start = {p: [float(v) for v in q] for p, q in zip(task.part_ids, request.initial_poses, strict=True)}
    final = start
    try:
        poses = run_refiner(spec, request, run_dir / "refine", timeout_s)
        final = {p: [float(v) for v in q] for p, q in zip(task.part_ids, poses, strict=True)}
        extra["returned_start"] = returned_start(request.initial_poses, poses)
    except RefinerError as exc:
        error = str(exc)
    seconds = time.monotonic() - t0
    header = TrajectoryHeader(
        task_id=task.task_id,
        system=system,
        started_at=started,
        part_ids=task.part_ids,
        initial_poses=start,
        initial_poses_from=str(start_file.resolve()) if start_file is not None else None,
    )
    writer = TrajectoryWriter(run_dir / "trajectory.jsonl", header)
    changed = [p for p in task.part_ids if final[p] != start[p]]
    writer.call(
        TrajectoryCall(
            seq=1,
            t=round(seconds, 6),
            server_t=round(seconds, 6),
            tool="refine",
            args={"refiner": spec.name},
            ok=error is None,
            error=error,
            changed=changed,
            poses=final if changed else None,
        )
    )
    reason: EndReason = "finished" if error is None else "error"
    writer.end(
        TrajectoryEnd(reason=reason, t=round(seconds, 6), server_t=round(seconds, 6), message=error or "", poses=final)
    )
    write_final(run_dir / "final.json", FinalState(task_id=task.task_id, reason=reason, poses=final))
    info = RunInfo(
        system=system,
        task_id=task.task_id,
        agent=spec.name,
        started_at=started,
        wall_seconds=round(seconds, 3),
        mcp_calls=0,
        ended="finished" if error is None else "error",
        error=error,
        extra=extra,
    )
    write_run_info(run_dir / "run.json", info)
    return info


@dataclass
class RefineConfig:
    """A refiner over a suite: ``start_from`` is a directory of start states (a system's runs,
    ``<task_id>/final.json``, or ``<task_id>.json`` poses files), None for the tasks' layouts."""

    suite_dir: Path
    out_dir: Path
    system: str
    spec: RefinerSpec
    start_from: Path | None = None
    tasks: list[str] | None = None
    timeout_s: float = DEFAULT_TIMEOUT_S
    seed: int = 42
    steps: int = 20
    options: dict[str, Any] = field(default_factory=dict)
    overwrite: bool = False
    keep_failed: bool = False  # keep runs that failed (default: a rerun retries them)
    jobs: int = 1
    progress: bool = False


def refine_suite(
    cfg: RefineConfig, on_done: Callable[[RunInfo], None] | None = None, log: Callable[[str], None] | None = None
) -> tuple[list[RunInfo], ExistingRuns]:
    """Refine every task (or ``cfg.tasks``) of the suite; ``(run infos, what was done with the
    runs already there)``. Without ``overwrite``, tasks with a finished run are skipped and runs
    that failed are retried (said through ``log``), or kept with ``keep_failed``; a task whose
    start state is missing under ``start_from`` is recorded as an error run."""
    from concurrent.futures import ThreadPoolExecutor

    try:
        ids = read_manifest(cfg.suite_dir).select(cfg.tasks)
    except ValueError as exc:
        raise RefinerError(str(exc)) from None
    if cfg.overwrite:
        existing = ExistingRuns(todo=list(ids))
    else:
        existing = existing_runs({t: cfg.out_dir / cfg.system / t for t in ids}, cfg.keep_failed)
        if log is not None and existing.retry:
            log(existing.retry_line())
    todo = [t for t in ids if t not in set(existing.kept)]
    bar = None
    if cfg.progress:
        from aw.progress import progress

        bar = progress(len(todo), cfg.system, "task")

    def one(tid: str) -> RunInfo:
        run_dir = cfg.out_dir / cfg.system / tid
        start_file = None
        if cfg.start_from is not None:
            start_file = initial_poses_file(cfg.start_from, tid)
            if start_file is None:
                return _failed(
                    cfg,
                    run_dir,
                    tid,
                    f"no start state for {tid} under {cfg.start_from} (<task_id>/final.json or <task_id>.json)",
                )
        try:
            task = read_task(suite_paths(cfg.suite_dir, tid)[0])
            return refine_task(
                cfg.spec,
                task,
                cfg.suite_dir,
                run_dir,
                cfg.system,
                start_file=start_file,
                timeout_s=cfg.timeout_s,
                seed=cfg.seed,
                steps=cfg.steps,
                options=cfg.options,
            )
        except (FormatError, ValueError, OSError) as exc:
            return _failed(cfg, run_dir, tid, str(exc))

    out = []
    with ThreadPoolExecutor(max_workers=max(1, cfg.jobs)) as pool:
        for info in pool.map(one, todo):
            out.append(info)
            if bar is not None:
                bar.update(1)
            if on_done is not None:
                on_done(info)
    if bar is not None:
        bar.close()
    return out, existing


def _failed(cfg: RefineConfig, run_dir: Path, task_id: str, error: str) -> RunInfo:
    """A run.json alone, for a task the refiner could not even be given."""
    run_dir.mkdir(parents=True, exist_ok=True)
    info = RunInfo(
        system=cfg.system,
        task_id=task_id,
        agent=cfg.spec.name,
        started_at=_utc(),
        ended="error",
        error=error,
        extra={"refiner": cfg.spec.name},
    )
    write_run_info(run_dir / "run.json", info)
    return info
