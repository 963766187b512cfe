"""What is on disk under the watched folder: its episodes, their status, and their recordings,
read as they grow. Nothing here writes a file or takes a lock.

An episode is a run directory: a folder with ``trajectory.jsonl``, ``final.json``, ``run.json``,
``.aw-lock`` or ``.runner/`` (``aw-run``'s working folder while an episode runs). They are
found down to :data:`MAX_DEPTH` levels below the watched folder (``RUNS/<system>/<task_id>/``,
``RUNS/<name>/attempt-N/<task_id>/``), hidden folders and suites skipped. Tasks that an
``aw-run`` batch still has to run (its ``.aw-batch.json``, while its process lives) are queued.

Status, from the most authoritative file present: ``aw-run``'s ``run.json`` (how the agent
ended), else the trajectory's end record (how the server closed), else a live recorder (the
lock of ``aw.runlock`` held, read from the kernel's lock list) or ``aw-run``'s working folder:
running; else the recording stopped without an end record: interrupted.
"""

from __future__ import annotations

import hashlib
import os
import socket
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

import orjson

from aw.formats import FormatError, TrajectoryFollower, read_run_info
from aw.formats.io import pid_alive
from aw.formats.run import BATCH_FILE, BatchPlan, read_batch_plan
from aw.runlock import LOCK_FILE, kernel_flocks, run_in_progress
from aw_view.public import NotPublic, PublicFiles, TaskFiles, TaskView

__all__ = ["Watch", "Episode", "MAX_DEPTH", "STATUSES", "MAX_ARGS_CHARS"]

MAX_DEPTH = 4
RUN_MARKERS = ("trajectory.jsonl", "final.json", "run.json", LOCK_FILE, ".runner")
STATUSES = ("queued", "running", "finished", "error", "timed out", "interrupted", "unreadable")
# the server's end record and aw-run's run.json, as the runs page says them
_END_STATUS = {
    "finished": "finished",
    "disconnect": "finished",
    "timeout": "timed out",
    "error": "error",
    "interrupted": "interrupted",
}
_RUN_STATUS = {"finished": "finished", "timeout": "timed out", "error": "error", "crashed": "error", "hung": "error"}
MAX_ARGS_CHARS = 4000  # a call's arguments as listed on the episode page (the recorder caps them at 20,000)
SCAN_INTERVAL = 0.25  # seconds: requests within this share one look at the disk
DETAILED = 8  # episodes whose every call is kept in memory (the pages opened last)


def _unix(iso: str) -> float | None:
    try:
        return datetime.fromisoformat(iso.replace("Z", "+00:00")).timestamp()
    except ValueError:
        return None


def _first_line(text: str | None) -> str:
    return (text or "").strip().splitlines()[0] if (text or "").strip() else ""


@dataclass
class Queued:
    id: str
    system: str
    task_id: str


@dataclass
class Episode:
    """One run directory: its followers (a summary one for the runs page, a detailed one while
    its page is open) and what ``run.json`` said last."""

    id: str
    run_dir: Path
    system: str
    dir_name: str
    summary: TrajectoryFollower
    detail: TrajectoryFollower | None = None
    run_info: tuple[int, Any] | None = None  # (mtime_ns, RunInfo or error text)
    lock: threading.Lock = field(default_factory=threading.Lock)

    @property
    def trajectory_path(self) -> Path:
        return self.run_dir / "trajectory.jsonl"


