"""Scene state and its edit operations, with the semantics of the paper's Table A-2.

Independent of MCP: the server is a thin adapter over this class. Every operation validates
its whole request before changing anything (all-or-nothing) and raises :class:`SceneError`
with a message that says what was wrong and what is allowed. Messages never contain geometry,
targets or file paths.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from aw.camera import PITCH_LIMIT_DEG, Camera, wrap_degrees
from aw.pose import IDENTITY_POSE, matrix_to_quat, quat_multiply, quat_to_matrix

# Normalized scene units: assembled objects are about one unit across. Anything beyond this is
# refused as absurd rather than silently accepted.
MAX_COORDINATE = 1000.0
MAX_ANGLE_DEG = 3600.0
MAX_GROUP_NAME = 200
ZOOM_RANGE = (0.25, 4.0)
YAW_RANGE = (-180.0, 180.0)
PITCH_RANGE = (-85.0, 85.0)
SPACES = ("world", "camera")


class SceneError(ValueError):
    """An invalid request; the scene is unchanged."""


@dataclass
class Group:
    id: str
    name: str
    members: list[str]


@dataclass(frozen=True)
class SceneSnapshot:
    """A scene's mutable state at one moment (:meth:`Scene.snapshot`)."""

    poses: dict[str, np.ndarray]
    groups: dict[str, Group]
    next_group: int
    camera: Camera


@dataclass
class PartInfo:
    """What the scene knows of a part: its id, display name and mesh-local bounding box."""

    id: str
    name: str
    bounds_min: np.ndarray
    bounds_max: np.ndarray

    @property
    def extents(self) -> np.ndarray:
        return self.bounds_max - self.bounds_min


def _finite_vector(value, length: int, what: str, limit: float) -> np.ndarray:
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence | np.ndarray):
        raise SceneError(f"{what} must be a list of {length} numbers")
    if len(value) != length:
        raise SceneError(f"{what} must have exactly {length} numbers, got {len(value)}")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, int | float | np.floating | np.integer):
            raise SceneError(f"{what} must contain only numbers")
        f = float(v)
        if not math.isfinite(f):
            raise SceneError(f"{what} contains a non-finite number (NaN or infinity)")
        if abs(f) > limit:
            raise SceneError(
                f"{what} has a value of magnitude {abs(f):.3g}; the allowed range is [-{limit:g}, {limit:g}]"
            )
        out.append(f)
    return np.array(out)


