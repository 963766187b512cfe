"""The official benchmark's page tools (WebMCP) over a project :class:`~aw.episode.Episode`.

The official environment is a web page that registers 14 tools (3DWebAgent ``schema/tools.json``);
a benchmark episode enables twelve of them (``runtime.enabledTools`` as written by
assembly-world-agent ``episodes.py``: the physics tools ``apply_force`` and
``advance_simulation`` are not registered). :class:`WebMcpPage` gives those tools the official
names, argument schemas, object catalogue and result shapes, and runs each call through
:meth:`Episode.call` under the project's tool name and argument form, so the trajectory is the one
the default surface records. No MCP here: ``aw_server.official_surface`` is the adapter.

Mapping (official -> project):

- object ids: ``part-0001``, ``part-0002``, ... for the task's part ids in sorted order, names
  ``Part <part id>`` (assembly-world-agent ``episodes.py``); group ids ``group-<episode>-<n>`` for
  the project's ``g<n>`` (3DWebAgent ``src/runtime.ts``);
- ``move_camera``: the official pitch turns the orbit's polar angle, so a positive pitch lowers the
  camera; the project's positive pitch raises it, so the sign is flipped. Yaw, zoom and the pan
  agree (3DWebAgent ``src/pose.ts``);
- ``group_objects``: at least two objects, and groups sharing a member are dissolved first
  (``exclusive`` in the recorded arguments); the default name is ``Group``;
- every call to a registered tool starts the episode (the official runtime activates the episode
  on the first page-tool call), so the budget runs from then.

Results follow 3DWebAgent ``schema/results.schema.json``; a failed call is the official error
object ``{"error": message, "code": code}`` (codes from 3DWebAgent ``src/runtime.ts``). Messages
name the argument and never contain geometry, targets or paths.
"""

from __future__ import annotations

import base64
import json
import math
import re
import sys
import threading
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from aw.camera import IMAGE_HEIGHT, IMAGE_WIDTH, VERTICAL_FOV_DEG
from aw.episode import Capture, Episode, EpisodeError

# ---------------------------------------------------------------------------------------------------
# Tool definitions: the official argument schemas (3DWebAgent schema/tools.json) with our own words.

_IDS = {"type": "array", "items": {"type": "string", "minLength": 1}, "minItems": 1, "uniqueItems": True}
_VEC3 = {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3}
_QUAT = {"type": "array", "items": {"type": "number"}, "minItems": 4, "maxItems": 4}
_SPACE = {"type": "string", "enum": ["world", "camera"]}
_ID = {"type": "string", "minLength": 1}


def _closed(properties: dict, required: tuple[str, ...] = (), **extra: Any) -> dict:
    return {
        "type": "object",
        "properties": properties,
        "required": list(required),
        "additionalProperties": False,
        **extra,
    }


@dataclass(frozen=True)
class PageTool:
    name: str
    description: str
    input_schema: dict
    read_only: bool


