"""Scoring a whole study: find the runs, reuse what the cache holds, score the rest task by task
(in-process, in a local process pool, or on a Dask cluster), and assemble the :class:`Study`.

Runs are ``RUNS_DIR/<system>/<task_id>/`` (``trajectory.jsonl``, ``final.json``, optional
``run.json``). Every system is scored on every suite task: a task without a run directory, or
whose directory holds neither a trajectory nor final.json, is ``missing`` (PA = SR = 0). Run
directories for tasks outside the suite are listed in ``Study.unknown_runs`` and ignored.
"""

from __future__ import annotations

import multiprocessing
import os
import re
import warnings
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aw.cli.common import plural
from aw.cores import available_cores
from aw.formats import FormatError, read_manifest, read_run_info
from aw.formats.suite import suite_paths
from aw.progress import warnings_in_one_line
from aw_eval.study import evaluator
from aw_eval.study.cache import Cache, file_digest, geometry_key, run_key
from aw_eval.study.job import STATUS_ERROR, RunRequest, ScoreSettings, TaskJob, TaskOutput, score_task
from aw_eval.study.model import STATUS_MISSING, RunScore
from aw_eval.study.table import RunRecord, Study
from aw_eval.workers import stop_pool, watch_parent

__all__ = ["StudyError", "ScoringFailed", "Coverage", "discover_runs", "score_study", "ScoreStats"]


class StudyError(Exception):
    """A problem with the inputs as a whole (no suite, no runs directory): one line for the user."""


class ScoringFailed(StudyError):
    """The scoring machinery failed (a worker process died, the process pool broke, a Dask worker
    was lost): a failure of the tool, not of the runs, so no run is scored 0 for it. Tasks scored
    before the failure are cached; a rerun resumes."""


@dataclass
class ScoreStats:
    """What a scoring pass did: runs found in the cache, runs scored now, tasks dispatched."""

    cached: int = 0
    scored: int = 0
    tasks_dispatched: int = 0
    missing: int = 0
    errors: int = 0
    executor: str = "none"
    seconds_geometry: float = 0.0  # summed over the tasks dispatched now (worker wall time)
    seconds_checkpoints: float = 0.0
    seconds_final: float = 0.0
    coverage: Coverage | None = None  # how the runs found match the suite


def shape_family(task_dir: Path) -> str:
    """Digest of a task's part meshes: tasks with equal digests share their evaluation geometry
    (paired PartNet conditions), which the evaluator's geometry cache computes once."""
    return "|".join(file_digest(f) for f in sorted((Path(task_dir) / "parts").glob("*")))


def schedule_jobs(jobs: list[TaskJob], n_parts: dict[str, int]) -> list[TaskJob]:
    """Dispatch order: largest tasks first (their geometry dominates, and starting them first
    shortens the tail on a pool), and a task whose meshes repeat an earlier task's after every
    first occurrence, so its geometry is a cache hit instead of being computed twice at once."""
    seen: set[str] = set()
    first, repeats = [], []
    for job in sorted(jobs, key=lambda j: (-n_parts.get(j.task_id, 0), j.task_id)):
        fam = shape_family(Path(job.task_dir))
        (repeats if fam in seen and fam else first).append(job)
        seen.add(fam)
    return first + repeats


def _is_run_dir(p: Path) -> bool:
    return (p / "trajectory.jsonl").exists() or (p / "final.json").exists()


_ATTEMPT = re.compile(r"attempt-[0-9]+")


def _attempt_dirs(system_dir: Path) -> list[Path]:
    """The ``attempt-N`` subfolders of an ``aw-serve --record-under`` folder, in attempt order."""
    dirs = [p for p in system_dir.iterdir() if p.is_dir() and _ATTEMPT.fullmatch(p.name)]
    return sorted(dirs, key=lambda p: int(p.name.split("-")[1]))


