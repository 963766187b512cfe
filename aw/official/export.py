"""A run recorded here (``trajectory.jsonl`` + ``final.json`` by ``aw-serve``/``aw-run``) as an
official episode archive, so the official tools can read and score it.

The archive continues an initial (setup) archive: the sample's own, for tasks converted from the
official package (``SUITE/official/<task_id>.episode.zip``), or one made from the task's meshes
(:func:`aw.official.world.setup_archive`) for this project's tasks. Then:

- each recorded call with a tool name of the official surface becomes a ``calls.jsonl`` row:
  ``timestamp`` = the run's ``started_at`` + the call's ``t``, part ids in its arguments as
  object ids (``part-000k``), status, error, and a ``request``/``complete`` event pair;
- each call that recorded poses, and each successful edit or camera move, appends a state (the
  moved parts at rest, everything else of the previous state kept), and its call's
  ``state_index`` names it; a change of the closing poses that no call recorded appends one
  more state;
- a completed call gets the result the official runtime returns (3DWebAgent
  ``schema/results.schema.json``), computed from the state it ran in: edits ``{status, index,
  physics}``, ``start_episode`` ``{status: "active"}``, the catalogue, scene and state queries,
  and a capture with its kept PNG as an observation (a capture whose image was not kept is left
  out, as a result without its image is not valid);
- the manifest is the initial one with ``lifecycle`` ``active`` (``setup`` when nothing was
  recorded); no trace frames are written (the project does not record intermediate poses).

Tool calls outside the official surface and group membership are not carried over (the
trajectory does not record groups): frames keep the initial frame's groups, and query results
report the state's poses with zero velocities and no contacts (physics is disabled in the
benchmark's episodes).
"""

from __future__ import annotations

import copy
import hashlib
from datetime import timedelta
from pathlib import Path

import numpy as np

from aw.formats import FormatError, read_final, read_trajectory
from aw.formats.agreement import closing_contradiction
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


def export_trajectory(
    traj: Trajectory,
    initial: EpisodeArchive,
    out: str | Path,
    final_poses: dict[str, list[float]] | None = None,
    run_dir: Path | None = None,
    trust_final: bool = False,
) -> EpisodeArchive:
    """Write ``traj`` (recorded from ``initial``'s initial state) as an official archive at
    ``out``; captures are looked up below ``run_dir`` (default: the trajectory's folder).

    A closing state (``final_poses``, else the end record's) that contradicts the state the calls
    leave (:func:`aw.formats.agreement.closing_contradiction`, the rule by which aw-score flags the
    run and scores the calls' state) is refused with an :class:`ExportError`, unless
    ``trust_final``: then it is exported as one more state, as it was recorded."""
    run_dir = Path(run_dir) if run_dir is not None else Path(traj.path).parent
    out = Path(out)
    where = traj.path
    gap = closing_contradiction(traj, final_poses)
    if gap and not trust_final:
        raise ExportError(
            where,
            f"its closing state ({'final.json' if final_poses is not None else 'the end record'}) contradicts the "
            f"state its calls leave (parts {gap}): edits that no call records; aw-score flags this run and scores "
            "the calls' state. Pass --trust-final to export the closing state anyway",
        )
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
    ep = EpisodeArchive(
        out, manifest, {n: d for n, d in initial.files.items() if n.startswith("world/")}, initial.initial
    )
    current = start.copy()
    view = _StateView(model, ep)
    object_ids = dict(zip(part_ids, names, strict=True))

    def record_state(poses: dict[str, list[float]] | None, camera: CameraState | None) -> int:
        target = current if poses is None else np.array([poses[p] for p in part_ids], dtype=float)
        moved = {k: target[k] for k in range(len(part_ids)) if not np.array_equal(target[k], current[k])}
        cam = official_camera(camera) if camera is not None else None
        frame = append_state(model, ep, moved, camera=cam)
        current[:] = target
        view.update()
        return frame.index

    for call in traj.calls:
        before = len(ep.states)
        mutation = call.ok and call.tool in _MUTATIONS
        index = record_state(call.poses, call.camera) if call.poses is not None or mutation else None
        if call.tool not in TOOL_NAMES:
            continue
        row = {
            "name": call.tool,
            "arguments": _object_arguments(call.args, object_ids),
            "actor": "agent",
            "producer": dict(PRODUCER),
            "timestamp": iso_timestamp(t0 + timedelta(seconds=max(call.t or 0.0, 0.0))),
            "before_index": before,
            "state_index": len(ep.states),
            "trace_start": 0,
            "trace_end": 0,
            "sim_start": 0.0,
            "sim_end": 0.0,
            "steps": 0,
            "status": "completed" if call.ok else "error",
        }
        if not call.ok:
            row.update(error=call.error or "error", error_code="invalid_argument")
        else:
            result = _result(call, index, view, run_dir)
            if result is None:
                continue
            row["result"] = result
        _append_call(ep, row)
    closing = final_poses if final_poses is not None else (traj.end.poses if traj.end is not None else None)
    if closing is not None and not np.array_equal(np.array([closing[p] for p in part_ids], dtype=float), current):
        record_state(closing, None)
    if ep.calls or ep.states:
        manifest["lifecycle"] = "active"
        manifest["originTime"] = float(ep.initial.integration[0])
    return write_archive(ep, out)