PAGE_TOOLS: dict[str, PageTool] = {
    t.name: t
    for t in (
        PageTool(
            "list_objects", "List the object ids and names of the scene and its current groups.", _closed({}), True
        ),
        PageTool(
            "get_object",
            "Read one object: body pose (position, quaternion wxyz), velocity, mass and geometry, in episode units.",
            _closed({"id": _ID}, ("id",)),
            True,
        ),
        PageTool(
            "get_scene",
            "Read the scene name, units, axis and quaternion conventions, runtime settings and object catalogue.",
            _closed({}),
            True,
        ),
        PageTool(
            "get_state",
            "Read the live state: every object's pose, the groups, the camera and contacts.",
            _closed({}),
            True,
        ),
        PageTool(
            "translate_objects",
            "Move the given object or group ids by delta, in world axes or in the "
            "camera's right/up/forward axes. One state per call.",
            _closed({"ids": _IDS, "delta": _VEC3, "space": _SPACE}, ("ids", "delta")),
            False,
        ),
        PageTool(
            "rotate_objects",
            "Rotate the given ids by angles in degrees about X, then Y, then Z (world "
            "axes, or camera right/up/forward). The pivot is the mean body origin unless a world point "
            "is given.",
            _closed({"ids": _IDS, "angles": _VEC3, "space": _SPACE, "pivot": _VEC3}, ("ids", "angles")),
            False,
        ),
        PageTool(
            "set_object_pose",
            "Set one object's absolute world position and/or quaternion (wxyz); its velocity is cleared.",
            _closed(
                {"id": _ID, "position": _VEC3, "quaternion": _QUAT},
                ("id",),
                anyOf=[{"required": ["position"]}, {"required": ["quaternion"]}],
            ),
            False,
        ),
        PageTool(
            "group_objects",
            "Group the given ids logically so that later edits can move them together; nothing snaps or welds.",
            _closed({"ids": _IDS, "name": {"type": "string", "maxLength": 200}}, ("ids",)),
            False,
        ),
        PageTool(
            "ungroup_objects", "Dissolve the given group ids; no object moves.", _closed({"ids": _IDS}, ("ids",)), False
        ),
        PageTool("capture_scene", "Render the current scene from the agent camera as a PNG image.", _closed({}), True),
        PageTool(
            "move_camera",
            "Orbit the camera by relative yaw/pitch degrees, multiply its distance by "
            "zoom, or pan it along its right/up axes. Physics does not advance.",
            _closed(
                {
                    "yaw": {"type": "number", "minimum": -180, "maximum": 180},
                    "pitch": {"type": "number", "minimum": -85, "maximum": 85},
                    "zoom": {"type": "number", "minimum": 0.25, "maximum": 4},
                    "right": {"type": "number"},
                    "up": {"type": "number"},
                }
            ),
            False,
        ),
        PageTool(
            "apply_force",
            "Push one object with a world force (newtons, magnitude at most 20) for the "
            "configured time, then settle. Needs physics.",
            _closed({"id": _ID, "force": _VEC3}, ("id", "force")),
            False,
        ),
        PageTool(
            "start_episode",
            "Start recording; calling it again changes nothing.",
            _closed({"task": {"type": "string"}}),
            False,
        ),
        PageTool(
            "advance_simulation",
            "Step the enabled physics for the given duration in seconds.",
            _closed({"duration": {"type": "number", "exclusiveMinimum": 0, "maximum": 60}}, ("duration",)),
            False,
        ),
    )
}

# runtime.enabledTools of a benchmark episode (assembly-world-agent episodes.py), in its order.
# end_episode is retired: the page does not register it.
ENABLED_TOOLS: tuple[str, ...] = (
    "list_objects",
    "get_object",
    "get_scene",
    "get_state",
    "translate_objects",
    "rotate_objects",
    "set_object_pose",
    "group_objects",
    "ungroup_objects",
    "capture_scene",
    "move_camera",
    "start_episode",
    "end_episode",
)
# runtime.physics of a benchmark episode: disabled, no contacts.
PHYSICS: dict[str, Any] = {
    "enabled": False,
    "gravity": [0, 0, -9.81],
    "detection": False,
    "response": False,
    "strategy": "fixed",
    "duration": 0.25,
    "maxDuration": 5.0,
    "quietDuration": 0.1,
    "linearThreshold": 0.01,
    "angularThreshold": 0.01,
}
# capture_scene's render block (3DWebAgent schema/results.schema.json).
RENDER = {
    "width": IMAGE_WIDTH,
    "height": IMAGE_HEIGHT,
    "pixelRatio": 1,
    "fovy": int(VERTICAL_FOV_DEG) if float(VERTICAL_FOV_DEG).is_integer() else VERTICAL_FOV_DEG,
    "near": 0.01,
    "far": 1000,
}
# What get_object reports of each body: the constants of a benchmark episode's MJCF
# (assembly-world-agent episodes.py: unit mass, diagonal inertia 0.1, no collision) and MuJoCo's
# default geom friction and contact dimension. Geometry type 7 is MuJoCo's mesh.
_MASS, _INERTIA, _FRICTION, _CONDIM, _MESH = 1.0, [0.1, 0.1, 0.1], [1.0, 0.005, 0.0001], 3, 7


