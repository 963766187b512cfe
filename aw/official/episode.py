"""Official episodes restored with MuJoCo: the world, part bodies and the poses of each state.

The benchmark's worlds give part ``part_ids[k]`` (part ids sorted) the body ``part-%04d`` of
``k + 1`` with one free joint, and the catalogue entry ``{"id": "part-000k", "name": "Part
<part id>", "type": "rigid", "collisionEnabled": false}`` (assembly-world-bench ``poses.py``;
assembly-world-agent ``episodes.py``). A state is a MuJoCo ``mj_getState`` vector of the
manifest's ``stateSpec``; restoring one is ``mj_setState`` then ``mj_forward``, after which a
part's pose ``[x, y, z, qw, qx, qy, qz]`` is its body's world position and orientation: the
transform of the part's points in ``evaluation.json`` (its body frame) into the scene.

A final archive is scored only as a continuation of its sample's initial archive: same
catalogue, identity, producer, state layout and world (:func:`check_continuation`).
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np

from aw.formats.common import pose_problem
from aw.official.archive import ENGINE, MJB_MODEL, EpisodeArchive, Frame, read_archive
from aw.official.errors import EngineVersionError, EpisodeMismatchError, InconsistentEpisodeError, WorldModelError

__all__ = [
    "PartEpisode",
    "body_name",
    "expected_objects",
    "catalogue_part_ids",
    "require_engine",
    "load_model",
    "compare_compiled_models",
    "check_continuation",
    "state_poses",
    "free_body_rotations",
    "read_part_episode",
]

_COMPILED_COUNTS = (
    "nbody",
    "njnt",
    "ngeom",
    "nmesh",
    "nq",
    "nv",
    "nu",
    "na",
    "neq",
    "ntendon",
    "nplugin",
    "nflex",
    "nskin",
    "ntex",
)
# Immutable geometry and structure of a compiled world (physics options may differ between runs).
_COMPILED_ARRAYS = (
    "names",
    "name_bodyadr",
    "body_parentid",
    "body_jntadr",
    "body_jntnum",
    "body_geomadr",
    "body_geomnum",
    "body_pos",
    "body_quat",
    "body_ipos",
    "body_iquat",
    "body_mass",
    "body_inertia",
    "jnt_type",
    "jnt_bodyid",
    "jnt_qposadr",
    "jnt_dofadr",
    "jnt_pos",
    "jnt_axis",
    "jnt_limited",
    "jnt_range",
    "qpos0",
    "dof_damping",
    "geom_type",
    "geom_bodyid",
    "geom_dataid",
    "geom_pos",
    "geom_quat",
    "geom_size",
    "geom_rgba",
    "geom_friction",
    "geom_condim",
    "mesh_vertadr",
    "mesh_vertnum",
    "mesh_faceadr",
    "mesh_facenum",
    "mesh_vert",
    "mesh_face",
    "mesh_pos",
    "mesh_quat",
    "mesh_normal",
    "mesh_facenormal",
)
_POSITION_TOLERANCE = 2e-7  # compiled float32 geometry of the same MJB may differ in the last bits
_NORMAL_TOLERANCE = 1e-5  # recomputed shading normals are more sensitive near degenerate faces


def body_name(k: int) -> str:
    """The body (and catalogue id) of the ``k``-th part, ``k`` counted from 0."""
    return f"part-{k + 1:04d}"


def expected_objects(part_ids: list[str]) -> list[dict]:
    """The object catalogue of a benchmark episode whose parts are ``part_ids`` (sorted)."""
    return [
        {"id": body_name(k), "name": f"Part {pid}", "type": "rigid", "collisionEnabled": False}
        for k, pid in enumerate(part_ids)
    ]


def catalogue_part_ids(ep: EpisodeArchive) -> list[str]:
    """The part ids an archive's catalogue names, when it follows the benchmark rule."""
    objects = ep.manifest["objects"]
    ids = [o["name"][len("Part ") :] for o in objects if o["name"].startswith("Part ")]
    if len(ids) != len(objects) or ids != sorted(set(ids)) or objects != expected_objects(ids):
        raise EpisodeMismatchError(
            ep.path,
            "manifest.json: objects do not follow the benchmark catalogue "
            "(part-0001, part-0002, ... named 'Part <part id>' in part id order)",
        )
    return ids


def require_engine() -> None:
    import mujoco

    if mujoco.__version__ != ENGINE:
        raise EngineVersionError(
            "mujoco", f"official worlds and states need MuJoCo {ENGINE}; {mujoco.__version__} is installed"
        )


