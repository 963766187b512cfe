"""The per-task job: load one task's geometry once and score every requested run of it.

:func:`score_task` is a pure top-level function of a picklable :class:`TaskJob`, so the same
job runs in-process, in a local process pool or on a Dask worker with identical results. It
never writes anything (except the evaluator's own geometry cache, when one is given): results
go back to the caller, which caches them.
"""

from __future__ import annotations

import errno
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from aw import interrupts
from aw.formats import FormatError, read_targets, read_task
from aw.meshes import load_task_meshes
from aw.official.eval_points import suite_eval_inputs
from aw.prepare.geometry import part_size_ratio
from aw_eval import TaskGeometry
from aw_eval.study import evaluator
from aw_eval.study.decreases import pa_decreases
from aw_eval.study.episode import RunUnreadable, read_episode
from aw_eval.study.model import STATUS_SCORED, STATUS_UNREADABLE, RunScore, TaskFacts

__all__ = [
    "ScoreSettings",
    "RunRequest",
    "TaskJob",
    "TaskOutput",
    "score_task",
    "surface_centroids",
    "STATUS_ERROR",
    "STATUS_TASK_ERROR",
]

STATUS_ERROR = "error"  # the evaluator raised on this run (not cached; listed in the report)
STATUS_TASK_ERROR = "task_error"  # the task's geometry could not be loaded
_WRITE_FAULTS = (errno.ENOSPC, errno.EFBIG, errno.EDQUOT)  # a full disk or a size limit: never a task's fault


@dataclass(frozen=True)
class ScoreSettings:
    """What changes scores: part of every cache key."""

    checkpoint_mode: str = "fast"
    final_mode: str = "exact"
    final_only: bool = False
    # Score final.json even where it contradicts the trajectory's last recorded state.
    trust_final: bool = False
    # Overrides of the evaluation protocol's numbers (ProtocolSettings fields): not the paper's
    # protocol; for experiments and fast tests. Sorted (name, value) pairs.
    protocol: tuple[tuple[str, float], ...] = ()
    # Where exact scoring runs (aw_eval.registration.BACKENDS; fast runs on the CPU kernels):
    # the same numbers to rounding, so not part of the cache key.
    backend: str = "auto"

    def __post_init__(self) -> None:
        for name in ("checkpoint_mode", "final_mode"):
            if getattr(self, name) not in evaluator.MODES:
                raise ValueError(f"{name} must be one of {evaluator.MODES}, got {getattr(self, name)!r}")
        if self.backend not in evaluator.BACKENDS:
            raise ValueError(f"backend must be one of {evaluator.BACKENDS}, got {self.backend!r}")
        object.__setattr__(self, "protocol", tuple(sorted(self.protocol)))
        evaluator.protocol_settings(self.protocol)  # validates names and values

    def key(self) -> str:
        proto = ",".join(f"{k}={v!r}" for k, v in self.protocol)
        trust = ";trust_final=1" if self.trust_final else ""
        return (
            f"ck={self.checkpoint_mode};final={self.final_mode};final_only={int(self.final_only)}{trust};"
            f"protocol={proto}"
        )


@dataclass(frozen=True)
class RunRequest:
    system: str
    run_dir: str


@dataclass(frozen=True)
class TaskJob:
    task_id: str
    task_dir: str
    targets_path: str
    runs: tuple[RunRequest, ...]
    settings: ScoreSettings
    geometry_cache: str | None = None


@dataclass
class TaskOutput:
    task_id: str
    facts: TaskFacts | None
    results: list[RunScore] = field(default_factory=list)
    error: str | None = None


def surface_centroids(meshes) -> np.ndarray:
    """``(A, 3)`` area-weighted surface centroids (the mean of area-weighted surface samples)."""
    out = []
    for m in meshes:
        areas = m.area_faces
        out.append((m.triangles_center * areas[:, None]).sum(axis=0) / max(areas.sum(), 1e-300))
    return np.array(out).reshape(-1, 3)


