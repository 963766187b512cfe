"""The environment tools of Table A-2: closed argument models and the descriptions agents read.

Each tool is a pydantic argument model (``extra="forbid"``, so the published JSON schema has
``additionalProperties: false``) plus a description that teaches the scene conventions. Numbers
are strict finite floats with the scene's ranges in the schema; optional arguments accept an
explicit ``null`` as "not given" but are published without a null branch, to keep schemas simple
for every harness. Semantics (unknown ids, zero quaternions, ...) are checked by ``aw.scene``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any, Literal

from mcp.server.mcpserver.utilities.func_metadata import ArgModelBase
from pydantic import ConfigDict, Field, ValidationError

from aw.camera import IMAGE_HEIGHT, IMAGE_WIDTH, VERTICAL_FOV_DEG
from aw.scene import MAX_ANGLE_DEG, MAX_COORDINATE, MAX_GROUP_NAME, PITCH_RANGE, YAW_RANGE, ZOOM_RANGE

MAX_ID_CHARS = 128
MAX_QUAT_COMPONENT = 1e6

Coord = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=-MAX_COORDINATE, le=MAX_COORDINATE)]
Angle = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=-MAX_ANGLE_DEG, le=MAX_ANGLE_DEG)]
QuatComponent = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=-MAX_QUAT_COMPONENT, le=MAX_QUAT_COMPONENT)]
Id = Annotated[str, Field(min_length=1, max_length=MAX_ID_CHARS)]
Space = Literal["world", "camera"]

_IDS_DESC = (
    "One or more unique object or group ids (from list_objects). A group id selects all of its "
    "member objects; each object moves at most once."
)
_SPACE_DESC = (
    "Frame of the vector/angles: 'world' (X, Y, Z with +Z up) or 'camera' (the current view's "
    "right, up and forward axes; forward points from the camera into the scene)."
)


def _ids_field(desc: str = _IDS_DESC):
    return Field(min_length=1, max_length=1000, description=desc, json_schema_extra={"uniqueItems": True})


class _Closed(ArgModelBase):
    model_config = ConfigDict(extra="forbid", arbitrary_types_allowed=True)


class NoArgs(_Closed):
    pass


class GetObjectArgs(_Closed):
    id: Id = Field(description="An object id or group id from list_objects.")


class TranslateArgs(_Closed):
    ids: list[Id] = _ids_field()
    delta: list[Coord] = Field(
        min_length=3,
        max_length=3,
        description=f"Translation [dx, dy, dz] in normalized scene units, each within +-{MAX_COORDINATE:g}; "
        "in camera space the components are along right, up and forward.",
    )
    space: Space = Field(default="world", description=_SPACE_DESC)


class RotateArgs(_Closed):
    ids: list[Id] = _ids_field()
    angles: list[Angle] = Field(
        min_length=3,
        max_length=3,
        description=f"Rotation angles [ax, ay, az] in degrees (each within +-{MAX_ANGLE_DEG:g}), applied about "
        "the X axis first, then Y, then Z, right-hand rule. In camera space X, Y, Z are the camera's "
        "right, up and forward axes.",
    )
    space: Space = Field(default="world", description=_SPACE_DESC)
    pivot: list[Coord] | None = Field(
        default=None,
        min_length=3,
        max_length=3,
        description="Optional world point [x, y, z] to rotate about (always world coordinates). Default: the "
        "mean of the selected objects' body origins (not their visual centers).",
    )


class SetPoseArgs(_Closed):
    id: Id = Field(description="One object id (not a group id).")
    position: list[Coord] | None = Field(
        default=None,
        min_length=3,
        max_length=3,
        description="Optional new world position [x, y, z] of the body origin, in normalized scene units.",
    )
    quaternion: list[QuatComponent] | None = Field(
        default=None,
        min_length=4,
        max_length=4,
        description="Optional new world orientation as a quaternion [w, x, y, z] (scalar first); it is "
        "normalized, so it must not be all zeros.",
    )


class GroupArgs(_Closed):
    ids: list[Id] = _ids_field("Objects to group, by object or group id (a group id adds its members).")
    name: str | None = Field(default=None, max_length=MAX_GROUP_NAME, description="Optional display name.")


class UngroupArgs(_Closed):
    ids: list[Id] = _ids_field("One or more unique group ids to dissolve.")


class MoveCameraArgs(_Closed):
    yaw: float | None = Field(
        default=None,
        strict=True,
        allow_inf_nan=False,
        ge=YAW_RANGE[0],
        le=YAW_RANGE[1],
        description="Orbit about the world Z axis through the look-at point, in degrees relative to the "
        "current view (positive moves the camera counterclockwise around the scene, seen from above). Default 0.",
    )
    pitch: float | None = Field(
        default=None,
        strict=True,
        allow_inf_nan=False,
        ge=PITCH_RANGE[0],
        le=PITCH_RANGE[1],
        description="Change of elevation in degrees relative to the current view (positive looks more from "
        "above); the resulting elevation is kept within +-85 degrees. Default 0.",
    )
    zoom: float | None = Field(
        default=None,
        strict=True,
        allow_inf_nan=False,
        ge=ZOOM_RANGE[0],
        le=ZOOM_RANGE[1],
        description="Multiplier of the camera distance: < 1 moves closer, > 1 moves away. Default 1.",
    )
    right: float | None = Field(
        default=None,
        strict=True,
        allow_inf_nan=False,
        ge=-MAX_COORDINATE,
        le=MAX_COORDINATE,
        description="Pan the look-at point along the camera's right axis, in scene units. Default 0.",
    )
    up: float | None = Field(
        default=None,
        strict=True,
        allow_inf_nan=False,
        ge=-MAX_COORDINATE,
        le=MAX_COORDINATE,
        description="Pan the look-at point along the camera's up axis, in scene units. Default 0.",
    )


class StartEpisodeArgs(_Closed):
    task: str | None = Field(
        default=None, max_length=MAX_GROUP_NAME, description="Optional task label (recorded only)."
    )


CONVENTIONS_TEXT = (
    "Scene conventions: normalized scene units; right-handed world with +Z up; a pose is a body "
    "position [x, y, z] plus a unit quaternion [w, x, y, z] (scalar first); angles in degrees. Initial "
    "placements are baked into the part meshes, so every body starts at the identity pose and body "
    "origins need not coincide with visual part centers."
)

_EDIT_NOTE = (
    " Returns execution status only (ok and the ids whose pose changed); call capture_scene to see the "
    "effect. Edits are refused once the execution budget is exhausted."
)


@dataclass(frozen=True)
class ToolSpec:
    name: str
    args: type[_Closed]
    description: str
    kind: Literal["query", "edit", "camera", "capture", "control"]


TOOL_SPECS: tuple[ToolSpec, ...] = (
    ToolSpec(
        "list_objects",
        NoArgs,
        "List the stable object ids and display names, and the current groups (id, name, member ids). "
        "Object ids are anonymized part identifiers; group ids can be used wherever ids are accepted.",
        "query",
    ),
    ToolSpec(
        "get_object",
        GetObjectArgs,
        "Report one object's body pose (position [x, y, z] and quaternion [w, x, y, z], world frame), its "
        "mesh-local bounding extents and local bounding box (min/max, in the mesh's own frame, scene "
        "units), display name and groups. For a group id, report the group's name and member ids. Mesh "
        "vertices and faces are not available: infer shape from captured views. " + CONVENTIONS_TEXT,
        "query",
    ),
    ToolSpec(
        "get_scene",
        NoArgs,
        "Report the scene units and conventions, settings (image size, field of view, argument ranges, "
        "default pivot), the reference condition, every object's pose and local bounding box, groups, the "
        "camera state and the execution budget.",
        "query",
    ),
    ToolSpec(
        "get_state",
        NoArgs,
        "Report the latest body poses of all objects (position [x, y, z], quaternion [w, x, y, z]), the "
        "groups, the camera state (look-at target, yaw, pitch, distance, position and right/up/forward axes) "
        "and the execution budget.",
        "query",
    ),
    ToolSpec(
        "translate_objects",
        TranslateArgs,
        "Move the selected objects (group ids select their members) by one translation vector, in world "
        "coordinates or in camera coordinates (right, up, forward). Relative poses inside the selection "
        "are kept; nothing snaps or collides." + _EDIT_NOTE,
        "edit",
    ),
    ToolSpec(
        "rotate_objects",
        RotateArgs,
        "Rotate the selected objects (group ids select their members) as one rigid body: angles in degrees "
        "applied about the X axis, then Y, then Z (right-hand rule), of the world frame or of the camera "
        "frame (X = right, Y = up, Z = forward), about a pivot point. In the camera frame a positive angle "
        "about forward turns the selection clockwise in the image, about right tilts its top toward the "
        "camera, and about up turns its right side away from the camera. The default pivot is the mean of the "
        "selected objects' body origins; give pivot [x, y, z] (world) to rotate about another point. "
        "Both positions and orientations change." + _EDIT_NOTE,
        "edit",
    ),
    ToolSpec(
        "set_object_pose",
        SetPoseArgs,
        "Set one object's absolute world pose: position [x, y, z] and/or quaternion [w, x, y, z] (give at "
        "least one; the other is kept). The quaternion is normalized. Body origins need not coincide with "
        "visual part centers." + _EDIT_NOTE,
        "edit",
    ),
    ToolSpec(
        "group_objects",
        GroupArgs,
        "Create a logical transformation group of the given objects so that later translate/rotate calls "
        "can move them together by the group id. Nothing moves or snaps. Returns the new group id (g1, g2, "
        "...) and its members. Edits are refused once the execution budget is exhausted.",
        "edit",
    ),
    ToolSpec(
        "ungroup_objects",
        UngroupArgs,
        "Dissolve the given groups. Nothing moves; the member objects keep their poses. Edits are refused "
        "once the execution budget is exhausted.",
        "edit",
    ),
    ToolSpec(
        "capture_scene",
        NoArgs,
        f"Render the current view as a {IMAGE_WIDTH}x{IMAGE_HEIGHT} PNG image with a {VERTICAL_FOV_DEG:g} degree "
        "vertical field of view, from the orbit camera (see move_camera). This is the only way to see the "
        "parts and the effect of edits.",
        "capture",
    ),
    ToolSpec(
        "move_camera",
        MoveCameraArgs,
        f"Move the orbit camera (the view only; objects never move): yaw and pitch orbit around the look-at "
        f"point by relative degrees (yaw in [{YAW_RANGE[0]:g}, {YAW_RANGE[1]:g}], pitch in "
        f"[{PITCH_RANGE[0]:g}, {PITCH_RANGE[1]:g}]), zoom multiplies the distance (in [{ZOOM_RANGE[0]:g}, "
        f"{ZOOM_RANGE[1]:g}]), right and up pan the look-at point along the camera's right and up axes (scene "
        "units). All arguments are optional. Returns the new camera state; call capture_scene to see it.",
        "camera",
    ),
    ToolSpec(
        "start_episode",
        StartEpisodeArgs,
        "Mark the interaction as active: starts the episode clock and the execution budget. Call it once "
        "before working on the assembly; repeated calls change nothing.",
        "control",
    ),
)

TOOL_NAMES = tuple(s.name for s in TOOL_SPECS)


def _strip_null_branches(schema: Any) -> Any:
    """Publish ``X | None`` properties as plain ``X`` (null is still accepted on input)."""
    if isinstance(schema, dict):
        any_of = schema.get("anyOf")
        if isinstance(any_of, list) and len(any_of) == 2 and {"type": "null"} in any_of:
            other = next(b for b in any_of if b != {"type": "null"})
            rest = {k: v for k, v in schema.items() if k != "anyOf"}
            if rest.get("default", 0) is None:
                rest.pop("default")
            schema = {**other, **rest}
        return {k: _strip_null_branches(v) for k, v in schema.items()}
    if isinstance(schema, list):
        return [_strip_null_branches(v) for v in schema]
    return schema


def input_schema(spec: ToolSpec) -> dict:
    """The closed JSON schema published for ``spec``."""
    schema = _strip_null_branches(spec.args.model_json_schema(by_alias=True))
    schema.pop("title", None)
    schema.setdefault("properties", {})
    schema["additionalProperties"] = False
    return schema


def _short(value: Any, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def describe_validation_error(spec: ToolSpec, exc: ValidationError) -> str:
    """What was wrong with each argument, and what the tool accepts for those arguments."""
    fields = spec.args.model_fields
    problems: list[str] = []
    named: list[str] = []
    extra = False
    for err in exc.errors():
        loc = list(err.get("loc", ()))
        name = str(loc[0]) if loc else ""
        path = name + "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in loc[1:])
        kind = err.get("type", "")
        if kind == "extra_forbidden":
            problems.append(f"unexpected argument {name!r}")
            extra = True
            continue
        if kind == "missing":
            problems.append(f"{path}: required argument is missing")
        else:
            problems.append(f"{path or 'arguments'}: {err.get('msg', 'invalid')} (got {_short(err.get('input'))})")
        if name in fields and name not in named:
            named.append(name)
    parts = [f"invalid arguments for {spec.name}: " + "; ".join(problems) + "."]
    for n in named:
        f = fields[n]
        parts.append(f"{n} ({'required' if f.is_required() else 'optional'}): {f.description}")
    if extra or not named:
        parts.append(
            "Allowed arguments: " + (", ".join(fields) if fields else "none (call it with no arguments)") + "."
        )
    parts.append("Nothing was changed.")
    return " ".join(parts)