def load_model(ep: EpisodeArchive):
    """The compiled world of an archive: MJCF ``world/model.xml`` with the other ``world/``
    members as its assets, or the binary ``world/model.mjb``."""
    import mujoco

    require_engine()
    if ep.is_mjb:
        with tempfile.TemporaryDirectory(prefix="aw-mjb-") as folder:
            target = Path(folder) / "model.mjb"
            target.write_bytes(ep.files["world/" + MJB_MODEL["path"]])
            try:
                return mujoco.MjModel.from_binary_path(str(target))
            except Exception as exc:
                raise WorldModelError(ep.path, f"world/model.mjb: MuJoCo cannot load it ({exc})") from None
    xml = ep.files["world/model.xml"]
    try:
        meshes = ET.fromstring(xml).findall("./asset/mesh")
    except ET.ParseError as exc:
        raise WorldModelError(ep.path, f"world/model.xml: not XML ({exc})") from None
    assets = ep.world_files()
    absent = sorted({m.attrib["file"] for m in meshes if "file" in m.attrib} - set(assets))
    if absent:
        raise WorldModelError(ep.path, f"world/model.xml: mesh files missing from world/: {absent}")
    try:
        return mujoco.MjModel.from_xml_string(
            xml.decode("utf-8"), {k: v for k, v in assets.items() if k != "model.xml"}
        )
    except (ValueError, UnicodeDecodeError) as exc:
        raise WorldModelError(ep.path, f"world/model.xml: MuJoCo cannot compile it ({exc})") from None


def compare_compiled_models(actual, expected, where: Path) -> None:
    """Raise unless two compiled worlds have the same structure and geometry."""
    for name in _COMPILED_COUNTS:
        if getattr(actual, name) != getattr(expected, name):
            raise EpisodeMismatchError(where, f"world/model.mjb: compiled {name} differs from the initial episode's")
    for name in _COMPILED_ARRAYS:
        a, b = getattr(actual, name), getattr(expected, name)
        if isinstance(a, bytes):
            same = a == b
        else:
            a, b = np.asarray(a), np.asarray(b)
            tol = _NORMAL_TOLERANCE if name == "mesh_normal" else _POSITION_TOLERANCE
            same = a.shape == b.shape and (
                np.allclose(a, b, atol=tol, rtol=0) if np.issubdtype(a.dtype, np.floating) else np.array_equal(a, b)
            )
        if not same:
            raise EpisodeMismatchError(where, f"world/model.mjb: compiled {name} differs from the initial episode's")


def check_continuation(final: EpisodeArchive, initial: EpisodeArchive, part_ids: list[str]):
    """Check that ``final`` continues ``initial`` for the parts ``part_ids`` (sorted, distinct),
    as the official scorer does before it restores anything; returns the compiled world."""
    if part_ids != sorted(set(part_ids)):
        raise EpisodeMismatchError(final.path, "part ids must be sorted and distinct")
    want = expected_objects(part_ids)
    if initial.manifest["objects"] != want:
        raise EpisodeMismatchError(initial.path, "manifest.json: object catalogue differs from the evaluation's parts")
    if final.manifest["objects"] != want:
        raise EpisodeMismatchError(final.path, "manifest.json: object catalogue differs from the evaluation's parts")
    for key in ("id", "producer", "contract", "engine", "stateSpec", "stateSize"):
        if final.manifest[key] != initial.manifest[key]:
            raise EpisodeMismatchError(final.path, f"manifest.json: {key} differs from the initial episode's")
    if final.manifest.get("model") != initial.manifest.get("model"):
        raise EpisodeMismatchError(final.path, "manifest.json: model declaration differs from the initial episode's")
    world, reference = final.world_files(), initial.world_files()
    if final.is_mjb:
        if set(world) != set(reference):
            raise EpisodeMismatchError(final.path, "world/: members differ from the initial episode's")
        model = load_model(final)
        compare_compiled_models(model, load_model(initial), final.path)
        return model
    if world != reference:
        raise EpisodeMismatchError(final.path, "world/: files differ from the initial episode's")
    return load_model(final)


def _bodies(model, names: list[str], where: Path) -> list[int]:
    import mujoco

    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n) for n in names]
    missing = [n for n, b in zip(names, ids, strict=True) if b <= 0]
    if missing:
        raise WorldModelError(where, f"the world has no bodies {missing}")
    return ids