def discover_runs(
    runs_dir: Path, task_ids: set[str]
) -> tuple[list[str], dict[tuple[str, str], Path], list[dict[str, Any]]]:
    """``(systems, {(system, task_id): run_dir}, unknown)`` where ``unknown`` lists run
    directories of tasks not in the suite. Hidden directories are skipped.

    A system folder laid out by ``aw-serve --record-under`` (``<name>/attempt-N/<task_id>/``, no
    task folder of its own) is one system per attempt, named ``<name>/attempt-N``."""
    if not runs_dir.is_dir():
        raise StudyError(f"{runs_dir}: runs directory not found")
    top = sorted(p.name for p in runs_dir.iterdir() if p.is_dir() and not p.name.startswith("."))
    as_tasks = [s for s in top if s in task_ids and _is_run_dir(runs_dir / s)]
    if as_tasks:
        shown = ", ".join(as_tasks[:3]) + (", ..." if len(as_tasks) > 3 else "")
        raise StudyError(
            f"{runs_dir} looks like one system's folder: its subdirectories {shown} are runs of suite "
            f"tasks; pass the runs root that holds it ({runs_dir.parent}), laid out as "
            "RUNS_DIR/<system>/<task_id>/"
        )
    folders: dict[str, Path] = {}
    for name in top:
        attempts = _attempt_dirs(runs_dir / name)
        own_tasks = any((runs_dir / name / t).is_dir() for t in task_ids)
        if attempts and not own_tasks:
            folders.update((f"{name}/{a.name}", a) for a in attempts)
        else:
            folders[name] = runs_dir / name
    found: dict[tuple[str, str], Path] = {}
    unknown: list[dict[str, Any]] = []
    for s, folder in folders.items():
        for p in sorted(folder.iterdir()):
            if not p.is_dir() or p.name.startswith("."):
                continue
            if p.name in task_ids:
                found[(s, p.name)] = p
            elif _is_run_dir(p):
                unknown.append({"system": s, "task_id": p.name, "path": str(p)})
    return list(folders), found, unknown


@dataclass
class Coverage:
    """How the runs found match the suite: ``runs[system]`` runs (a folder with a trajectory or
    final.json) of its ``n_tasks`` tasks, and ``unknown`` runs of tasks outside it."""

    n_tasks: int
    runs: dict[str, int]
    unknown: int

    @classmethod
    def of(
        cls, systems: list[str], found: dict[tuple[str, str], Path], unknown: list[dict[str, Any]], n_tasks: int
    ) -> Coverage:
        runs = {s: 0 for s in systems}
        for (s, _), p in found.items():
            runs[s] += _is_run_dir(p)
        return cls(n_tasks, runs, len(unknown))

    @property
    def matched(self) -> int:
        return sum(self.runs.values())

    def numbers(self) -> str:
        """Runs found, suite tasks, unknown runs, in one phrase."""
        return (
            f"{plural(self.matched + self.unknown, 'run')} found: {self.matched} for the suite's "
            f"{plural(self.n_tasks, 'task')}, {self.unknown} for tasks not in the suite"
        )

    def warnings(self, suite_name: str) -> list[str]:
        """One line per system that lacks runs, and one for runs of tasks outside the suite."""
        out = []
        for s, k in self.runs.items():
            if k < self.n_tasks:
                out.append(
                    f"system {s} has runs for {k} of the {plural(self.n_tasks, 'task')}; the other "
                    f"{self.n_tasks - k} count as missing (PA = SR = 0)"
                )
        if self.unknown:
            out.append(f"{plural(self.unknown, 'run')} for tasks not in suite {suite_name} ignored ({self.numbers()})")
        return out


def _progress(total: int, enabled: bool, desc: str):
    from aw.progress import progress

    return progress(total, desc, "task", enabled=enabled)


def _worker_init(parent: int) -> None:
    # One XLA thread per worker process: the pool already spreads work over the cores.
    os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")
    watch_parent(parent)  # a killed aw-score takes its workers with it
    warnings.showwarning = warnings_in_one_line("aw-score")  # e.g. a task that will take long


def _failed(job: TaskJob, exc: BaseException, where: str) -> ScoringFailed:
    """The error for a job whose worker failed."""
    msg = f"scoring failed: {where} died or broke while scoring task {job.task_id} ({type(exc).__name__}: {exc})"
    if isinstance(exc, OSError) and exc.filename:  # e.g. a full disk under the geometry cache
        msg = f"scoring failed: {exc.filename}: {exc.strerror or exc} (while scoring task {job.task_id})"
    if isinstance(exc, BrokenProcessPool):
        msg += (
            '; if score_study is called from a script, put the call under `if __name__ == "__main__":` '
            "(worker processes import the script)"
        )
    return ScoringFailed(msg + "; tasks scored before it are cached, and a rerun resumes from them")