def mesh_geom_sizes(meshes) -> list[list[float]]:
    """What MuJoCo reports as each mesh geom's ``size``: the half-sizes of the mesh's bounding box
    in its principal (shell-inertia) frame, as the benchmark's MJCF compiles it. The value does not
    depend on where the mesh is placed, so the baked task meshes give the official numbers. A mesh
    that MuJoCo cannot compile falls back to half its axis-aligned bounding box.

    ``meshes``: trimesh meshes; returns ``(n_meshes, 3)`` as lists.
    """
    import mujoco  # lazy: only the official surface's object queries need it

    out = []
    for m in meshes:
        spec = mujoco.MjSpec()
        mesh = spec.add_mesh(name="m", inertia=mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL)
        mesh.uservert = np.asarray(m.vertices, float).ravel().tolist()
        mesh.userface = np.asarray(m.faces, int).ravel().tolist()
        body = spec.worldbody.add_body(name="b", mass=_MASS, inertia=_INERTIA, explicitinertial=True)
        body.add_freejoint()
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname="m", contype=0, conaffinity=0)
        try:
            out.append([float(v) for v in spec.compile().geom_size[0]])
        except Exception:  # a degenerate mesh: MuJoCo refuses it; keep a meaningful size
            out.append([float(v) / 2 for v in np.ptp(np.asarray(m.vertices, float), axis=0)])
    return out


_MUTATIONS = frozenset(
    {"translate_objects", "rotate_objects", "set_object_pose", "group_objects", "ungroup_objects", "move_camera"}
)
_PHYSICAL = frozenset({"translate_objects", "rotate_objects", "set_object_pose"})


def registered_tools(enabled: tuple[str, ...] = ENABLED_TOOLS) -> list[str]:
    """The tools the page registers: the enabled ones it defines, in the enabled order."""
    return [n for n in dict.fromkeys(enabled) if n in PAGE_TOOLS]


# ---------------------------------------------------------------------------------------------------
# Argument checking against the schemas above (the keywords they use), naming the argument.


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _type_ok(kind: str, v: Any) -> bool:
    return {
        "object": lambda: isinstance(v, Mapping),
        "array": lambda: isinstance(v, list),
        "string": lambda: isinstance(v, str),
        "number": lambda: _is_number(v),
        "integer": lambda: isinstance(v, int) and not isinstance(v, bool),
        "boolean": lambda: isinstance(v, bool),
    }[kind]()


def _check(schema: dict, v: Any, path: str, out: list[str]) -> None:
    kind = schema.get("type")
    if kind and not _type_ok(kind, v):
        out.append(f"{path} must be {'an' if kind[0] in 'aeiou' else 'a'} {kind}, got {_json_type(v)}")
        return
    if _is_number(v):
        if not _finite(v):
            out.append(f"{path} must be a finite number")
        elif "minimum" in schema and v < schema["minimum"]:
            out.append(f"{path} must be >= {schema['minimum']:g}, got {v:g}")
        elif "maximum" in schema and v > schema["maximum"]:
            out.append(f"{path} must be <= {schema['maximum']:g}, got {v:g}")
        elif "exclusiveMinimum" in schema and v <= schema["exclusiveMinimum"]:
            out.append(f"{path} must be > {schema['exclusiveMinimum']:g}, got {v:g}")
    if isinstance(v, str):
        if len(v) < schema.get("minLength", 0):
            out.append(f"{path} must not be empty")
        if "maxLength" in schema and len(v) > schema["maxLength"]:
            out.append(f"{path} must have at most {schema['maxLength']} characters, got {len(v)}")
        if "enum" in schema and v not in schema["enum"]:
            out.append(f"{path} must be one of {', '.join(map(repr, schema['enum']))}, got {short_repr(v)}")
    if isinstance(v, list):
        lo, hi = schema.get("minItems", 0), schema.get("maxItems")
        if lo == hi and len(v) != lo:
            out.append(f"{path} must have exactly {lo} items, got {len(v)}")
        elif len(v) < lo:
            out.append(f"{path} must have at least {lo} item{'s' if lo > 1 else ''}, got {len(v)}")
        elif hi is not None and len(v) > hi:
            out.append(f"{path} must have at most {hi} items, got {len(v)}")
        if schema.get("uniqueItems") and len({repr(x) for x in v}) != len(v):
            out.append(f"{path} must not repeat an item")
        for i, x in enumerate(v):
            _check(schema.get("items", {}), x, f"{path}[{i}]", out)
    if isinstance(v, Mapping):
        props = schema.get("properties", {})
        if schema.get("additionalProperties") is False:
            out.extend(
                f"unexpected argument {short_repr(k)} (allowed: {', '.join(props) or 'none'})"
                for k in v
                if k not in props
            )
        out.extend(f"{k} is required" for k in schema.get("required", ()) if k not in v)
        for k, x in v.items():
            if k in props:
                _check(props[k], x, k, out)
        alternatives = schema.get("anyOf")
        if alternatives and not any(all(k in v for k in a.get("required", ())) for a in alternatives):
            out.append("give at least one of " + " or ".join(k for a in alternatives for k in a["required"]))