def _score_run(
    req: RunRequest,
    task_id: str,
    geom,
    all_ids: list[str],
    centroids: np.ndarray,
    settings: ScoreSettings,
    memo: dict | None = None,
) -> RunScore:
    scored_ids = list(geom.part_ids)
    try:
        ep = read_episode(
            req.run_dir,
            task_id,
            all_ids,
            scored_ids,
            centroids,
            float(geom.divisor),
            final_only=settings.final_only,
            trust_final=settings.trust_final,
        )
    except RunUnreadable as exc:
        return RunScore.unscored(req.system, task_id, STATUS_UNREADABLE, [str(exc)])
    r = RunScore(
        system=req.system,
        task_id=task_id,
        status=STATUS_SCORED,
        problems=list(ep.problems),
        final_from=ep.final_from,
        end_reason=ep.end_reason,
        truncated=ep.truncated,
        has_trajectory=ep.has_trajectory,
        end_t=ep.end_t,
        final_mode=settings.final_mode,
        checkpoint_mode="" if settings.final_only else settings.checkpoint_mode,
        moved=ep.moved,
        call_t=ep.call_t,
        call_kind=ep.call_kind,
        call_ok=ep.call_ok,
        edit_call=ep.edit_call,
        edit_translation=ep.edit_translation,
        edit_rotation_deg=ep.edit_rotation_deg,
        edit_revisit=ep.edit_revisit,
        ck_seq=ep.ck_seq,
        ck_t=ep.ck_t,
    )
    ck = None
    t0 = time.perf_counter()
    if len(ep.ck_poses):
        ck = evaluator.score_states(
            geom,
            ep.ck_poses,
            settings.checkpoint_mode,
            settings.backend,
            memo if settings.checkpoint_mode == "exact" else None,
        )
        r.ck_pa, r.ck_sr, r.ck_sra, r.ck_scd = ck["pa"], ck["sr"], ck["sra"], ck["scd"]
        r.ck_part_errors, r.ck_assignment = ck["part_errors"], ck["assignment"]
        r.ck_reg_rotation, r.ck_reg_translation = ck["reg_rotation"], ck["reg_translation"]
        dec = pa_decreases(geom, ep.ck_poses, ck["pa"], ck["assignment"], ck["reg_rotation"], ck["reg_translation"])
        r.ck_drop_index, r.ck_drop_assignment_changed = dec.index, dec.assignment_changed
        r.ck_drop_persist_alignment, r.ck_drop_persist_both = dec.persist_alignment, dec.persist_both
    r.seconds_checkpoints = time.perf_counter() - t0
    t0 = time.perf_counter()
    # the final state: reuse the last checkpoint when it is the same state in the same mode
    if (
        ck is not None
        and settings.final_mode == settings.checkpoint_mode
        and np.array_equal(ep.final_poses, ep.ck_poses[-1])
    ):
        fin, row, poses = ck, len(ep.ck_poses) - 1, ep.ck_poses
    else:
        poses = ep.final_poses[None]
        fin, row = (
            evaluator.score_states(
                geom, poses, settings.final_mode, settings.backend, memo if settings.final_mode == "exact" else None
            ),
            0,
        )
    r.pa, r.sr, r.sra, r.scd = (float(fin[k][row]) for k in ("pa", "sr", "sra", "scd"))
    r.part_errors, r.assignment = fin["part_errors"][row], fin["assignment"][row]
    r.reg_rotation, r.reg_translation = fin["reg_rotation"][row], fin["reg_translation"][row]
    r.centred_cd, r.offset = evaluator.final_diagnostics(geom, poses, fin, row)
    r.seconds_final = time.perf_counter() - t0
    return r


def _load_native(job: TaskJob, t0: float):
    """Geometry, all part ids, centroids and facts of a task read from its task directory."""
    task = read_task(job.task_dir)
    read_targets(job.targets_path)  # fail early with a clear message
    geom = evaluator.load_geometry(
        Path(job.task_dir),
        Path(job.targets_path),
        Path(job.geometry_cache) if job.geometry_cache else None,
        job.settings.protocol,
    )
    meshes = load_task_meshes(task)
    all_ids = task.part_ids
    scored = set(geom.part_ids)
    ratio = part_size_ratio([m for pid, m in zip(all_ids, meshes, strict=True) if pid in scored])
    facts = TaskFacts(
        job.task_id, int(geom.n_parts), float(ratio), float(geom.divisor), list(geom.part_ids), time.perf_counter() - t0
    )
    return geom, all_ids, surface_centroids(meshes), facts