def _run_jobs(
    jobs: list[TaskJob], *, scheduler: str | None, n_jobs: int
) -> tuple[Iterator[TaskOutput], str, Callable[[bool], None]]:
    """Yield outputs as they complete; returns (iterator, executor name, closer). ``closer(True)``
    abandons the work (an interrupt or a failure): local workers are terminated at once."""
    if not jobs:
        return iter(()), "none", lambda abort: None
    if scheduler:
        try:
            from distributed import Client
            from distributed import as_completed as dask_completed
        except ImportError as exc:  # pragma: no cover - distributed is a dependency
            raise StudyError(f"--scheduler needs the 'distributed' package ({exc})") from None
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise StudyError(f"cannot connect to the Dask scheduler at {scheduler}: {exc}") from None
        futures = client.map(score_task, jobs, pure=False)
        job_of = {f.key: j for f, j in zip(futures, jobs)}

        def gen_dask() -> Iterator[TaskOutput]:
            for fut in dask_completed(futures):
                try:
                    out = fut.result()
                except Exception as exc:  # a worker died (KilledWorker) or could not run the job
                    raise _failed(job_of[fut.key], exc, "a Dask worker") from None
                yield out

        return gen_dask(), f"dask:{scheduler}", lambda abort: client.close()
    if n_jobs <= 1 or len(jobs) == 1:

        def gen_inline() -> Iterator[TaskOutput]:
            for j in jobs:
                try:
                    out = score_task(j)
                except Exception as exc:  # score_task reports bad runs itself: this is a bug or a crash
                    raise _failed(j, exc, "the scoring code") from exc
                yield out

        return gen_inline(), "in-process", lambda abort: None
    pool = ProcessPoolExecutor(
        max_workers=min(n_jobs, len(jobs)),
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_worker_init,
        initargs=(os.getpid(),),
    )
    futs = {pool.submit(score_task, j): j for j in jobs}

    def gen_pool() -> Iterator[TaskOutput]:
        for f in as_completed(futs):
            try:
                out = f.result()
            except Exception as exc:  # e.g. BrokenProcessPool: a worker was killed
                raise _failed(futs[f], exc, "a scoring worker process") from None
            yield out

    def close(abort: bool) -> None:
        if abort:
            stop_pool(pool)
        else:
            pool.shutdown(cancel_futures=True)

    return gen_pool(), f"processes:{min(n_jobs, len(jobs))}", close


def _read_info(run_dir: Path | None) -> tuple[Any, str | None]:
    if run_dir is None or not (run_dir / "run.json").is_file():
        return None, None
    try:
        return read_run_info(run_dir / "run.json"), None
    except FormatError as exc:
        return None, f"run.json unreadable: {exc.problem}"


