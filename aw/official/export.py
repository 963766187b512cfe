"""A run recorded here (``trajectory.jsonl`` + ``final.json`` by ``aw-serve``/``aw-run``) as an
official episode archive, so the official tools can read and score it.

The archive continues an initial (setup) archive: the sample's own, for tasks converted from the
official package (``SUITE/official/<task_id>.episode.zip``), or one made from the task's meshes
(:func:`aw.official.world.setup_archive`) for this project's tasks. Then:

- each recorded call with a tool name of the official surface becomes a ``calls.jsonl`` row:
  ``timestamp`` = the run's ``started_at`` + the call's ``t``, status, error, and a
  ``request``/``complete`` event pair;
- each call that recorded poses appends a state (the moved parts at rest, everything else of
  the previous state kept), and its call's ``state_index`` names it; a state change of the
  closing poses that no call recorded appends one more state;
- the manifest is the initial one with ``lifecycle`` ``active`` (``setup`` when nothing was
  recorded); no trace frames are written (the project does not record intermediate poses).

Tool calls outside the official surface and group membership are not carried over (the
trajectory does not record groups): frames keep the initial frame's groups.
"""

from __future__ import annotations

import copy
from datetime import timedelta
from pathlib import Path

import numpy as np

from aw.formats import FormatError, read_final, read_trajectory
from aw.formats.trajectory import CameraState, Trajectory
from aw.official.archive import TOOL_NAMES, EpisodeArchive, iso_timestamp, parse_timestamp, read_archive, write_archive
from aw.official.episode import catalogue_part_ids, load_model, state_poses
from aw.official.errors import ExportError
from aw.official.world import PRODUCER, append_state, setup_archive

__all__ = ["official_camera", "export_trajectory", "export_run", "task_setup_archive", "export_task_run"]

_POSE_TOLERANCE = 1e-9  # the run's initial poses against the archive's initial state


def official_camera(camera: CameraState) -> dict[str, list[float]]:
    """``{position, target}`` of this project's orbit camera."""
    from aw.camera import Camera

    cam = Camera(target=np.asarray(camera.target, float), yaw=camera.yaw, pitch=camera.pitch, distance=camera.distance)
    return {"position": [float(x) for x in cam.position], "target": [float(x) for x in cam.target]}


def export_trajectory(traj: Trajectory, initial: EpisodeArchive, out: str | Path,
                      final_poses: dict[str, list[float]] | None = None) -> EpisodeArchive:
    """Write ``traj`` (recorded from ``initial``'s initial state) as an official archive at ``out``."""
    out = Path(out)
    where = traj.path
    part_ids = catalogue_part_ids(initial)
    if sorted(traj.header.part_ids) != part_ids:
        raise ExportError(where, f"the run's parts {sorted(traj.header.part_ids)} are not the archive's {part_ids}")
    model = load_model(initial)
    names = [o["id"] for o in initial.manifest["objects"]]
    start = state_poses(model, initial, [initial.initial], names)[0]
    given = np.array([traj.header.initial_poses[p] for p in part_ids], dtype=float)
    if not np.allclose(given, start, atol=_POSE_TOLERANCE, rtol=0):
        raise ExportError(where, f"the run's initial poses differ from the initial state of {initial.path}")
    t0 = parse_timestamp(traj.header.started_at)
    if t0 is None:
        raise ExportError(where, f"header started_at {traj.header.started_at!r} is not an ISO-8601 time")
    manifest = copy.deepcopy(initial.manifest)
    manifest.pop("end", None)
    ep = EpisodeArchive(out, manifest, {n: d for n, d in initial.files.items() if n.startswith("world/")}, initial.initial)
    current = start.copy()

    def record_state(poses: dict[str, list[float]], camera: CameraState | None) -> int | None:
        target = np.array([poses[p] for p in part_ids], dtype=float)
        moved = {k: target[k] for k in range(len(part_ids)) if not np.array_equal(target[k], current[k])}
        cam = official_camera(camera) if camera is not None else None
        frame = append_state(model, ep, moved, camera=cam)
        current[:] = target
        return frame.index

    for call in traj.calls:
        before = len(ep.states)
        index = record_state(call.poses, call.camera) if call.poses is not None else None
        if call.tool not in TOOL_NAMES:
            continue
        n = len(ep.calls)
        stamp = iso_timestamp(t0 + timedelta(seconds=max(call.t, 0.0)))
        row = {"index": n, "id": f"call-{n}", "name": call.tool, "arguments": call.args, "actor": "agent",
               "producer": dict(PRODUCER), "timestamp": stamp, "before_index": before, "state_index": len(ep.states),
               "trace_start": 0, "trace_end": 0, "sim_start": 0.0, "sim_end": 0.0, "steps": 0,
               "status": "completed" if call.ok else "error"}
        if not call.ok:
            row.update(error=call.error or "error", error_code="invalid_argument")
        elif index is not None:
            row["result"] = {"status": "completed", "index": index}
        ep.calls.append(row)
        for kind in ("request", "complete"):
            ep.events.append({"index": len(ep.events), "call_id": row["id"], "kind": kind, "timestamp": stamp, "sim_time": 0.0})
    closing = final_poses if final_poses is not None else (traj.end.poses if traj.end is not None else None)
    if closing is not None and not np.array_equal(np.array([closing[p] for p in part_ids], dtype=float), current):
        record_state(closing, None)
    if ep.calls or ep.states:
        manifest["lifecycle"] = "active"
        manifest["originTime"] = float(ep.initial.integration[0])
    return write_archive(ep, out)


def export_run(run_dir: str | Path, initial: str | Path | EpisodeArchive, out: str | Path) -> EpisodeArchive:
    """Export ``RUN_DIR/trajectory.jsonl`` (and ``final.json`` when present) as an official
    archive continuing ``initial``."""
    run_dir = Path(run_dir)
    traj = read_trajectory(run_dir / "trajectory.jsonl")
    final = read_final(run_dir / "final.json").poses if (run_dir / "final.json").is_file() else None
    init = initial if isinstance(initial, EpisodeArchive) else read_archive(initial)
    return export_trajectory(traj, init, out, final)


def task_setup_archive(task_dir: str | Path, initial_poses: dict[str, list[float]], path: str | Path = "<setup>") -> EpisodeArchive:
    """The setup archive of one of this project's tasks: its meshes (in their baked frame) at
    the given initial poses, parts in sorted id order."""
    from aw.formats import read_task
    from aw.meshes import load_task_meshes

    task = read_task(task_dir)
    meshes = dict(zip(task.part_ids, load_task_meshes(task)))
    ids = sorted(initial_poses)
    if set(ids) - set(meshes):
        raise FormatError(Path(task_dir), f"the run names parts {sorted(set(ids) - set(meshes))} the task lacks")
    return setup_archive(ids, [(meshes[p].vertices, meshes[p].faces) for p in ids],
                         np.array([initial_poses[p] for p in ids], dtype=float), name=task.task_id,
                         task=task.prompt, path=path)


def export_task_run(run_dir: str | Path, task_dir: str | Path, out: str | Path) -> EpisodeArchive:
    """Export a run of one of this project's tasks (no official initial archive)."""
    run_dir = Path(run_dir)
    traj = read_trajectory(run_dir / "trajectory.jsonl")
    final = read_final(run_dir / "final.json").poses if (run_dir / "final.json").is_file() else None
    return export_trajectory(traj, task_setup_archive(task_dir, dict(traj.header.initial_poses)), out, final)