def _finite_scalar(value, what: str, lo: float, hi: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        raise SceneError(f"{what} must be a number")
    f = float(value)
    if not math.isfinite(f):
        raise SceneError(f"{what} must be finite")
    if not lo <= f <= hi:
        raise SceneError(f"{what} must lie in [{lo:g}, {hi:g}], got {f:g}")
    return f


def _axis_rotation(axis: np.ndarray, angle_deg: float) -> np.ndarray:
    """Right-hand rotation about a unit ``axis`` (Rodrigues)."""
    a = np.radians(angle_deg)
    k = axis / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * kx + (1 - np.cos(a)) * (kx @ kx)


def _initial_pose(value, pid: str) -> np.ndarray:
    p = _finite_vector(value, 7, f"initial pose of {pid}", 1e6)
    n = float(np.linalg.norm(p[3:]))
    if n < 1e-9:
        raise SceneError(f"initial pose of {pid} has a zero-length quaternion")
    q = p[3:] / n
    p[3:] = q if q[0] >= 0 else -q
    return p


def _check_space(space) -> str:
    if not isinstance(space, str) or space not in SPACES:
        raise SceneError(f"space must be 'world' or 'camera', got {space!r}")
    return space


class Scene:
    """Part poses (wire form ``[x, y, z, qw, qx, qy, qz]``), named groups and the camera."""

    def __init__(
        self,
        parts: Sequence[PartInfo],
        poses: Mapping[str, Sequence[float]] | None = None,
        camera: Camera | None = None,
    ):
        if not parts:
            raise SceneError("a scene needs at least one part")
        self.parts: dict[str, PartInfo] = {p.id: p for p in parts}
        if len(self.parts) != len(parts):
            raise SceneError("part ids must be unique")
        poses = dict(poses or {})
        unknown = [pid for pid in poses if pid not in self.parts]
        if unknown:
            raise SceneError(f"poses given for unknown part ids {unknown}")
        self.poses: dict[str, np.ndarray] = {
            pid: _initial_pose(poses[pid], pid) if pid in poses else IDENTITY_POSE.copy() for pid in self.parts
        }
        self.groups: dict[str, Group] = {}
        self._next_group = 1
        if camera is None:
            lo = np.min([p.bounds_min for p in parts], axis=0)
            hi = np.max([p.bounds_max for p in parts], axis=0)
            camera = Camera.framing(lo, hi)
        self.camera = camera

    # ---------------------------------------------------------------- selection
    @property
    def part_ids(self) -> list[str]:
        return list(self.parts)

    def resolve(self, ids) -> list[str]:
        """Expand a selection of part and group ids into unique part ids (selection order kept)."""
        if isinstance(ids, str) or not isinstance(ids, Sequence):
            raise SceneError("ids must be a list of object or group ids")
        if len(ids) == 0:
            raise SceneError("ids must name at least one object or group")
        if not all(isinstance(i, str) for i in ids):
            raise SceneError("ids must be strings")
        if len(set(ids)) != len(ids):
            raise SceneError("ids must be unique")
        out: list[str] = []
        for i in ids:
            if i in self.parts:
                members = [i]
            elif i in self.groups:
                members = self.groups[i].members
            else:
                raise SceneError(f"unknown id {i!r}; use list_objects for the object and group ids")
            out.extend(m for m in members if m not in out)
        return out

    # ---------------------------------------------------------------- edits
    def _check_positions(self, new: Mapping[str, np.ndarray]) -> None:
        for pid, pose in new.items():
            if np.any(np.abs(pose[:3]) > MAX_COORDINATE):
                raise SceneError(f"the edit would move {pid} to a position beyond +-{MAX_COORDINATE:g} units; refused")

    def _commit(self, new: Mapping[str, np.ndarray]) -> list[str]:
        self._check_positions(new)
        changed = [pid for pid, pose in new.items() if not np.array_equal(pose, self.poses[pid])]
        for pid, pose in new.items():
            self.poses[pid] = pose
        return changed

    def _frame(self, space) -> np.ndarray:
        _check_space(space)
        return np.eye(3) if space == "world" else self.camera.axes()

    def translate(self, ids, delta, space: str = "world") -> list[str]:
        """Move the selected parts by ``delta``; in camera space its components are along
        right, up and forward. Returns the ids whose pose changed."""
        sel = self.resolve(ids)
        d = _finite_vector(delta, 3, "delta", MAX_COORDINATE)
        world = self._frame(space) @ d
        new = {}
        for pid in sel:
            p = self.poses[pid].copy()
            p[:3] += world
            new[pid] = p
        return self._commit(new)

    def rotation_matrix(self, angles, space: str = "world") -> np.ndarray:
        """The rotation of ``rotate_objects``: X, then Y, then Z angles (degrees) about the axes
        of ``space`` (world X/Y/Z, or the camera's right/up/forward), right-hand rule."""
        a = _finite_vector(angles, 3, "angles", MAX_ANGLE_DEG)
        axes = self._frame(space)
        rot = np.eye(3)
        for k in range(3):
            rot = _axis_rotation(axes[:, k], a[k]) @ rot
        return rot

    def rotate(self, ids, angles, space: str = "world", pivot=None) -> list[str]:
        """Rotate the selected parts about ``pivot`` (default: mean of their body origins)."""
        sel = self.resolve(ids)
        rot = self.rotation_matrix(angles, space)
        if pivot is None:
            c = np.mean([self.poses[pid][:3] for pid in sel], axis=0)
        else:
            c = _finite_vector(pivot, 3, "pivot", MAX_COORDINATE)
        if np.array_equal(rot, np.eye(3)):
            return []  # zero angles: leave the poses bit-identical (no float noise from the pivot)
        q = matrix_to_quat(rot)
        new = {}
        for pid in sel:
            p = self.poses[pid]
            pos = rot @ (p[:3] - c) + c
            quat = quat_multiply(q, p[3:])
            quat /= np.linalg.norm(quat)
            new[pid] = np.concatenate([pos, quat if quat[0] >= 0 else -quat])
        return self._commit(new)

    def set_pose(self, id: str, position=None, quaternion=None) -> list[str]:
        """Set a part's absolute position and/or quaternion (w, x, y, z), normalized here."""
        if not isinstance(id, str):
            raise SceneError("id must be a string")
        if id not in self.parts:
            hint = " (a group id: set_object_pose takes a single object id)" if id in self.groups else ""
            raise SceneError(f"unknown object id {id!r}{hint}; use list_objects for the ids")
        if position is None and quaternion is None:
            raise SceneError("give position and/or quaternion")
        p = self.poses[id].copy()
        if position is not None:
            p[:3] = _finite_vector(position, 3, "position", MAX_COORDINATE)
        if quaternion is not None:
            q = _finite_vector(quaternion, 4, "quaternion", 1e6)
            n = float(np.linalg.norm(q))
            if n < 1e-9:
                raise SceneError("quaternion has zero length; give a non-zero (w, x, y, z)")
            q = q / n
            p[3:] = q if q[0] >= 0 else -q
        return self._commit({id: p})

    # ---------------------------------------------------------------- groups
    def group(self, ids, name: str | None = None, exclusive: bool = False) -> Group:
        """Create a logical transform group; nothing moves or snaps.

        ``exclusive`` gives the official runtime's rule: the group needs at least two objects,
        and every existing group that shares a member with it is dissolved first."""
        members = self.resolve(ids)
        if not isinstance(exclusive, bool):
            raise SceneError("exclusive must be true or false")
        if exclusive and len(members) < 2:
            raise SceneError("ids must name at least two objects to group (a group id counts its members)")
        if name is not None:
            if not isinstance(name, str):
                raise SceneError("name must be a string")
            if len(name) > MAX_GROUP_NAME:
                raise SceneError(f"name must be at most {MAX_GROUP_NAME} characters")
        if exclusive:
            for gid in [g.id for g in self.groups.values() if set(g.members) & set(members)]:
                del self.groups[gid]
        gid = f"g{self._next_group}"
        while gid in self.groups or gid in self.parts:
            self._next_group += 1
            gid = f"g{self._next_group}"
        self._next_group += 1
        g = Group(gid, name if name else gid, members)
        self.groups[gid] = g
        return g

    def ungroup(self, ids) -> list[str]:
        """Remove groups; nothing moves."""
        if isinstance(ids, str) or not isinstance(ids, Sequence) or len(ids) == 0:
            raise SceneError("ids must be a non-empty list of group ids")
        if not all(isinstance(i, str) for i in ids):
            raise SceneError("ids must be strings")
        if len(set(ids)) != len(ids):
            raise SceneError("ids must be unique")
        bad = [i for i in ids if i not in self.groups]
        if bad:
            raise SceneError(f"not group ids: {bad}; use list_objects for the group ids")
        for i in ids:
            del self.groups[i]
        return list(ids)

    # ---------------------------------------------------------------- camera
    def move_camera(self, yaw=0.0, pitch=0.0, zoom=1.0, right=0.0, up=0.0) -> Camera:
        """Orbit by relative ``yaw``/``pitch`` degrees, multiply the distance by ``zoom``, and pan
        the look-at point by ``right``/``up`` scene units along the camera's axes (None: not given).

        The pan uses the axes of the view before the orbit; the pitch stays within +-85 degrees
        (clamped), the yaw wraps to (-180, 180]. Returns the new camera."""
        yaw = 0.0 if yaw is None else _finite_scalar(yaw, "yaw", *YAW_RANGE)
        pitch = 0.0 if pitch is None else _finite_scalar(pitch, "pitch", *PITCH_RANGE)
        zoom = 1.0 if zoom is None else _finite_scalar(zoom, "zoom", *ZOOM_RANGE)
        right = 0.0 if right is None else _finite_scalar(right, "right", -MAX_COORDINATE, MAX_COORDINATE)
        up = 0.0 if up is None else _finite_scalar(up, "up", -MAX_COORDINATE, MAX_COORDINATE)
        cam = self.camera.copy()
        # Pan in the current view's axes, then orbit about the panned target.
        target = cam.target + right * cam.right + up * cam.up
        if np.any(np.abs(target) > MAX_COORDINATE):
            raise SceneError("the pan would move the camera target beyond the scene limits; refused")
        cam.target = target
        cam.yaw = wrap_degrees(cam.yaw + yaw)
        cam.pitch = float(np.clip(cam.pitch + pitch, -PITCH_LIMIT_DEG, PITCH_LIMIT_DEG))
        cam.distance = float(cam.distance * zoom)
        if not 1e-3 <= cam.distance <= MAX_COORDINATE:
            raise SceneError("the zoom would put the camera outside the allowed distance range; refused")
        self.camera = cam
        return cam

    # ---------------------------------------------------------------- undo
    def snapshot(self) -> SceneSnapshot:
        """Everything a call can change: to undo a call whose success could not be recorded."""
        return SceneSnapshot(
            {pid: p.copy() for pid, p in self.poses.items()},
            {gid: Group(g.id, g.name, list(g.members)) for gid, g in self.groups.items()},
            self._next_group,
            self.camera.copy(),
        )

    def restore(self, snap: SceneSnapshot) -> None:
        """Put the scene back to ``snap`` (taken by :meth:`snapshot` on this scene)."""
        self.poses = {pid: p.copy() for pid, p in snap.poses.items()}
        self.groups = {gid: Group(g.id, g.name, list(g.members)) for gid, g in snap.groups.items()}
        self._next_group = snap.next_group
        self.camera = snap.camera.copy()

    # ---------------------------------------------------------------- queries
    def pose_dict(self) -> dict[str, list[float]]:
        return {pid: [float(v) for v in p] for pid, p in self.poses.items()}

    def object_record(self, pid: str) -> dict:
        info = self.parts[pid]
        p = self.poses[pid]
        return {
            "id": pid,
            "name": info.name,
            "position": [float(v) for v in p[:3]],
            "quaternion": [float(v) for v in p[3:]],
            "extents": [float(v) for v in info.extents],
            "local_bounds": {"min": [float(v) for v in info.bounds_min], "max": [float(v) for v in info.bounds_max]},
            "groups": [g.id for g in self.groups.values() if pid in g.members],
        }

    def group_record(self, gid: str) -> dict:
        g = self.groups[gid]
        return {"id": g.id, "name": g.name, "members": list(g.members)}

    def world_bounds(self, pid: str) -> tuple[np.ndarray, np.ndarray]:
        """World-space axis-aligned box of a part's local bounding box under its current pose."""
        info = self.parts[pid]
        corners = np.array(
            [
                [x, y, z]
                for x in (info.bounds_min[0], info.bounds_max[0])
                for y in (info.bounds_min[1], info.bounds_max[1])
                for z in (info.bounds_min[2], info.bounds_max[2])
            ]
        )
        p = self.poses[pid]
        w = corners @ quat_to_matrix(p[3:]).T + p[:3]
        return w.min(axis=0), w.max(axis=0)

    def groups_list(self) -> list[dict]:
        return [self.group_record(g) for g in self.groups]


def scene_from_meshes(part_ids: Iterable[str], meshes: Iterable, names: Iterable[str] | None = None) -> Scene:
    """Build a scene from trimesh meshes in their baked frame (identity initial poses)."""
    part_ids = list(part_ids)
    meshes = list(meshes)
    names = list(names) if names is not None else part_ids
    infos = [
        PartInfo(pid, nm, np.asarray(m.bounds[0], float), np.asarray(m.bounds[1], float))
        for pid, m, nm in zip(part_ids, meshes, names, strict=True)
    ]
    return Scene(infos)
