"""Official package + episode archives -> this project's suite and runs layout, for ``aw-score``.

::

    SUITE/manifest.json                 one entry per sample (task id = sample id made file-safe)
    SUITE/targets/<task_id>.json        target poses, eval_divisor = the official divisor,
                                        equivalence_hint = the official groups
    SUITE/eval_points/<task_id>.npz     the official evaluation inputs (1000 points per part)
    RUNS/<system>/<task_id>/trajectory.jsonl, final.json, run.json

The converted suite is for scoring only: it has no ``tasks/`` folder (the package's evaluation
inputs are points, not meshes). Scoring must use the official points, so ``aw-score`` takes a
task's geometry from :func:`suite_geometry` whenever ``eval_points/<task_id>.npz`` exists, and
from the task's meshes otherwise. Every recorded frame of an episode becomes a checkpoint (a
trajectory call line carrying the poses after it).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import orjson

from aw.formats import FinalState, FormatError, PartTarget, RunInfo, SuiteEntry, SuiteManifest, Targets, write_final, write_manifest, write_run_info, write_targets
from aw.formats.suite import suite_paths
from aw.formats.trajectory import TrajectoryCall, TrajectoryEnd, TrajectoryHeader
from aw.official.episode import Episode, read_episode
from aw.official.package import EvalInputs, OfficialPackage, read_eval_inputs, write_eval_inputs

__all__ = ["task_id_for_sample", "eval_points_path", "suite_eval_inputs", "suite_geometry", "convert_package",
           "episode_records", "write_episode_run", "find_archives", "convert"]

_END = {"finished": "finished", "complete": "finished", "completed": "finished", "done": "finished", "success": "finished",
        "timeout": "timeout", "time_limit": "timeout", "error": "error", "failed": "error", "disconnect": "disconnect",
        "interrupted": "interrupted", "cancelled": "interrupted", "canceled": "interrupted"}
_RUN_END = {"finished": "finished", "timeout": "timeout", "error": "error", "disconnect": "error", "interrupted": "error"}


def task_id_for_sample(sample_id: str) -> str:
    from aw.prepare.writer import safe_id

    return safe_id(sample_id)


def eval_points_path(suite_dir: str | Path, task_id: str) -> Path:
    return Path(suite_dir) / "eval_points" / f"{task_id}.npz"


def suite_eval_inputs(suite_dir: str | Path, task_id: str) -> EvalInputs | None:
    """The official evaluation inputs stored with a converted suite, or None for native tasks."""
    path = eval_points_path(suite_dir, task_id)
    return read_eval_inputs(path, task_id) if path.is_file() else None


def suite_geometry(suite_dir: str | Path, task_id: str):
    """``aw_eval.TaskGeometry`` from the official points of a converted task, or None when the
    task has none (then score it from its meshes as usual)."""
    inputs = suite_eval_inputs(suite_dir, task_id)
    return None if inputs is None else inputs.task_geometry()


def convert_package(package: str | Path | OfficialPackage, suite_out: str | Path, force: bool = False) -> SuiteManifest:
    """Write the scoring suite of an official package (see the module doc)."""
    pkg = package if isinstance(package, OfficialPackage) else OfficialPackage(package)
    out = Path(suite_out)
    existing = [out / n for n in ("manifest.json", "targets", "eval_points", "tasks") if (out / n).exists()]
    if existing and not force:
        raise FileExistsError(f"{out}: already holds a suite ({', '.join(p.name for p in existing)}); pass force=True to replace it")
    for p in existing:
        shutil.rmtree(p) if p.is_dir() else p.unlink()
    (out / "targets").mkdir(parents=True, exist_ok=True)
    (out / "eval_points").mkdir(parents=True, exist_ok=True)
    entries, seen = [], {}
    for sid, sample in pkg.samples.items():
        tid = task_id_for_sample(sid)
        if tid in seen:
            raise FormatError(pkg.root / "manifest.json", f"samples {seen[tid]!r} and {sid!r} map to the same task id {tid!r}")
        seen[tid] = sid
        inputs = pkg.eval_inputs(sid)
        write_eval_inputs(eval_points_path(out, tid), inputs)
        hint = [g for g in inputs.groups if len(g) > 1] or None
        targets = Targets(
            task_id=tid,
            parts={p: PartTarget(pose=[float(x) for x in pose]) for p, pose in zip(inputs.part_ids, inputs.target_poses)},
            equivalence_hint=hint,
            scale=1.0,
            eval_divisor=inputs.divisor,
        )
        write_targets(suite_paths(out, tid)[1], targets)
        entries.append(SuiteEntry(task_id=tid, source=sample.source, condition=sample.condition, object_id=sample.object_id,
                                  category=sample.category, n_parts=inputs.n_parts, weight=sample.weight))
    manifest = SuiteManifest(name=f"official-{pkg.root.resolve().name}", generator="aw.official", tasks=entries)
    write_manifest(out, manifest)
    return manifest


def _pose_dict(part_ids: list[str], poses: np.ndarray) -> dict[str, list[float]]:
    return {p: [float(x) for x in pose] for p, pose in zip(part_ids, poses)}


def episode_records(ep: Episode, task_id: str, system: str, part_ids: list[str] | None = None):
    """The native trajectory records ``(header, calls, end)`` of an episode, poses in
    ``part_ids`` order (default: the episode's)."""
    ids = list(part_ids or ep.part_ids)
    if sorted(ids) != sorted(ep.part_ids):
        raise FormatError(ep.path, f"episode parts {sorted(ep.part_ids)} differ from the sample's {sorted(ids)}")
    order = [ep.part_ids.index(p) for p in ids]
    poses = ep.poses[:, order]
    header = TrajectoryHeader(task_id=task_id, system=system, started_at=ep.started_at or "1970-01-01T00:00:00Z",
                              part_ids=ids, initial_poses=_pose_dict(ids, poses[0]))
    frames_by_call: dict[int, list[int]] = {}
    loose: list[int] = []
    for fr in ep.frames[1:]:
        if fr.call is not None and ep.calls:
            frames_by_call.setdefault(fr.call, []).append(fr.index)
        else:
            loose.append(fr.index)
    items: list[tuple[float, int, str, object]] = []
    for k, c in enumerate(ep.calls):
        items.append((c.t, k, "call", c))
    for k, f in enumerate(loose):
        items.append((ep.frames[f].t, len(ep.calls) + k, "frame", f))
    items.sort(key=lambda it: (it[0], it[1]))

    calls: list[TrajectoryCall] = []
    prev = poses[0]
    seq = 0

    def record(t, tool, args, ok, error, frame):
        nonlocal seq, prev
        seq += 1
        rec_poses, changed = None, []
        if frame is not None:
            cur = poses[frame]
            changed = [p for p, a, b in zip(ids, cur, prev) if not np.array_equal(a, b)]
            rec_poses = _pose_dict(ids, cur)
            prev = cur
        calls.append(TrajectoryCall(seq=seq, t=float(t), tool=tool, args=args, ok=ok, error=error, changed=changed, poses=rec_poses))

    for t, _, kind, obj in items:
        if kind == "call":
            frames = frames_by_call.get(obj.seq, [])
            record(t, obj.tool, obj.args, obj.ok, obj.error, frames[0] if frames else None)
            for f in frames[1:]:  # several states recorded for one call
                record(ep.frames[f].t, "state", {}, True, None, f)
        else:
            record(t, "state", {}, True, None, obj)

    end = None
    ev = ep.end_event()
    if ev is not None:
        raw = str(ev.get("reason", "finished")).lower()
        reason = _END.get(raw, "finished")
        t_end = ev.get("t")
        t_end = float(t_end) if isinstance(t_end, (int, float)) and not isinstance(t_end, bool) else ep.frames[-1].t
        end = TrajectoryEnd(reason=reason, t=t_end, message="" if raw in _END else f"official end reason: {raw}",
                            poses=_pose_dict(ids, poses[-1]))
    return header, calls, end


def _dump(rec) -> bytes:
    return orjson.dumps(rec.model_dump(mode="json", exclude_none=True))


def write_episode_run(ep: Episode, runs_out: str | Path, system: str | None = None, task_id: str | None = None,
                      part_ids: list[str] | None = None, force: bool = False) -> Path:
    """Write ``RUNS/<system>/<task_id>/`` (trajectory.jsonl, final.json, run.json) for an episode."""
    system = system or ep.system or "official"
    task_id = task_id or task_id_for_sample(ep.sample_id)
    run_dir = Path(runs_out) / system / task_id
    traj = run_dir / "trajectory.jsonl"
    if traj.exists() and not force:
        raise FileExistsError(f"{traj}: already exists; pass force=True to replace it")
    run_dir.mkdir(parents=True, exist_ok=True)
    header, calls, end = episode_records(ep, task_id, system, part_ids)
    tmp = traj.with_suffix(".jsonl.tmp")
    with open(tmp, "wb") as fh:
        for rec in [header, *calls, *([end] if end is not None else [])]:
            fh.write(_dump(rec) + b"\n")
    os.replace(tmp, traj)
    last_poses = next((c.poses for c in reversed(calls) if c.poses is not None), header.initial_poses)
    final_poses = end.poses if end is not None else last_poses
    reason = end.reason if end is not None else "interrupted"
    write_final(run_dir / "final.json", FinalState(task_id=task_id, reason=reason, poses=final_poses))
    info = RunInfo(
        system=system, task_id=task_id, started_at=ep.started_at, wall_seconds=max(0.0, end.t if end else ep.frames[-1].t),
        mcp_calls=len(ep.calls), ended=_RUN_END[reason], error=end.message if end is not None and reason == "error" else None,
        extra={"official_archive": str(ep.path), "sample_id": ep.sample_id, "frames": len(ep.frames)},
    )
    write_run_info(run_dir / "run.json", info)
    return run_dir


def find_archives(root: str | Path) -> list[Path]:
    """Every ``*.episode.zip`` below ``root`` (or ``root`` itself), sorted."""
    root = Path(root)
    if root.is_file():
        return [root]
    if not root.is_dir():
        raise FormatError(root, "episode folder not found")
    return sorted(root.rglob("*.episode.zip"))


def convert(package: str | Path, episodes: str | Path | Iterable[str | Path], suite_out: str | Path, runs_out: str | Path,
            system: str | None = None, force: bool = False) -> tuple[SuiteManifest, list[Path]]:
    """Convert a package and its episode archives. An archive's system is ``system``, else its
    manifest's ``system``, else the name of the folder above its sample folder."""
    pkg = OfficialPackage(package)
    manifest = convert_package(pkg, suite_out, force=force)
    archives = find_archives(episodes) if isinstance(episodes, (str, Path)) else [Path(p) for p in episodes]
    runs = []
    for arc in archives:
        ep = read_episode(arc)
        if ep.sample_id not in pkg.samples:
            raise FormatError(arc, f"manifest.json: sample_id {ep.sample_id!r} is not in the package")
        inputs = pkg.eval_inputs(ep.sample_id)
        ep = read_episode(arc, inputs.part_ids) if ep.part_ids != inputs.part_ids else ep
        sys_name = system or ep.system or arc.parent.parent.name or "official"
        runs.append(write_episode_run(ep, runs_out, sys_name, task_id_for_sample(ep.sample_id), inputs.part_ids, force=force))
    return manifest, runs