def state_poses(model, ep: EpisodeArchive, frames: list[Frame], names: list[str]) -> np.ndarray:
    """``(F, P, 7)`` world poses ``[x, y, z, qw, qx, qy, qz]`` of the bodies ``names`` in each
    frame. A top-level body on one free joint reports its joint coordinates as stored (so a
    pose written back reproduces the state exactly); any other body its forward kinematics."""
    import mujoco

    spec, size = ep.manifest["stateSpec"], ep.manifest["stateSize"]
    if mujoco.mj_stateSize(model, spec) != size:
        raise EpisodeMismatchError(
            ep.path,
            f"manifest.json: stateSize {size} differs from the world's state size "
            f"{mujoco.mj_stateSize(model, spec)} for stateSpec {spec}",
        )
    bodies = _bodies(model, names, ep.path)
    free = [_free_qpos_address(model, b) for b in bodies]
    data = mujoco.MjData(model)
    out = np.empty((len(frames), len(bodies), 7))
    for f, frame in enumerate(frames):
        mujoco.mj_setState(model, data, frame.integration, spec)
        mujoco.mj_forward(model, data)
        for p, (b, adr) in enumerate(zip(bodies, free, strict=True)):
            if adr is None:
                out[f, p, :3], out[f, p, 3:] = data.xpos[b], data.xquat[b]
            else:
                out[f, p] = data.qpos[adr : adr + 7]
            why = pose_problem(out[f, p].tolist())
            if why is not None:  # e.g. a zero quaternion: refused here rather than scored as some pose
                raise InconsistentEpisodeError(
                    ep.path, f"frames.bin: {frame.kind} {frame.index}: body {names[p]}: {why}"
                )
    return out


def free_body_rotations(quaternions: np.ndarray) -> np.ndarray:
    """``(P, 3, 3)`` world rotations (MuJoCo's ``xmat``) of top-level bodies on a free joint whose
    joint quaternions are ``quaternions: (P, 4)`` ``(w, x, y, z)`` as stored in a state.

    Forward kinematics normalizes the quaternion as ``mju_normalize4`` does (not at all when
    its norm is within MuJoCo's ``mjMINVAL`` of 1) and converts it with ``mju_quat2Mat``; these
    are MuJoCo's own functions, so the matrices are the ones ``mj_forward`` leaves in ``xmat``
    (which the official scorer and evaluation read, ``poses.py`` and ``evaluation/inputs.py``)
    bit for bit, without building the world."""
    import mujoco

    quats = np.array(quaternions, dtype=np.float64).reshape(-1, 4)
    out = np.empty((len(quats), 9))
    for quat, mat in zip(quats, out, strict=True):
        mujoco.mju_normalize4(quat)
        mujoco.mju_quat2Mat(mat, quat)
    return out.reshape(-1, 3, 3)


def _free_qpos_address(model, body: int) -> int | None:
    import mujoco

    if model.body_parentid[body] != 0 or model.body_jntnum[body] != 1:
        return None
    joint = model.body_jntadr[body]
    return int(model.jnt_qposadr[joint]) if model.jnt_type[joint] == mujoco.mjtJoint.mjJNT_FREE else None


@dataclass
class PartEpisode:
    """An archive restored for its parts.

    ``poses`` is ``(S + 1, P, 7)``: state index 0 (initial) .. S, parts in ``part_ids`` order.
    """

    archive: EpisodeArchive
    part_ids: list[str]
    poses: np.ndarray
    model: object

    @property
    def path(self) -> Path:
        return self.archive.path

    @property
    def final_index(self) -> int:
        return self.archive.final_state().index

    def final_poses(self) -> np.ndarray:
        """``(P, 7)`` poses of the state the official scorer restores."""
        return self.poses[self.final_index]


def read_part_episode(
    path: str | Path | EpisodeArchive,
    initial: str | Path | EpisodeArchive | None = None,
    part_ids: list[str] | None = None,
) -> PartEpisode:
    """Read (or take) an archive and restore every state's part poses. With ``initial``, the
    archive must continue it (:func:`check_continuation`); ``part_ids`` default to the
    catalogue's."""
    ep = path if isinstance(path, EpisodeArchive) else read_archive(path)
    ids = list(part_ids) if part_ids is not None else catalogue_part_ids(ep)
    if initial is not None:
        init = initial if isinstance(initial, EpisodeArchive) else read_archive(initial)
        model = check_continuation(ep, init, ids)
    else:
        if ep.manifest["objects"] != expected_objects(ids):
            raise EpisodeMismatchError(ep.path, "manifest.json: object catalogue differs from the given parts")
        model = load_model(ep)
    poses = state_poses(model, ep, [ep.initial, *ep.states], [body_name(k) for k in range(len(ids))])
    return PartEpisode(ep, ids, poses, model)