def check_arguments(schema: dict, arguments: Any) -> list[str]:
    """The problems of ``arguments`` under ``schema`` (empty when valid), each naming its argument."""
    out: list[str] = []
    _check(schema, arguments, "arguments", out)
    return out


def _finite(v: int | float) -> bool:
    """Finite, and usable as a float (JSON integers may have hundreds of digits)."""
    if isinstance(v, int):
        return abs(v) <= _FLOAT_MAX
    return math.isfinite(v)


_FLOAT_MAX = int(sys.float_info.max)


def _json_type(v: Any) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "a boolean"
    if _is_number(v):
        return "a number"
    if isinstance(v, str):
        return "a string"
    if isinstance(v, list):
        return "an array"
    return "an object" if isinstance(v, Mapping) else type(v).__name__


def short_repr(v: Any, limit: int = 40) -> str:
    try:
        text = repr(v)
    except ValueError:  # an integer beyond Python's 4300-digit text limit
        text = f"<integer of {v.bit_length()} bits>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


# ---------------------------------------------------------------------------------------------------
# execute_webmcp_tool's input: a JSON object encoded as text.

MAX_INPUT_DEPTH = 32  # the page tools' arguments nest three levels; deeper input is refused by name


class BadInput(ValueError):
    """``input`` is not a usable JSON object; the message names the problem in one line."""


def parse_tool_input(text: str) -> dict:
    """The argument object a page-tool call's ``input`` text encodes. Refused (:class:`BadInput`):
    text that is not JSON, NaN/Infinity, anything but an object, nesting deeper than
    ``MAX_INPUT_DEPTH``, and lone UTF-16 surrogates (``"\\ud800"``), which no UTF-8 record can
    hold. Integers beyond float range pass here and are refused by the argument check."""
    try:
        value = json.loads(text, parse_constant=_no_constant)
    except RecursionError:
        raise BadInput(f"input is nested more than {MAX_INPUT_DEPTH} levels deep") from None
    except ValueError as exc:
        if "integer string conversion" in str(exc):
            raise BadInput("input holds a number with more than 4300 digits; numbers must be finite") from None
        raise BadInput(f"input is not valid JSON: {exc}") from None
    if not isinstance(value, dict):
        raise BadInput(f"input must encode a JSON object, got {_json_kind(value)}")
    stack: list[tuple[Any, int]] = [(value, 1)]
    while stack:
        v, depth = stack.pop()
        if isinstance(v, str):
            _check_text(v)
        elif isinstance(v, (dict, list)):
            if depth > MAX_INPUT_DEPTH:
                raise BadInput(f"input is nested more than {MAX_INPUT_DEPTH} levels deep")
            items = v.items() if isinstance(v, dict) else enumerate(v)
            for k, x in items:
                if isinstance(k, str):
                    _check_text(k)
                stack.append((x, depth + 1))
    return value


def _check_text(s: str) -> None:
    try:
        s.encode("utf-8")
    except UnicodeEncodeError as exc:
        bad = s[exc.start : exc.end].encode("utf-8", "backslashreplace").decode("ascii")
        raise BadInput(f"input holds a lone UTF-16 surrogate ({bad}); strings must be valid Unicode text") from None


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number")


def _json_kind(v: Any) -> str:
    return {list: "an array", str: "a string", bool: "a boolean", type(None): "null"}.get(type(v), "a number")


# ---------------------------------------------------------------------------------------------------
# The page.


class NotRegistered(Exception):
    """The tool name is not registered on the page (never reaches the scene)."""


class _Refused(Exception):
    """A call refused by this surface before it reached the scene."""


def _error_code(message: str) -> str:
    """The official error code of a refusal (3DWebAgent ``errorCode``, applied to our messages)."""
    if "exhausted" in message or "has ended" in message or "takes no further calls" in message:
        return "episode_ended"
    return "invalid_argument"


