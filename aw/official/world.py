"""Setup archives (the initial episode of a sample) made from part meshes, in the official layout,
and new states recorded on top of an archive's last one.

The world follows assembly-world-agent ``episodes.py``: an MJCF ``world/model.xml`` with one
mesh asset ``world/meshes/part-000k.obj`` per part (OBJ, vertices written with 17 significant
digits), and per part a top-level body ``part-000k`` placed at the part's initial pose, with a
free joint, unit mass, diagonal inertia 0.1 and no contacts; zero gravity, contacts and
constraints disabled, time step 0.002. The state layout is ``mjSTATE_INTEGRATION``.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np

from aw.official.archive import CONTRACT, ENGINE, FORMAT, VERSION, EpisodeArchive, Frame
from aw.official.episode import _bodies, _free_qpos_address, body_name, expected_objects, require_engine
from aw.official.errors import ExportError

__all__ = ["PRODUCER", "world_files", "setup_archive", "camera_for", "append_state"]

# Who wrote an archive made here (manifest.producer and each recorded call's producer).
PRODUCER = {"backend": "native", "engine": ENGINE, "implementation": "assemblyworld-aw", "language": "python"}
_RGBA = "0.70 0.73 0.79 1"


def _number(v: float) -> str:
    return format(float(v), ".17g")


def _obj(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(vertices) == 3:  # MuJoCo needs four vertices: add the centroid, fan the triangle to it
        vertices = np.vstack([vertices, vertices.mean(axis=0)])
        faces = np.array([[a, b, 3] for f in faces for a, b in zip(f, np.roll(f, -1), strict=True)])
    lines = ["v " + " ".join(_number(x) for x in v) for v in vertices]
    lines += ["f " + " ".join(str(int(i) + 1) for i in f) for f in faces]
    return ("\n".join(lines) + "\n").encode()


def world_files(meshes: Sequence[tuple[np.ndarray, np.ndarray]], initial_poses: np.ndarray) -> dict[str, bytes]:
    """``world/`` members for parts ``k = 0..P-1``: meshes ``(vertices (V, 3), faces (F, 3))``
    in the part's own frame, placed at ``initial_poses (P, 7)`` ``[x, y, z, qw, qx, qy, qz]``."""
    root = ET.Element("mujoco", model="assembly-task")
    ET.SubElement(root, "compiler", angle="radian", autolimits="true")
    option = ET.SubElement(root, "option", timestep="0.002", gravity="0 0 0")
    ET.SubElement(option, "flag", contact="disable", constraint="disable", autoreset="disable")
    asset, world = ET.SubElement(root, "asset"), ET.SubElement(root, "worldbody")
    files = {}
    for k, ((vertices, faces), pose) in enumerate(
        zip(meshes, np.asarray(initial_poses, dtype=np.float64), strict=True)
    ):
        name = body_name(k)
        files[f"world/meshes/{name}.obj"] = _obj(vertices, faces)
        ET.SubElement(asset, "mesh", name=name, file=f"meshes/{name}.obj", inertia="shell")
        body = ET.SubElement(
            world,
            "body",
            name=name,
            pos=" ".join(_number(x) for x in pose[:3]),
            quat=" ".join(_number(x) for x in pose[3:]),
        )
        ET.SubElement(body, "freejoint")
        ET.SubElement(body, "inertial", pos="0 0 0", mass="1", diaginertia="0.1 0.1 0.1")
        ET.SubElement(body, "geom", type="mesh", mesh=name, contype="0", conaffinity="0", rgba=_RGBA)
    ET.indent(root)
    files["world/model.xml"] = ET.tostring(root, encoding="utf-8")
    return files


def camera_for(meshes: Sequence[tuple[np.ndarray, np.ndarray]], poses: np.ndarray) -> dict[str, list[float]]:
    """A default camera ``{position, target}`` looking at the placed parts' bounding box."""
    from aw.camera import Camera
    from aw.pose import apply_pose

    points = np.concatenate(
        [apply_pose(np.asarray(p, float), np.asarray(v, float)) for (v, _), p in zip(meshes, poses, strict=True)]
    )
    cam = Camera.framing(points.min(axis=0), points.max(axis=0))
    return {"position": [float(x) for x in cam.position], "target": [float(x) for x in cam.target]}