_MUTATIONS = frozenset(
    {"translate_objects", "rotate_objects", "set_object_pose", "group_objects", "ungroup_objects", "move_camera"}
)


class _StateView:
    """MuJoCo data at the archive's current (last) state, for query results."""

    def __init__(self, model, ep: EpisodeArchive):
        import mujoco

        self.model, self.ep, self.data = model, ep, mujoco.MjData(model)
        self.update()

    def update(self) -> None:
        import mujoco

        mujoco.mj_setState(self.model, self.data, self.ep.final_state().integration, self.ep.manifest["stateSpec"])
        mujoco.mj_forward(self.model, self.data)

    def object(self, object_id: str) -> dict | None:
        """What ``get_object`` returns of a catalogue object (3DWebAgent ``episode_runtime.py``)."""
        import mujoco

        info = next((o for o in self.ep.manifest["objects"] if o["id"] == object_id), None)
        if info is None:
            return None
        m, d = self.model, self.data
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, object_id)
        joint = m.body_jntadr[b]
        return dict(
            info,
            position=d.xpos[b].tolist(),
            quaternion=d.xquat[b].tolist(),
            velocity=d.cvel[b].tolist(),
            mass=float(m.body_mass[b]),
            movable=bool(m.body_parentid[b] == 0 and m.body_jntnum[b] == 1 and m.jnt_type[joint] == 0),
            inertia=m.body_inertia[b].tolist(),
            centerOfMass=m.body_ipos[b].tolist(),
            inertiaQuaternion=m.body_iquat[b].tolist(),
            geometries=[
                {
                    "index": g,
                    "type": int(m.geom_type[g]),
                    "size": m.geom_size[g].tolist(),
                    "friction": m.geom_friction[g].tolist(),
                    "condim": int(m.geom_condim[g]),
                    "collidable": bool(m.geom_contype[g] or m.geom_conaffinity[g]),
                }
                for g in range(m.ngeom)
                if m.geom_bodyid[g] == b
            ],
        )

    def frame(self) -> dict:
        return self.ep.final_state().record


def _object_arguments(args: dict, object_ids: dict[str, str]) -> dict:
    """A call's arguments with this project's part ids turned into the archive's object ids."""
    out = dict(args)
    if isinstance(out.get("id"), str):
        out["id"] = object_ids.get(out["id"], out["id"])
    if isinstance(out.get("ids"), list):
        out["ids"] = [object_ids.get(i, i) if isinstance(i, str) else i for i in out["ids"]]
    return out