@dataclass
class PageReply:
    """``output``: the tool's result or ``{"error", "code"}``; ``png``: a capture's image bytes."""

    output: dict
    png: bytes | None = None

    @property
    def ok(self) -> bool:
        return "error" not in self.output


class WebMcpPage:
    """The official page tools over ``episode``. ``episode_id`` names the groups
    (``group-<episode_id>-<n>``) and the scene; default: the task id."""

    def __init__(self, episode: Episode, episode_id: str | None = None, enabled: tuple[str, ...] = ENABLED_TOOLS):
        self.episode = episode
        self.episode_id = episode_id or episode.task.task_id
        self.enabled = tuple(dict.fromkeys(enabled))
        self.tools = registered_tools(self.enabled)
        pids = sorted(episode.part_ids)
        self._to_official = {pid: f"part-{k:04d}" for k, pid in enumerate(pids, start=1)}
        self._to_project = {oid: pid for pid, oid in self._to_official.items()}
        self.catalogue = [
            {"id": self._to_official[pid], "name": f"Part {pid}", "type": "rigid", "collisionEnabled": False}
            for pid in pids
        ]
        self._states = 0  # states committed since the start: the official "index"
        self._sizes: dict[str, list[float]] | None = None  # mesh geom sizes, computed on first use
        self._lock = threading.Lock()

    # -------------------------------------------------------------------- definitions
    def definitions(self) -> list[dict]:
        """``{name, description, inputSchema, annotations}`` of each registered tool, in order."""
        return [
            {
                "name": t.name,
                "description": t.description,
                "inputSchema": t.input_schema,
                "annotations": {"readOnlyHint": t.read_only},
            }
            for t in (PAGE_TOOLS[n] for n in self.tools)
        ]

    def not_registered_message(self, name: Any) -> str:
        why = ""
        if name in ("apply_force", "advance_simulation"):
            why = " (it needs physics, which is disabled in this episode)"
        elif name in PAGE_TOOLS:
            why = " (it is not enabled in this episode)"
        return (
            f"toolName {short_repr(name)} is not registered on the episode page{why}; "
            f"registered tools: {', '.join(self.tools)}"
        )

    # -------------------------------------------------------------------- ids
    def _group_to_official(self, gid: str) -> str:
        return f"group-{self.episode_id}-{gid[1:]}"

    def _project_id(self, oid: Any, *, objects: bool = True, groups: bool = True) -> str:
        if objects and oid in self._to_project:
            return self._to_project[oid]
        if groups:
            for gid in self.episode.scene.groups:
                if self._group_to_official(gid) == oid:
                    return gid
        kinds = " or ".join(k for k, on in (("object", objects), ("group", groups)) if on)
        raise _Refused(f"unknown {kinds} id {short_repr(oid)}; use list_objects for the ids")

    def _official_group(self, rec: dict) -> dict:
        return {
            "id": self._group_to_official(rec["id"]),
            "name": rec["name"],
            "members": [self._to_official[m] for m in rec["members"]],
        }

    def _groups(self) -> list[dict]:
        return [self._official_group(g) for g in self.episode.scene.groups_list()]

    def _camera(self) -> dict:
        cam = self.episode.scene.camera
        return {"position": [float(v) for v in cam.position], "target": [float(v) for v in cam.target]}

    def _size(self, pid: str) -> list[float]:
        if self._sizes is None:
            self._sizes = dict(zip(self.episode.part_ids, mesh_geom_sizes(self.episode.meshes), strict=True))
        return self._sizes[pid]

    def _object(self, pid: str, position: list[float], quaternion: list[float]) -> dict:
        k = sorted(self.episode.part_ids).index(pid)
        return {
            **self.catalogue[k],
            "position": position,
            "quaternion": quaternion,
            "velocity": [0.0] * 6,
            "mass": _MASS,
            "movable": True,
            "inertia": list(_INERTIA),
            "centerOfMass": [0.0, 0.0, 0.0],
            "inertiaQuaternion": [1.0, 0.0, 0.0, 0.0],
            "geometries": [
                {
                    "index": k,
                    "type": _MESH,
                    "size": self._size(pid),
                    "friction": list(_FRICTION),
                    "condim": _CONDIM,
                    "collidable": False,
                }
            ],
        }

    def _to_official_text(self, message: str) -> str:
        """Project part and group ids in a scene message, as the agent knows them."""
        for pid, oid in self._to_official.items():
            message = re.sub(rf"(?<![\w-]){re.escape(pid)}(?![\w-])", oid, message)
        return re.sub(r"(?<![\w-])g(\d+)(?![\w-])", lambda m: f"group-{self.episode_id}-{m[1]}", message)

    # -------------------------------------------------------------------- execution
    def execute(self, name: str, arguments: Any) -> PageReply:
        """Run one page tool call. Raises :class:`NotRegistered` for a name the page does not
        register; every other outcome, refusals included, is a reply and a trajectory line."""
        if name not in self.tools:
            raise NotRegistered(self.not_registered_message(name))
        self.episode.ensure_started()
        with self._lock:
            problems = check_arguments(PAGE_TOOLS[name].input_schema, arguments)
            try:
                if problems:
                    raise _Refused(f"Invalid {name} arguments: " + "; ".join(problems) + ".")
                tool, args = self._project_call(name, arguments)
            except _Refused as exc:
                msg = self.episode.reject(
                    name, arguments if isinstance(arguments, Mapping) else {"_raw": arguments}, str(exc)
                )
                return PageReply({"error": msg, "code": _error_code(msg) if msg != str(exc) else "invalid_argument"})
            try:
                result = self.episode.call(tool, args)
            except EpisodeError as exc:
                msg = self._to_official_text(str(exc))
                return PageReply({"error": msg, "code": _error_code(msg)})
            return self._reply(name, result)

    def _project_call(self, name: str, a: Mapping[str, Any]) -> tuple[str, dict]:
        """The project tool and arguments for an official call with valid arguments."""
        if name in ("translate_objects", "rotate_objects", "group_objects"):
            args = {**a, "ids": [self._project_id(i) for i in a["ids"]]}
            if name == "group_objects":
                args.update(name=a.get("name") or "Group", exclusive=True)
            return name, args
        if name == "ungroup_objects":
            return name, {"ids": [self._project_id(i, objects=False) for i in a["ids"]]}
        if name in ("get_object", "set_object_pose"):
            return name, {**a, "id": self._project_id(a["id"], groups=False)}
        if name == "move_camera":
            return name, {k: (-v if k == "pitch" else v) for k, v in a.items()}
        return name, dict(a)

    def _reply(self, name: str, result: Any) -> PageReply:
        if name in _MUTATIONS:
            self._states += 1
            out: dict[str, Any] = {"status": "completed"}
            if name in _PHYSICAL:
                out["physics"] = "disabled"
            if name == "group_objects":
                out["result"] = self._official_group(result["group"])
            out["index"] = self._states
            return PageReply(out)
        if name == "list_objects":
            return PageReply({"objects": [dict(o) for o in self.catalogue], "groups": self._groups()})
        if name == "get_object":
            return PageReply(self._object(result["id"], result["position"], result["quaternion"]))
        if name == "get_scene":
            return PageReply(
                {
                    "name": self.episode_id,
                    "units": "normalized",
                    "up": "Z",
                    "quaternion": "wxyz",
                    "runtime": {"physics": dict(PHYSICS), "enabledTools": list(self.enabled)},
                    "objects": [dict(o) for o in self.catalogue],
                }
            )
        if name == "get_state":
            poses = result["poses"]
            objects = [
                self._object(pid, poses[pid]["position"], poses[pid]["quaternion"])
                for pid in sorted(self.episode.part_ids)
            ]
            return PageReply(
                {
                    "index": self._states,
                    "units": "normalized",
                    "objects": objects,
                    "groups": self._groups(),
                    "camera": self._camera(),
                    "contacts": [],
                }
            )
        if name == "capture_scene":
            assert isinstance(result, Capture)
            data = base64.b64encode(result.png).decode("ascii")
            return PageReply(
                {
                    "content": [{"type": "image", "mimeType": "image/png", "data": data}],
                    "camera": self._camera(),
                    "render": dict(RENDER),
                },
                png=result.png,
            )
        if name == "start_episode":
            return PageReply({"status": "active"})
        raise AssertionError(f"no reply shape for {name}")  # every registered tool is handled above