def setup_archive(
    part_ids: list[str],
    meshes: Sequence[tuple[np.ndarray, np.ndarray]],
    initial_poses: np.ndarray,
    *,
    name: str,
    task: str = "",
    camera: dict[str, list[float]] | None = None,
    path: str | Path = "<setup>",
) -> EpisodeArchive:
    """The initial (``setup``) episode of parts ``part_ids`` (sorted, distinct) with their
    meshes and initial poses ``(P, 7)``. Its id is derived from its world and name."""
    import mujoco

    from aw.webmcp import ENABLED_TOOLS, PHYSICS

    require_engine()
    if list(part_ids) != sorted(set(part_ids)) or not part_ids:
        raise ExportError(path, "part ids must be non-empty, sorted and distinct")
    if len(meshes) != len(part_ids) or np.shape(initial_poses) != (len(part_ids), 7):
        raise ExportError(path, f"need one mesh and one pose (7 numbers) per part ({len(part_ids)})")
    files = world_files(meshes, initial_poses)
    try:
        model = mujoco.MjModel.from_xml_string(
            files["world/model.xml"].decode(),
            {k[len("world/") :]: v for k, v in files.items() if k != "world/model.xml"},
        )
    except ValueError as exc:
        raise ExportError(path, f"MuJoCo cannot compile the parts' world ({exc})") from None
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    spec = int(mujoco.mjtState.mjSTATE_INTEGRATION)
    state = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, state, spec)
    digest = hashlib.sha256(
        name.encode() + b"".join(hashlib.sha256(files[k]).digest() for k in sorted(files))
    ).hexdigest()
    manifest = {
        "format": FORMAT,
        "version": VERSION,
        "id": f"aw-{digest}",
        "contract": CONTRACT,
        "engine": ENGINE,
        "name": name,
        "units": "normalized",
        "stateSpec": spec,
        "stateSize": int(state.size),
        "lifecycle": "setup",
        "originTime": 0,
        "requiredCapabilities": ["state"],
        "producer": dict(PRODUCER),
        "runtime": {"enabledTools": list(ENABLED_TOOLS), "physics": dict(PHYSICS)},
        "objects": expected_objects(list(part_ids)),
        "hashes": {},
        **({"task": task} if task else {}),
    }
    frame = {"index": 0, "camera": camera or camera_for(meshes, initial_poses), "groups": [], "groupCounter": 0}
    return EpisodeArchive(Path(path), manifest, files, Frame("initial", frame, state))


def append_state(
    model, ep: EpisodeArchive, poses: dict[int, np.ndarray], camera: dict | None = None, groups: list | None = None
) -> Frame:
    """Record a new state on top of ``ep``'s last one: parts ``k`` in ``poses`` (``(7,)`` each)
    moved there at rest, everything else of the state kept bit for bit. Returns the new frame
    (appended to ``ep.states``)."""
    import mujoco

    spec = ep.manifest["stateSpec"]
    last = ep.final_state()
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, last.integration, spec)
    for k, pose in poses.items():
        body = _bodies(model, [body_name(k)], ep.path)[0]
        adr = _free_qpos_address(model, body)
        if adr is None:
            raise ExportError(ep.path, f"body {body_name(k)} is not a top-level body on a free joint")
        data.qpos[adr : adr + 7] = pose
        dof = int(model.jnt_dofadr[model.body_jntadr[body]])
        data.qvel[dof : dof + 6] = 0.0
    state = np.empty(ep.manifest["stateSize"])
    mujoco.mj_getState(model, data, state, spec)
    record = {
        "index": len(ep.states) + 1,
        "camera": camera or last.record["camera"],
        "groups": last.record["groups"] if groups is None else groups,
        "groupCounter": last.record["groupCounter"],
    }
    frame = Frame("state", record, state)
    ep.states.append(frame)
    return frame