def _result(call, index: int | None, view: _StateView, run_dir: Path) -> dict | None:
    """The official runtime's result of a completed call, or None when it cannot be rebuilt."""
    from aw.webmcp import RENDER

    m, frame = view.ep.manifest, view.frame()
    name = call.tool
    if name in _MUTATIONS:
        return {"status": "completed", "physics": "disabled", "index": index}
    if name == "start_episode":
        return {"status": "active"}
    if name == "list_objects":
        return {"objects": copy.deepcopy(m["objects"]), "groups": copy.deepcopy(frame["groups"])}
    if name == "get_scene":
        return {
            "name": m["name"],
            "units": m["units"],
            "up": "Z",
            "quaternion": "wxyz",
            "runtime": copy.deepcopy(m["runtime"]),
            "objects": copy.deepcopy(m["objects"]),
        }
    if name == "get_object":
        object_ids = dict(
            zip([o["name"][len("Part ") :] for o in m["objects"]], [o["id"] for o in m["objects"]], strict=True)
        )
        return view.object(object_ids.get(call.args.get("id"), call.args.get("id")))
    if name == "get_state":
        return {
            "index": len(view.ep.states),
            "units": m["units"],
            "objects": [view.object(o["id"]) for o in m["objects"]],
            "groups": copy.deepcopy(frame["groups"]),
            "camera": copy.deepcopy(frame["camera"]),
            "contacts": [],
        }
    if name == "capture_scene" and call.image:
        path = run_dir / call.image
        if not path.is_file():
            return None
        png = path.read_bytes()
        key = hashlib.sha256(png).hexdigest() + ".png"
        view.ep.files["observations/" + key] = png
        camera = official_camera(call.camera) if call.camera is not None else copy.deepcopy(frame["camera"])
        return {
            "content": [{"type": "image", "mimeType": "image/png", "observation": key}],
            "camera": camera,
            "render": dict(RENDER),
        }
    return None


def _append_call(ep: EpisodeArchive, row: dict) -> None:
    n = len(ep.calls)
    ep.calls.append({"index": n, "id": f"call-{n}", **row})
    for kind in ("request", "complete"):
        ep.events.append(
            {
                "index": len(ep.events),
                "call_id": f"call-{n}",
                "kind": kind,
                "timestamp": row["timestamp"],
                "sim_time": 0.0,
            }
        )


def export_run(
    run_dir: str | Path, initial: str | Path | EpisodeArchive, out: str | Path, trust_final: bool = False
) -> EpisodeArchive:
    """Export ``RUN_DIR/trajectory.jsonl`` (and ``final.json`` when present) as an official
    archive continuing ``initial``."""
    run_dir = Path(run_dir)
    traj = read_trajectory(run_dir / "trajectory.jsonl")
    final = read_final(run_dir / "final.json").poses if (run_dir / "final.json").is_file() else None
    init = initial if isinstance(initial, EpisodeArchive) else read_archive(initial)
    return export_trajectory(traj, init, out, final, run_dir, trust_final)


def task_setup_archive(
    task_dir: str | Path, initial_poses: dict[str, list[float]], path: str | Path = "<setup>"
) -> EpisodeArchive:
    """The setup archive of one of this project's tasks: its meshes (in their baked frame) at
    the given initial poses, parts in sorted id order."""
    from aw.formats import read_task
    from aw.meshes import load_task_meshes

    task = read_task(task_dir)
    meshes = dict(zip(task.part_ids, load_task_meshes(task), strict=True))
    ids = sorted(initial_poses)
    if set(ids) - set(meshes):
        raise FormatError(Path(task_dir), f"the run names parts {sorted(set(ids) - set(meshes))} the task lacks")
    return setup_archive(
        ids,
        [(meshes[p].vertices, meshes[p].faces) for p in ids],
        np.array([initial_poses[p] for p in ids], dtype=float),
        name=task.task_id,
        task=task.prompt,
        path=path,
    )


def export_task_run(
    run_dir: str | Path, task_dir: str | Path, out: str | Path, trust_final: bool = False
) -> EpisodeArchive:
    """Export a run of one of this project's tasks (no official initial archive)."""
    run_dir = Path(run_dir)
    traj = read_trajectory(run_dir / "trajectory.jsonl")
    final = read_final(run_dir / "final.json").poses if (run_dir / "final.json").is_file() else None
    setup = task_setup_archive(task_dir, dict(traj.header.initial_poses))
    return export_trajectory(traj, setup, out, final, run_dir, trust_final)
