"""With ``--suite``: the target as a ghost and each recorded state's PA/SR/SCD, computed in the
viewer's process (never by ``aw-serve``) through the ``aw_eval`` API, in one background thread
at low priority, for the episodes whose pages are open.

- A running episode: each state is scored in ``fast`` mode when it arrives (the shown state
  first, then the newest), once: results are kept by the state's poses.
- An episode that has ended: scored as ``aw-score`` scores a run (``aw_eval.study.score_task``:
  every state ``fast``, the final one ``exact``), kept in ``aw-score``'s run cache
  (:class:`aw_eval.study.cache.Cache`, keyed by the files' hashes), so that neither a reload nor
  a restart of the viewer computes it again.

The ghost of a state is the target moved by the inverse of that state's registration, so it
lies over the parts as recorded: the evaluator maps a state point ``x`` onto the target by
``R x / d + t`` (``d`` the evaluation divisor), so a target part at ``(R_j, p_j)`` is drawn at
``(R^T R_j, R^T (p_j - d t))``.
"""

from __future__ import annotations

import os
import sys
import threading
import time
import traceback
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aw.formats import read_manifest
from aw.formats.suite import suite_paths
from aw.pose import matrices_to_poses, poses_to_matrices

__all__ = ["Scorer", "ScoreRequest", "ghost_poses"]

STALE_SECONDS = 30.0  # a page that has not asked for this long is closed: its states wait
SCORE_NICE = 10  # the scoring thread's niceness: episodes come first


def ghost_poses(target: np.ndarray, rotation: np.ndarray, translation: np.ndarray, divisor: float) -> np.ndarray:
    """Target poses ``(P, 7)`` drawn in a state's frame through that state's registration
    (``rotation (3, 3)``, ``translation (3,)`` in normalized units)."""
    inv = np.eye(4)
    inv[:3, :3] = rotation.T
    inv[:3, 3] = -rotation.T @ (divisor * translation)
    return matrices_to_poses(inv[None] @ poses_to_matrices(target))


@dataclass
class _Task:
    """One task's geometry for scoring (or why it cannot be scored)."""

    task_dir: Path
    targets: Path
    geom: Any = None
    geometry_key: str = ""
    error: str | None = None


@dataclass
class ScoreRequest:
    """What an open episode page asked for last."""

    rid: str
    system: str
    task_id: str
    run_dir: Path
    part_ids: list[str]
    states: np.ndarray  # (N, A, 7) in part_ids order
    ended: bool
    want: int
    at: float = field(default_factory=time.monotonic)
    run_key: str = ""  # of an ended episode: the hash of its files (aw-score's run cache key)


def _numbers(pa: float, sr: float, scd: float) -> dict[str, Any]:
    return {"pa": float(pa), "sr": bool(sr), "scd": float(scd) if np.isfinite(scd) else None}