class Watch:
    """The episodes under ``root`` and what the pages show of them."""

    def __init__(
        self, root: Path, public: PublicFiles, tasks: TaskFiles, stuck_seconds: float = 120.0, scorer: Any = None
    ):
        self.root = Path(root)
        self.public = public
        self.tasks = tasks
        self.stuck_seconds = stuck_seconds
        self.scorer = scorer
        self._lock = threading.Lock()
        self._episodes: dict[str, Episode] = {}
        self._plans: dict[Path, tuple[int, BatchPlan | str]] = {}
        self._detailed: OrderedDict[str, None] = OrderedDict()
        self._scanned_at = 0.0
        self._runs: tuple[bytes, str] = (b"", "")
        self._host = socket.gethostname()

    # ------------------------------------------------------------------ discovery
    def _episode_id(self, run_dir: Path) -> str:
        """The path from the root (the root's own name when the root is a run directory)."""
        return run_dir.relative_to(self.root).as_posix() if run_dir != self.root else self.root.name

    def _find(self) -> tuple[list[Path], list[Path], list[str]]:
        """``(run dirs, folders holding a batch plan, problems)`` under the root."""
        runs: list[Path] = []
        plans: list[Path] = []
        problems: list[str] = []
        stack = [(self.root, 0)]
        while stack:
            folder, depth = stack.pop()
            try:
                names = sorted(os.listdir(folder))
            except OSError as exc:
                problems.append(f"{folder}: cannot be listed ({exc.strerror})")
                continue
            if any(n in names for n in RUN_MARKERS):
                runs.append(folder)
                continue
            if "manifest.json" in names and "tasks" in names:  # a suite: nothing to watch in it
                continue
            if BATCH_FILE in names:
                plans.append(folder)
            if depth >= MAX_DEPTH:
                continue
            for name in reversed(names):
                if name.startswith(".") or name == "captures":
                    continue
                sub = folder / name
                if sub.is_dir() and not sub.is_symlink():
                    stack.append((sub, depth + 1))
        return runs, plans, problems

    def _plan(self, folder: Path) -> BatchPlan | str:
        path = folder / BATCH_FILE
        try:
            self.public.check(path)
            stamp = path.stat().st_mtime_ns
        except (OSError, NotPublic) as exc:
            return str(exc)
        known = self._plans.get(folder)
        if known is not None and known[0] == stamp:
            return known[1]
        try:
            plan: BatchPlan | str = read_batch_plan(path)
        except FormatError as exc:
            plan = str(exc)
        self._plans[folder] = (stamp, plan)
        return plan

    def _batch_alive(self, plan: BatchPlan) -> bool:
        return plan.finished_unix is None and plan.host == self._host and pid_alive(plan.pid)

    def suites(self) -> list[Path]:
        """The suites named by the batch plans seen (where queued tasks' files are)."""
        with self._lock:
            plans = [p for _, p in self._plans.values() if isinstance(p, BatchPlan)]
        return [Path(p.suite_dir) for p in plans]

    def _plan_of(self, run_dir: Path) -> BatchPlan | None:
        with self._lock:
            known = self._plans.get(run_dir.parent)
        return known[1] if known is not None and isinstance(known[1], BatchPlan) else None

    # ------------------------------------------------------------------ the runs page
    def runs(self) -> tuple[bytes, str]:
        """The runs page's JSON and its ETag; the disk is looked at most every ``SCAN_INTERVAL``."""
        with self._lock:
            if time.monotonic() - self._scanned_at < SCAN_INTERVAL and self._runs[0]:
                return self._runs
        rows, problems = self._scan()
        body = orjson.dumps(
            {"root": str(self.root), "stuck_seconds": self.stuck_seconds, "rows": rows, "problems": problems}
        )
        etag = '"' + hashlib.sha1(body).hexdigest()[:20] + '"'
        with self._lock:
            self._runs = (body, etag)
            self._scanned_at = time.monotonic()
        return body, etag

    def _scan(self) -> tuple[list[dict], list[str]]:
        run_dirs, plan_dirs, problems = self._find()
        plans = {}
        for folder in plan_dirs:
            plan = self._plan(folder)
            if isinstance(plan, str):
                problems.append(plan)
            else:
                plans[folder] = plan
        flocks = kernel_flocks()
        rows = []
        seen = set()
        for run_dir in run_dirs:
            ep = self._get(run_dir)
            seen.add(ep.id)
            rows.append(self._row(ep, flocks))
        for folder, plan in plans.items():
            if not self._batch_alive(plan):
                continue
            for tid in plan.tasks:
                run_dir = folder / tid
                rid = self._episode_id(run_dir)
                if rid in seen and not self._older_than(run_dir, plan):
                    continue
                row = next((r for r in rows if r["id"] == rid), None)
                if row is not None:
                    rows.remove(row)
                rows.append(self._queued_row(Queued(rid, self._system_of(run_dir), tid)))
        with self._lock:
            for gone in set(self._episodes) - seen:
                del self._episodes[gone]
                self._detailed.pop(gone, None)
        rows.sort(key=lambda r: (r["system"], r["task_id"], r["id"]))
        return rows, problems

    @staticmethod
    def _older_than(run_dir: Path, plan: BatchPlan) -> bool:
        """Whether ``run_dir`` is left from before the batch (it will be replaced when its turn comes)."""
        try:
            return run_dir.stat().st_mtime < plan.started_unix - 1.0
        except OSError:
            return True

    def _system_of(self, run_dir: Path) -> str:
        rel = run_dir.relative_to(self.root).parts
        return "/".join(rel[:-1]) if len(rel) > 1 else (run_dir.parent.name if not rel else self.root.name)

    def _get(self, run_dir: Path) -> Episode:
        rid = self._episode_id(run_dir)
        with self._lock:
            ep = self._episodes.get(rid)
            if ep is None:
                ep = Episode(
                    rid,
                    run_dir,
                    self._system_of(run_dir),
                    run_dir.name,
                    TrajectoryFollower(run_dir / "trajectory.jsonl", keep_calls=False),
                )
                self._episodes[rid] = ep
        return ep

    def episode(self, rid: str) -> Episode | None:
        """An episode by id: one found under the root whose folder is still there."""
        with self._lock:
            ep = self._episodes.get(rid)
        if ep is None or not ep.run_dir.is_dir():
            with self._lock:
                self._scanned_at = 0.0
            self.runs()
            with self._lock:
                ep = self._episodes.get(rid)
        return ep if ep is not None and ep.run_dir.is_dir() else None

    def _queued_row(self, q: Queued) -> dict:
        return {"id": q.id, "system": q.system, "task_id": q.task_id, "status": "queued", "detail": "", "calls": 0}

    def _run_info(self, ep: Episode) -> Any:
        """``run.json`` (re-read when it changes): a RunInfo, an error text, or None."""
        path = ep.run_dir / "run.json"
        try:
            stamp = path.stat().st_mtime_ns
        except OSError:
            return None
        if ep.run_info is not None and ep.run_info[0] == stamp:
            return ep.run_info[1]
        try:
            self.public.check(path)
            info: Any = read_run_info(path)
        except (FormatError, NotPublic) as exc:
            info = str(exc)
        ep.run_info = (stamp, info)
        return info

    @staticmethod
    def _detail(ep: Episode) -> TrajectoryFollower:
        """The follower of ``ep``'s whole recording, made on first use (hold ``ep.lock``)."""
        if ep.detail is None:
            ep.detail = TrajectoryFollower(ep.trajectory_path, keep_calls=True)
        return ep.detail

    def _poll(self, follower: TrajectoryFollower) -> str | None:
        """Read what was appended; the problem in one line, or None."""
        try:
            self.public.check(follower.path)
            follower.poll()
        except FormatError as exc:
            if exc.problem == "file not found":
                return "no trajectory.jsonl yet"
            return str(exc)
        except NotPublic as exc:
            return str(exc)
        return None

    def _row(self, ep: Episode, flocks: frozenset[str] | None) -> dict:
        with ep.lock:
            problem = self._poll(ep.summary)
            traj = ep.summary.trajectory if problem is None or problem.startswith("no trajectory") else None
            info = self._run_info(ep)
            row: dict[str, Any] = {
                "id": ep.id,
                "system": ep.system,
                "task_id": traj.header.task_id if traj is not None else ep.dir_name,
                "calls": ep.summary.n_calls,
                "detail": "",
            }
            if traj is not None:
                row.update(self._times(ep, traj))
                last = ep.summary.last_call
                if last is not None:
                    row["last"] = {"seq": last.seq, "tool": last.tool, "ok": last.ok, "error": _first_line(last.error)}
                    if last.t is not None:
                        row["last_t"] = last.t
                image = ep.summary.last_image
                if image is not None and _is_capture_name(image):  # a name elsewhere is never asked for
                    row["thumb"] = image
            status, detail = self._status(ep, traj, info, problem, flocks)
            row["status"], row["detail"] = status, detail
            row["budget_s"] = self._budget(ep, traj, info)
        return row

    def _times(self, ep: Episode, traj) -> dict:
        """Wall-clock times (seconds since the epoch) the page turns into elapsed time and budget."""
        out: dict[str, Any] = {}
        start = _unix(traj.header.started_at)
        if start is None:
            return out
        out["server_start"] = start
        offset = ep.summary.clock_offset
        if offset is not None:
            out["clock_start"] = start + offset
        last = ep.summary.last_call
        if last is not None and last.server_t is not None:
            out["last_activity"] = start + last.server_t
        else:
            try:
                out["last_activity"] = ep.trajectory_path.stat().st_mtime
            except OSError:
                pass
        if traj.end is not None:
            out["ended_t"] = traj.end.t if traj.end.t is not None else 0.0
        return out

    def _status(self, ep: Episode, traj, info: Any, problem: str | None, flocks) -> tuple[str, str]:
        if isinstance(info, str):
            return "unreadable", info
        if info is not None:
            return _RUN_STATUS.get(info.ended, "error"), (
                "" if info.ended == "finished" else f"{info.ended}: {_first_line(info.error)}".rstrip(": ")
            )
        if problem is not None and not problem.startswith("no trajectory"):
            return "unreadable", problem
        if traj is not None and traj.end is not None:
            reason = traj.end.reason
            detail = "the client disconnected" if reason == "disconnect" else _first_line(traj.end.message)
            return _END_STATUS.get(reason, "error"), detail
        holder = run_in_progress(ep.run_dir, flocks)
        plan = self._plan_of(ep.run_dir)
        if holder is not None or ((ep.run_dir / ".runner").is_dir() and plan is not None and self._batch_alive(plan)):
            return "running", ("starting" if traj is None else "")
        if traj is None:
            return "interrupted", "no recording"
        return "interrupted", "the recording stopped without an end record"

    def _budget(self, ep: Episode, traj, info: Any) -> float | None:
        """The execution budget in seconds: aw-run's --budget-minutes, else the task's."""
        settings = info.extra.get("settings") if info is not None and not isinstance(info, str) else None
        if isinstance(settings, dict) and isinstance(settings.get("budget_minutes"), int | float):
            return 60.0 * float(settings["budget_minutes"])
        plan = self._plan_of(ep.run_dir)
        if plan is not None and plan.budget_minutes is not None:
            return 60.0 * plan.budget_minutes
        task_dir = self._task_dir(ep, traj) if traj is not None else None
        if task_dir is None:
            return None
        try:
            return 60.0 * self.tasks.task(task_dir).budget_minutes  # task.json alone: no meshes for a row
        except (FormatError, NotPublic, OSError):
            return None

    # ------------------------------------------------------------------ the episode page
    def _task_dir(self, ep: Episode, traj) -> Path | None:
        """The public task directory of the episode's task (given folders first, then the suite
        its aw-run batch names)."""
        plan = self._plan_of(ep.run_dir)
        return self.tasks.find(traj.header.task_id, [Path(plan.suite_dir)] if plan is not None else [])

    def task_view(self, ep: Episode, traj) -> TaskView | str:
        """The episode's public task files, or why there are none."""
        task_dir = self._task_dir(ep, traj)
        if task_dir is None:
            return "no task files found: start aw-view with --tasks SUITE/tasks (or --suite SUITE) to see the scene"
        try:
            return self.tasks.view(task_dir, list(traj.header.part_ids))
        except (FormatError, NotPublic, OSError, ValueError) as exc:
            return f"the task files cannot be shown: {exc}"

    def detail(self, rid: str, start: int) -> tuple[dict, str] | None:
        """The episode page's JSON from call ``start`` on, and its ETag; None for an unknown id."""
        ep = self.episode(rid)
        if ep is None:
            return None
        with self._lock:
            self._detailed[rid] = None
            self._detailed.move_to_end(rid)
            while len(self._detailed) > DETAILED:
                old = self._episodes.get(self._detailed.popitem(last=False)[0])
                if old is not None:
                    old.detail = None
        row = self._row(ep, kernel_flocks())
        with ep.lock:
            detail = self._detail(ep)
            problem = self._poll(detail)
            traj = detail.trajectory
            generation = detail.generation
            out: dict[str, Any] = {"row": row, "generation": generation, "problem": problem}
            if traj is None:
                out["n_calls"] = 0
                return out, f'"{generation}.none.{row["status"]}.{problem}"'
            calls = traj.calls
            start = max(0, min(start, len(calls)))
            part_ids = list(traj.header.part_ids)
            out.update(
                n_calls=len(calls),
                start=start,
                part_ids=part_ids,
                initial_poses=[traj.header.initial_poses[p] for p in part_ids],
                calls=[self._call_row(c, part_ids) for c in calls[start:]],
                end=None
                if traj.end is None
                else {"reason": traj.end.reason, "message": traj.end.message, "t": traj.end.t},
            )
        view = self.task_view(ep, traj)
        if isinstance(view, TaskView):
            out["task"] = {
                "condition": view.task.condition,
                "references": len(view.task.references),
                "prompt": view.task.prompt,
            }
        else:
            out["no_task"] = view
        etag = f'"{generation}.{len(calls)}.{start}.{row["status"]}.{row.get("detail", "")}.{problem}"'
        return out, etag

    @staticmethod
    def _call_row(c, part_ids: list[str]) -> dict:
        args = orjson.dumps(c.args).decode()
        row: dict[str, Any] = {
            "seq": c.seq,
            "t": c.t,
            "server_t": c.server_t,
            "tool": c.tool,
            "args": args if len(args) <= MAX_ARGS_CHARS else args[: MAX_ARGS_CHARS - 3] + "...",
            "ok": c.ok,
        }
        if c.error:
            row["error"] = c.error
        if c.changed:
            row["changed"] = c.changed
        if c.poses is not None:
            row["poses"] = [c.poses[p] for p in part_ids]
        if c.image and _is_capture_name(c.image):  # a name elsewhere is never offered
            row["image"] = c.image
        return row

    def score(self, rid: str, want: int) -> dict | None:
        """With ``--suite``: the episode's scores as known now (:meth:`aw_view.scores.Scorer.report`),
        state ``want``'s ghost included; the scorer works on the rest in the background."""
        import numpy as np

        from aw_view.scores import ScoreRequest

        ep = self.episode(rid)
        if ep is None or self.scorer is None:
            return None
        row = self._row(ep, kernel_flocks())
        with ep.lock:
            detail = self._detail(ep)
            problem = self._poll(detail)
            traj = detail.trajectory
            if traj is None or row["status"] == "unreadable":
                return {"error": problem or row.get("detail") or "no recording yet", "states": {}, "pending": 0}
            part_ids = list(traj.header.part_ids)
            states = [[traj.header.initial_poses[p] for p in part_ids]]
            states += [[c.poses[p] for p in part_ids] for c in traj.calls if c.poses is not None]
        req = ScoreRequest(
            rid,
            ep.system,
            traj.header.task_id,
            ep.run_dir,
            part_ids,
            np.asarray(states, dtype=np.float64),
            ended=row["status"] not in ("running", "queued"),
            want=want if 0 <= want < len(states) else len(states) - 1,
        )
        return self.scorer.report(req)

    def scene(self, rid: str) -> dict | None:
        """The parts of the episode's task as the 3D view draws them, or why there are none."""
        ep = self.episode(rid)
        if ep is None:
            return None
        with ep.lock:
            problem = self._poll(ep.summary)
            traj = ep.summary.trajectory
        if traj is None:
            return {"problem": problem or "no recording yet"}
        view = self.task_view(ep, traj)
        if isinstance(view, str):
            return {"problem": view}
        return {"parts": view.parts}

    def capture(self, rid: str, name: str) -> Path | None:
        """A capture of the episode (``captures/NNNNNN.png``), checked by the gate."""
        ep = self.episode(rid)
        if ep is None or not _is_capture_name(name):
            return None
        try:
            return self.public.check(ep.run_dir / name)
        except NotPublic:
            return None

    def reference(self, rid: str, k: int) -> Path | None:
        """The ``k``-th reference image of the episode's task."""
        ep = self.episode(rid)
        if ep is None:
            return None
        with ep.lock:
            self._poll(ep.summary)
            traj = ep.summary.trajectory
        if traj is None:
            return None
        view = self.task_view(ep, traj)
        if isinstance(view, str) or not 0 <= k < len(view.task.references):
            return None
        try:
            return self.public.check(view.reference(k))
        except NotPublic:
            return None


def _is_capture_name(name: str) -> bool:
    head, _, tail = name.partition("/")
    stem, dot, ext = tail.partition(".")
    return head == "captures" and dot == "." and ext == "png" and stem.isdigit() and stem.isascii() and len(stem) <= 12