def score_study(
    suite_dir: str | Path,
    runs_dir: str | Path,
    out_dir: str | Path,
    settings: ScoreSettings,
    *,
    scheduler: str | None = None,
    n_jobs: int | None = None,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
    geometry_cache: str | Path | None = None,
) -> tuple[Study, ScoreStats]:
    """Score every run of every system on every suite task (resuming from ``out_dir/cache``).

    ``geometry_cache``: the evaluator's per-task geometry cache (default ``out_dir/cache/geometry``).
    """
    suite_dir, runs_dir, out_dir = Path(suite_dir), Path(runs_dir), Path(out_dir)
    try:
        manifest = read_manifest(suite_dir)
    except FormatError as exc:
        raise StudyError(str(exc)) from None
    entries = list(manifest.tasks)
    ids = {e.task_id for e in entries}
    systems, found, unknown = discover_runs(runs_dir, ids)
    if not systems:
        raise StudyError(f"{runs_dir}: no system directories (expected RUNS_DIR/<system>/<task_id>/)")
    coverage = Coverage.of(systems, found, unknown, len(entries))
    if coverage.matched == 0:  # a table of zeros would look like a result
        example = f" (e.g. {unknown[0]['system']}/{unknown[0]['task_id']})" if unknown else ""
        raise StudyError(
            f"{runs_dir}: no run matches a task of suite {manifest.name} ({coverage.numbers()}{example}); "
            "are these runs of another suite? Runs are RUNS_DIR/<system>/<task_id>/ with "
            "trajectory.jsonl or final.json"
        )
    if log:
        recorded = sorted({s.split("/")[0] for s in systems if "/" in s})
        for name in recorded:
            mine = [s for s in systems if s.startswith(name + "/")]
            log(
                f"{runs_dir / name} holds aw-serve --record-under recordings: scored as "
                f"{plural(len(mine), 'system')}, one per attempt ({', '.join(mine)})"
            )
        for line in coverage.warnings(manifest.name):
            log(f"warning: {line}")
    cache = Cache(out_dir / "cache")
    cache.remove_stale()
    ev_version = evaluator.evaluator_version()
    stats = ScoreStats(coverage=coverage)
    scores: dict[tuple[str, str], RunScore] = {}
    keys: dict[tuple[str, str], str] = {}
    facts = {}
    jobs: list[TaskJob] = []
    gkeys: dict[str, str] = {}
    for e in entries:
        task_dir, targets = suite_paths(suite_dir, e.task_id)
        gkey = gkeys[e.task_id] = geometry_key(task_dir, targets)
        f = cache.get_facts(e.task_id, gkey)
        if f is not None:
            facts[e.task_id] = f
        todo = []
        for s in systems:
            run_dir = found.get((s, e.task_id))
            if run_dir is None or not _is_run_dir(run_dir):
                where = f"{runs_dir / s / e.task_id}"
                scores[(s, e.task_id)] = RunScore.unscored(s, e.task_id, STATUS_MISSING, [f"no run at {where}"])
                stats.missing += 1
                continue
            key = run_key(gkey, run_dir, settings.key(), ev_version)
            keys[(s, e.task_id)] = key
            hit = cache.get_run(s, e.task_id, key)
            if hit is not None:
                scores[(s, e.task_id)] = hit
                stats.cached += 1
            else:
                todo.append(RunRequest(s, str(run_dir)))
        if todo or f is None:
            jobs.append(
                TaskJob(
                    e.task_id,
                    str(task_dir),
                    str(targets),
                    tuple(todo),
                    settings,
                    str(geometry_cache or cache.geometry_dir),
                )
            )
    jobs = schedule_jobs(jobs, {e.task_id: e.n_parts for e in entries})
    stats.tasks_dispatched = len(jobs)
    outputs, stats.executor, close = _run_jobs(jobs, scheduler=scheduler, n_jobs=n_jobs or available_cores())
    if log and jobs:
        log(
            f"scoring {plural(sum(len(j.runs) for j in jobs), 'run')} of {plural(len(jobs), 'task')} ({stats.executor}); "
            f"{plural(stats.cached, 'run')} from the cache"
        )
    aborted = True
    try:
        with _progress(len(jobs), progress and len(jobs) > 0, "scoring") as bar:
            for out in outputs:
                if out.facts is not None:
                    facts[out.task_id] = out.facts
                    stats.seconds_geometry += out.facts.seconds_geometry
                    cache.put_facts(out.facts, gkeys[out.task_id])
                for r in out.results:
                    scores[(r.system, r.task_id)] = r
                    stats.scored += 1
                    stats.seconds_checkpoints += r.seconds_checkpoints
                    stats.seconds_final += r.seconds_final
                    if r.status == STATUS_ERROR or out.error:
                        stats.errors += 1
                    else:
                        cache.put_run(r, keys[(r.system, r.task_id)])
                bar.update(1)
        aborted = False
    finally:
        close(aborted)
    runs: dict[tuple[str, str], RunRecord] = {}
    for (s, t), sc in scores.items():
        run_dir = found.get((s, t))
        info, problem = _read_info(run_dir)
        runs[(s, t)] = RunRecord(sc, info, problem, run_dir)
    study = Study(
        manifest.name,
        entries,
        systems,
        runs,
        facts,
        unknown,
        settings={
            "checkpoint_mode": settings.checkpoint_mode,
            "final_mode": settings.final_mode,
            "final_only": settings.final_only,
            "trust_final": settings.trust_final,
            "evaluator_version": ev_version,
            "protocol_overrides": {k: v for k, v in settings.protocol},
        },
    )
    return study, stats