class Scorer:
    """Scores for the episode pages of one suite; ``cache_dir`` holds the run cache and the
    evaluator's geometry cache."""

    def __init__(self, suite_dir: Path, cache_dir: Path):
        self.suite_dir = Path(suite_dir)
        self.task_ids = {e.task_id for e in read_manifest(self.suite_dir).tasks}
        from aw_eval.study.cache import Cache

        self.cache = Cache(Path(cache_dir))
        self._lock = threading.Condition()
        self._tasks: dict[str, _Task] = {}
        self._states: dict[tuple[str, bytes], dict[str, Any]] = {}  # (geometry key, poses) -> fast scores
        self._runs: dict[tuple[str, str], Any] = {}  # (episode id, run key) -> RunScore
        self._requests: OrderedDict[str, ScoreRequest] = OrderedDict()
        self._failed: dict[tuple[str, str], str] = {}  # (episode id, run key) -> why it could not be scored
        self._thread: threading.Thread | None = None
        self.busy = False

    # ------------------------------------------------------------------ answers
    def report(self, req: ScoreRequest) -> dict[str, Any]:
        """What is known for ``req``'s episode now (numbers of every scored state, the ghost of
        the wanted one), and the request is queued for the rest."""
        if req.task_id not in self.task_ids:
            return {"error": f"task {req.task_id!r} is not in the suite {self.suite_dir}"}
        task = self._task(req.task_id)
        if task.error is not None:
            return {"error": task.error}
        geom = task.geom
        if req.ended and geom is not None:
            req.run_key = self._run_key(req, task)
        with self._lock:
            self._requests[req.rid] = req
            self._requests.move_to_end(req.rid)
            self._start()
            self._lock.notify_all()
        if geom is None:
            return {"pending": len(req.states), "note": "loading the task's geometry"}
        scored = [req.part_ids.index(p) for p in geom.part_ids]
        run = self._run_score(req, task) if req.ended else None
        out: dict[str, Any] = {"part_ids": list(geom.part_ids), "states": {}, "pending": 0}
        failed = self._failed.get((req.rid, req.run_key))
        if failed is not None:
            out["error"] = failed
        for k, poses in enumerate(req.states):
            res = self._state_result(run, k, task.geometry_key, poses[scored])
            if res is None:
                out["pending"] += 1
                continue
            if "error" in res:
                out["states"][str(k)] = {"error": res["error"]}
                continue
            out["states"][str(k)] = _numbers(res["pa"], res["sr"], res["scd"]) | {"mode": res["mode"]}
            if k == req.want:
                out["ghost"] = ghost_poses(
                    geom.target_poses, res["rotation"], res["translation"], float(geom.divisor)
                ).tolist()
        if run is not None:
            out["final"] = _numbers(run.pa, run.sr, run.scd) | {"mode": run.final_mode, "from": run.final_from}
            if req.want == len(req.states) - 1:
                out["ghost"] = ghost_poses(
                    geom.target_poses, run.reg_rotation, run.reg_translation, float(geom.divisor)
                ).tolist()
        elif req.ended and failed is None:
            out["pending"] += 1
        return out

    def _state_result(self, run: Any, k: int, gkey: str, poses: np.ndarray) -> dict[str, Any] | None:
        if run is not None and k < len(run.ck_pa) and len(run.ck_reg_rotation) == len(run.ck_pa):
            return {
                "pa": run.ck_pa[k],
                "sr": run.ck_sr[k],
                "scd": run.ck_scd[k],
                "rotation": run.ck_reg_rotation[k],
                "translation": run.ck_reg_translation[k],
                "mode": run.checkpoint_mode,
            }
        with self._lock:
            return self._states.get((gkey, _state_key(poses)))

    def _task(self, task_id: str) -> _Task:
        with self._lock:
            task = self._tasks.get(task_id)
            if task is None:
                task_dir, targets = suite_paths(self.suite_dir, task_id)
                task = self._tasks[task_id] = _Task(task_dir, targets)
            return task

    def _run_key(self, req: ScoreRequest, task: _Task) -> str:
        from aw_eval.study import evaluator
        from aw_eval.study.cache import run_key
        from aw_eval.study.job import ScoreSettings

        return run_key(task.geometry_key, req.run_dir, ScoreSettings().key(), evaluator.evaluator_version())

    def _run_score(self, req: ScoreRequest, task: _Task) -> Any:
        key = req.run_key
        with self._lock:
            hit = self._runs.get((req.rid, key))
        if hit is None:
            hit = self.cache.get_run(req.system, req.task_id, key)
            if hit is not None:
                with self._lock:
                    self._runs[(req.rid, key)] = hit
        return hit

    # ------------------------------------------------------------------ the worker
    def _start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._work, name="aw-view-scores", daemon=True)
            self._thread.start()

    def _work(self) -> None:
        try:
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), SCORE_NICE)
        except (AttributeError, OSError):
            pass
        from aw_eval.study import evaluator

        evaluator.prepare_thread()
        while True:
            with self._lock:
                job = self._next()
                while job is None:
                    self.busy = False
                    self._lock.wait(timeout=1.0)
                    job = self._next()
                self.busy = True
            try:
                job()
            except Exception as exc:  # each job records its own failure; this is the last resort
                print(f"aw-view: scoring failed: {_one_line(exc)}", file=sys.stderr, flush=True)
                time.sleep(1.0)

    def _next(self):
        """The next piece of work (a callable), the page asked for last first; None when idle."""
        now = time.monotonic()
        for rid in [r for r, q in self._requests.items() if now - q.at > STALE_SECONDS]:
            del self._requests[rid]
        for req in reversed(self._requests.values()):
            task = self._tasks[req.task_id]
            if task.error is not None:
                continue
            if task.geom is None:
                return lambda task=task: self._load(task)
            if req.ended:
                if not req.run_key or (req.rid, req.run_key) in self._failed or (req.rid, req.run_key) in self._runs:
                    continue
                return lambda req=req, task=task: self._score_run(req, task)
            scored = [req.part_ids.index(p) for p in task.geom.part_ids]
            n = len(req.states)
            order = [req.want] if 0 <= req.want < n else []
            order += list(range(n - 1, -1, -1))
            for k in order:
                poses = req.states[k][scored]
                if (task.geometry_key, _state_key(poses)) not in self._states:
                    return lambda task=task, poses=poses: self._score_state(task, poses)
        return None

    def _load(self, task: _Task) -> None:
        from aw.formats import FormatError
        from aw_eval.study import evaluator
        from aw_eval.study.cache import geometry_key

        try:
            geom = evaluator.load_geometry(task.task_dir, task.targets, self.cache.geometry_dir, ())
            key = geometry_key(task.task_dir, task.targets)
        except (FormatError, OSError, ValueError) as exc:
            with self._lock:
                task.error = f"the task cannot be scored: {exc}"
            return
        except Exception as exc:  # said on the page, never retried in a loop
            with self._lock:
                task.error = f"the task cannot be scored: {_one_line(exc)}"
            return
        with self._lock:
            task.geom, task.geometry_key = geom, key

    def _score_state(self, task: _Task, poses: np.ndarray) -> None:
        import aw_eval
        from aw_eval.study.episode import poses_array

        geom = task.geom
        unit = poses_array(dict(zip(geom.part_ids, poses.tolist(), strict=True)), list(geom.part_ids))
        res: dict[str, Any]
        try:
            r = aw_eval.score(geom, unit, mode="fast", backend="numba")
            res = {
                "pa": r.pa,
                "sr": r.sr,
                "scd": r.scd,
                "rotation": np.asarray(r.reg_rotation, dtype=np.float64),
                "translation": np.asarray(r.reg_translation, dtype=np.float64),
                "mode": "fast",
            }
        except Exception as exc:  # said on the page, never retried in a loop
            res = {"error": f"this state could not be scored: {_one_line(exc)}"}
        with self._lock:
            self._states[(task.geometry_key, _state_key(poses))] = res

    def _score_run(self, req: ScoreRequest, task: _Task) -> None:
        from aw_eval.study.job import STATUS_SCORED, RunRequest, ScoreSettings, TaskJob, score_task

        key = req.run_key
        job = TaskJob(
            req.task_id,
            str(task.task_dir),
            str(task.targets),
            (RunRequest(req.system, str(req.run_dir)),),
            ScoreSettings(),
            str(self.cache.geometry_dir),
        )
        try:
            out = score_task(job)
        except Exception as exc:  # said on the page, never retried in a loop
            with self._lock:
                self._failed[(req.rid, key)] = f"the run could not be scored: {_one_line(exc)}"
            return
        r = out.results[0] if out.results else None
        if r is None or r.status != STATUS_SCORED:
            why = out.error or ("; ".join(r.problems) if r is not None else "no result")
            with self._lock:
                self._failed[(req.rid, key)] = f"the run could not be scored: {why}"
            return
        self.cache.put_run(r, key)
        with self._lock:
            self._runs[(req.rid, key)] = r


def _one_line(exc: BaseException) -> str:
    return "".join(traceback.format_exception_only(type(exc), exc)).strip().splitlines()[-1]


def _state_key(poses: np.ndarray) -> bytes:
    return np.ascontiguousarray(poses, dtype=np.float64).tobytes()