def _load_official(job: TaskJob, inputs, t0: float):
    """The same for a task converted from an official package (``aw.official``): its geometry is
    the package's own evaluation points; there is no task directory."""
    read_targets(job.targets_path)
    geom = TaskGeometry.from_points(inputs.part_ids, inputs.points, inputs.target_poses, inputs.divisor, inputs.groups)
    facts = TaskFacts(
        job.task_id,
        int(geom.n_parts),
        float(inputs.size_ratio()),
        float(geom.divisor),
        list(geom.part_ids),
        time.perf_counter() - t0,
    )
    return geom, list(inputs.part_ids), inputs.centroids(), facts


def _prescore_runs(job: TaskJob, geom, all_ids: list[str], centroids: np.ndarray) -> dict | None:
    """On the jax backend, every ``exact`` state of every run of the task scored in one batch
    (checkpoints of all systems fill each device call); ``None`` elsewhere, or where that batch
    fails (each run is then scored, and fails, on its own)."""
    st = job.settings
    if not evaluator.batched_backend("exact", st.backend):
        return None
    poses = []
    for req in job.runs:
        try:
            ep = read_episode(
                req.run_dir,
                job.task_id,
                all_ids,
                list(geom.part_ids),
                centroids,
                float(geom.divisor),
                final_only=st.final_only,
                trust_final=st.trust_final,
            )
        except Exception as exc:  # unreadable here is reported by the run's own scoring
            interrupts.reraise_if_interrupted(exc)
            continue
        if st.checkpoint_mode == "exact" and len(ep.ck_poses):
            poses.append(ep.ck_poses)
        if st.final_mode == "exact":
            poses.append(ep.final_poses[None])
    try:
        return evaluator.prescore(geom, poses, "exact", st.backend)
    except Exception as exc:  # the per-run path reports the failure against its run
        interrupts.reraise_if_interrupted(exc)
        return None


def score_task(job: TaskJob) -> TaskOutput:
    """Score every run of ``job``; never raises for a bad run or task (errors are in the output).
    An interrupt raises :class:`aw.interrupts.Interrupted`, however a library wrapped it."""
    evaluator.prepare_thread()
    t0 = time.perf_counter()
    try:
        official = suite_eval_inputs(Path(job.targets_path).parent.parent, job.task_id)
        loaded = _load_official(job, official, t0) if official is not None else _load_native(job, t0)
    except (FormatError, ValueError, OSError) as exc:
        interrupts.reraise_if_interrupted(exc)  # e.g. trimesh or Qhull wrapping a Ctrl-C
        if isinstance(exc, OSError) and exc.errno in _WRITE_FAULTS:
            raise  # the geometry cache cannot be written (a full disk): the tool fails, not the task
        msg = f"task geometry could not be loaded: {exc}"
        return TaskOutput(
            job.task_id,
            None,
            [RunScore.unscored(r.system, job.task_id, STATUS_TASK_ERROR, [msg]) for r in job.runs],
            error=msg,
        )
    geom, all_ids, centroids, facts = loaded
    out = TaskOutput(job.task_id, facts)
    memo = _prescore_runs(job, geom, all_ids, centroids)
    for req in job.runs:
        try:
            out.results.append(_score_run(req, job.task_id, geom, all_ids, centroids, job.settings, memo))
            interrupts.check()  # an interrupt a library swallowed: this score may not be the run's
        except Exception as exc:  # an evaluator failure on one run must not lose the others
            # an interrupt inside a compiled kernel comes back as another exception (numba: a
            # SystemError): it stops the study, it is not this run's failure
            interrupts.reraise_if_interrupted(exc)
            if isinstance(exc, OSError) and exc.errno in _WRITE_FAULTS:
                raise
            detail = "".join(traceback.format_exception_only(type(exc), exc)).strip()
            out.results.append(RunScore.unscored(req.system, job.task_id, STATUS_ERROR, [f"scoring failed: {detail}"]))
    return out
