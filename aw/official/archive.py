"""Official episode archives (``*.episode.zip``): checked reading and deterministic writing.

Members (3DWebAgent ``python/episode_runtime.py`` ``save``/``load``, ``schema/episode.schema.json``;
assembly-world-bench ``assembly_world_bench/episode_io.py``)::

    manifest.json            the episode record; ``hashes`` maps every other member to its SHA-256
    frames.jsonl             one row per recorded frame: {"kind": "initial"|"state"|"trace", ...}
    frames.bin               little-endian float64, one row of ``stateSize`` values per frames.jsonl row
    calls.jsonl              one tool call per line (may be empty)
    events.jsonl             ``request``/``complete`` events of the calls (may be empty; the runtime
                             writes a pair per call, a call cancelled at export has none)
    world/model.xml + world/<assets>   the MJCF world and the files it names, or
    world/model.mjb          a compiled world, declared by ``manifest.model``
    observations/<sha256>.png          captured images, named by their digest

JSONL members are rows joined by ``\\n`` without a trailing newline. Row order: the initial
frame, the states (index 1, 2, ...), then every trace frame; the final state is the state with
the largest index, never the last row.

Nothing is used before the whole archive has been checked; each kind of problem raises its own
error of :mod:`aw.official.errors`, naming the archive and the member.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import re
import stat
import zipfile
import zlib
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from aw.formats.strict_json import MAX_DEPTH, JsonError, JsonLimits, parse_json
from aw.official.errors import (
    ArchiveTooLargeError,
    HashInventoryError,
    InconsistentEpisodeError,
    NotAnArchiveError,
    UnsafeMemberError,
    UnsupportedEpisodeError,
)

__all__ = [
    "FORMAT",
    "VERSION",
    "ENGINE",
    "CONTRACT",
    "MJB_MODEL",
    "TOOL_NAMES",
    "CALL_NAMES",
    "ArchiveLimits",
    "Frame",
    "EpisodeArchive",
    "check_member_name",
    "read_archive",
    "archive_bytes",
    "write_archive",
    "iso_timestamp",
    "parse_timestamp",
]

FORMAT = "3dwebagent-episode"
VERSION = 1
ENGINE = "3.12.0"  # assembly-world-bench common.py ENGINE: the MuJoCo that made the worlds and states
CONTRACT = "3dwebagent-runtime-1"
MJB_MODEL = {"format": "mjb", "path": "model.mjb"}  # the only compiled-world declaration (episode_model.py)
# Page tools an episode may enable or record (episode.schema.json), ``end_episode`` being retired.
TOOL_NAMES = (
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
    "apply_force",
    "start_episode",
    "end_episode",
    "advance_simulation",
)
HUMAN_COMMANDS = ("edit_poses", "set_camera")  # editor commands, recorded with actor "human" only
CALL_NAMES = TOOL_NAMES + HUMAN_COMMANDS
ERROR_CODES = (
    "invalid_argument",
    "disabled",
    "busy",
    "cancelled",
    "unstable_physics",
    "historical_edit",
    "episode_ended",
    "unsupported_capability",
)
CORE_MEMBERS = ("frames.jsonl", "frames.bin", "calls.jsonl", "events.jsonl")

_HEX64 = re.compile(r"[0-9a-f]{64}")
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")

_MANIFEST_REQUIRED = {
    "format",
    "version",
    "engine",
    "name",
    "units",
    "stateSpec",
    "stateSize",
    "runtime",
    "objects",
    "hashes",
    "id",
    "contract",
    "lifecycle",
    "originTime",
    "requiredCapabilities",
    "producer",
}
_MANIFEST_OPTIONAL = {"task", "end", "model"}
_PHYSICS_KEYS = {
    "enabled",
    "gravity",
    "detection",
    "response",
    "strategy",
    "duration",
    "maxDuration",
    "quietDuration",
    "linearThreshold",
    "angularThreshold",
}
_PRODUCER_REQUIRED = {"backend", "engine", "implementation", "language"}
_PRODUCER_OPTIONAL = {"renderer", "build", "engineBuild"}
_FRAME_KEYS = {"index", "camera", "groups", "groupCounter"}
_TRACE_REQUIRED = {"call_id", "phase", "step", "sim_time"}
_TRACE_PHASES = ("input", "physics", "final", "rollback")
_CALL_REQUIRED = {
    "index",
    "name",
    "arguments",
    "timestamp",
    "state_index",
    "status",
    "id",
    "actor",
    "producer",
    "before_index",
    "trace_start",
    "trace_end",
    "sim_start",
    "sim_end",
    "steps",
}
_CALL_OPTIONAL = {"result", "error", "error_code", "cancellation", "transport"}
_EVENT_KEYS = {"index", "call_id", "kind", "timestamp", "sim_time"}


@dataclass(frozen=True)
class ArchiveLimits:
    """What the reader accepts. The sizes are checked against the zip headers before anything is
    inflated (and the inflated bytes against the headers). The JSON limits bound what parsing
    costs: parsed JSON takes up to about 10 times its text in memory (floats in lists), so
    ``max_json_bytes`` (the text of manifest.json, frames.jsonl, calls.jsonl and events.jsonl
    together) bounds the parsed records to about 1 GiB; official episodes hold a few MiB."""

    max_members: int = 100_000
    max_member_bytes: int = 512 << 20
    max_total_bytes: int = 1 << 30
    max_ratio: int = 1000  # inflated / compressed, for members over 1 MiB
    max_json_bytes: int = 64 << 20  # all JSON members together, inflated
    max_row_bytes: int = 4 << 20  # one row of a JSONL member
    max_json_depth: int = MAX_DEPTH  # nested arrays/objects in one row (aw.formats.strict_json)
    max_state_value: float = 1e9  # |value| in an initial or state frame's vector (time, positions, ...)

    @property
    def json(self) -> JsonLimits:
        """The JSON reader's limits for the members (a row's size is checked before, by name)."""
        return JsonLimits(max_depth=self.max_json_depth, max_document_bytes=self.max_json_bytes)


DEFAULT_LIMITS = ArchiveLimits()


@dataclass
class Frame:
    """One ``frames.jsonl`` row and its ``frames.bin`` vector.

    ``record`` is the row without ``kind``: ``index``, ``camera`` ``{position, target}``,
    ``groups``, ``groupCounter``, and for traces ``call_id``, ``phase``, ``step``, ``sim_time``
    (optionally ``applied``). ``integration`` is ``(stateSize,)`` float64.
    """

    kind: str
    record: dict[str, Any]
    integration: np.ndarray

    @property
    def index(self) -> int:
        return int(self.record["index"])


@dataclass
class EpisodeArchive:
    """A checked episode: its manifest, members and records."""

    path: Path
    manifest: dict[str, Any]
    files: dict[str, bytes]  # every member except manifest.json
    initial: Frame
    states: list[Frame] = field(default_factory=list)  # index 1..N in order
    traces: list[Frame] = field(default_factory=list)  # index 0..T-1 in order
    calls: list[dict[str, Any]] = field(default_factory=list)
    events: list[dict[str, Any]] = field(default_factory=list)

    @property
    def lifecycle(self) -> str:
        return str(self.manifest["lifecycle"])

    @property
    def end(self) -> dict[str, Any] | None:
        return self.manifest.get("end")

    @property
    def is_mjb(self) -> bool:
        return "model" in self.manifest

    @property
    def model_member(self) -> str:
        return "world/" + (self.manifest["model"]["path"] if self.is_mjb else "model.xml")

    def world_files(self) -> dict[str, bytes]:
        """The ``world/`` members, keyed by their path inside ``world/``."""
        return {name[len("world/") :]: data for name, data in self.files.items() if name.startswith("world/")}

    def state(self, index: int) -> Frame:
        """The frame with state index ``index`` (0 is the initial frame)."""
        if index == 0:
            return self.initial
        if not 1 <= index <= len(self.states):
            raise IndexError(f"{self.path}: no state {index} (the archive has states 0..{len(self.states)})")
        return self.states[index - 1]

    def final_state(self) -> Frame:
        """The state the official scorer restores: the largest state index, else the initial frame
        (assembly-world-bench ``poses.py``; trace frames never count)."""
        return self.states[-1] if self.states else self.initial

    def object_ids(self) -> list[str]:
        return [o["id"] for o in self.manifest["objects"]]


# ---------------------------------------------------------------------------------------------------
# Reading


def check_member_name(name: str) -> str | None:
    """Why ``name`` may not name an archive member, or None when it may."""
    if not name:
        return "empty name"
    if "\\" in name or _CONTROL.search(name):
        return "contains a backslash or control character"
    if name.startswith("/") or re.match(r"^[A-Za-z]:", name):
        return "is an absolute path"
    if ":" in name:
        return "contains ':'"
    parts = name.split("/")
    if ".." in parts:
        return "contains '..'"
    if any(p in ("", ".") for p in parts):
        return "contains an empty or '.' path component"
    return None


def _members(zf: zipfile.ZipFile, path: Path, limits: ArchiveLimits) -> dict[str, zipfile.ZipInfo]:
    infos = zf.infolist()
    if len(infos) > limits.max_members:
        raise ArchiveTooLargeError(path, f"{len(infos)} members, over the limit of {limits.max_members}")
    out: dict[str, zipfile.ZipInfo] = {}
    total = 0
    for info in infos:
        why = check_member_name(info.filename)
        if why:
            raise UnsafeMemberError(path, f"member {info.filename!r} {why}")
        kind = stat.S_IFMT(info.external_attr >> 16)  # 0 when the writer recorded no file type
        if info.is_dir() or (kind and kind != stat.S_IFREG):
            raise UnsafeMemberError(path, f"member {info.filename!r} is not a regular file")
        if info.filename in out:
            raise UnsafeMemberError(path, f"member {info.filename!r} appears twice")
        if info.file_size > limits.max_member_bytes:
            raise ArchiveTooLargeError(
                path,
                f"member {info.filename!r} inflates to {info.file_size} bytes, over the limit of {limits.max_member_bytes}",
            )
        if info.file_size > (1 << 20) and info.file_size > limits.max_ratio * max(info.compress_size, 1):
            raise ArchiveTooLargeError(
                path,
                f"member {info.filename!r} compresses {info.file_size // max(info.compress_size, 1)}:1, over the limit of {limits.max_ratio}:1",
            )
        total += info.file_size
        out[info.filename] = info
    if total > limits.max_total_bytes:
        raise ArchiveTooLargeError(
            path, f"archive inflates to {total} bytes, over the limit of {limits.max_total_bytes}"
        )
    return out


def _read_member(zf: zipfile.ZipFile, info: zipfile.ZipInfo, path: Path) -> bytes:
    try:
        with zf.open(info) as fh:
            data = fh.read(info.file_size + 1)  # never more than the header promised, plus one byte
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError, RuntimeError, NotImplementedError, ValueError) as exc:
        raise NotAnArchiveError(path, f"member {info.filename!r} cannot be inflated ({exc})") from None
    if len(data) != info.file_size:
        raise ArchiveTooLargeError(path, f"member {info.filename!r} inflates to another size than its zip header says")
    return data


def _json(data: bytes, path: Path, where: str, limits: ArchiveLimits = DEFAULT_LIMITS) -> Any:
    try:
        return parse_json(data, limits.json)
    except JsonError as exc:
        raise InconsistentEpisodeError(path, f"{where}: {exc}") from None


def _jsonl(
    files: dict[str, bytes], name: str, path: Path, limits: ArchiveLimits = DEFAULT_LIMITS
) -> list[dict[str, Any]]:
    rows = []
    for k, line in enumerate(files[name].splitlines(), start=1):
        if not line.strip():
            continue
        if len(line) > limits.max_row_bytes:
            raise ArchiveTooLargeError(
                path, f"{name}: line {k}: {len(line)} bytes, over the limit of {limits.max_row_bytes} per row"
            )
        row = _json(line, path, f"{name}: line {k}", limits)
        if not isinstance(row, dict):
            raise InconsistentEpisodeError(path, f"{name}: line {k}: expected a JSON object")
        rows.append(row)
    return rows


def read_archive(
    path: str | Path, *, verify_hashes: bool = True, limits: ArchiveLimits = DEFAULT_LIMITS
) -> EpisodeArchive:
    """Check an episode archive completely and return its records (see the module doc)."""
    path = Path(path)
    if not path.is_file():
        raise NotAnArchiveError(path, "episode archive not found")
    try:
        zf = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise NotAnArchiveError(path, f"not a zip archive ({exc})") from None
    with zf:
        infos = _members(zf, path, limits)
        if "manifest.json" not in infos:
            raise HashInventoryError(path, "manifest.json: member missing")
        json_bytes = sum(
            infos[n].file_size for n in ("manifest.json", *CORE_MEMBERS) if n in infos and n != "frames.bin"
        )
        if json_bytes > limits.max_json_bytes:
            raise ArchiveTooLargeError(
                path, f"the JSON members inflate to {json_bytes} bytes, over the limit of {limits.max_json_bytes}"
            )
        manifest = _json(_read_member(zf, infos["manifest.json"], path), path, "manifest.json", limits)
        _check_identity(manifest, path)
        hashes = manifest.get("hashes")
        if not isinstance(hashes, dict):
            raise HashInventoryError(path, "manifest.json: hashes: expected an object {member: sha256}")
        listed, present = set(hashes), set(infos) - {"manifest.json"}
        if listed != present:
            detail = []
            if present - listed:
                detail.append(f"members not in hashes: {sorted(present - listed)}")
            if listed - present:
                detail.append(f"hashes names absent members: {sorted(listed - present)}")
            raise HashInventoryError(path, "manifest.json: " + "; ".join(detail))
        files = {}
        for name in sorted(present):
            data = _read_member(zf, infos[name], path)
            digest = hashes[name]
            if not isinstance(digest, str) or not _HEX64.fullmatch(digest):
                raise HashInventoryError(path, f"manifest.json: hashes[{name!r}]: expected 64 lowercase hex digits")
            if verify_hashes and hashlib.sha256(data).hexdigest() != digest:
                raise HashInventoryError(path, f"member {name!r}: SHA-256 differs from manifest.json hashes")
            files[name] = data
    return _episode(path, manifest, files, limits)


def _check_identity(manifest: Any, path: Path) -> None:
    if not isinstance(manifest, dict):
        raise UnsupportedEpisodeError(path, "manifest.json: expected a JSON object")
    for key, want in (("format", FORMAT), ("version", VERSION), ("engine", ENGINE), ("contract", CONTRACT)):
        got = manifest.get(key)
        if got != want or isinstance(got, bool):
            raise UnsupportedEpisodeError(path, f"manifest.json: {key} is {got!r}, expected {want!r}")


def _episode(
    path: Path, manifest: dict[str, Any], files: dict[str, bytes], limits: ArchiveLimits = DEFAULT_LIMITS
) -> EpisodeArchive:
    bad = InconsistentEpisodeError
    _check_manifest(manifest, files, path)
    for name in files:
        if name in CORE_MEMBERS or name.startswith("world/"):
            continue
        if name.startswith("observations/"):
            if name[len("observations/") :] != hashlib.sha256(files[name]).hexdigest() + ".png":
                raise bad(path, f"member {name!r}: an observation is named by the SHA-256 of its bytes plus .png")
            continue
        raise bad(
            path, f"member {name!r}: not an episode member (only frames, calls, events, world/ and observations/)"
        )
    missing = [m for m in CORE_MEMBERS if m not in files]
    if missing:
        raise bad(path, f"members missing: {missing}")
    rows = _jsonl(files, "frames.jsonl", path, limits)
    size = manifest["stateSize"]
    raw = files["frames.bin"]
    if len(raw) != len(rows) * size * 8:
        raise bad(
            path,
            f"frames.bin: {len(raw)} bytes, but {len(rows)} frames.jsonl rows of stateSize {size} need {len(rows) * size * 8}",
        )
    vectors = np.frombuffer(raw, dtype="<f8").reshape(len(rows), size).astype(np.float64)
    finite = np.isfinite(vectors).all(axis=1)
    if not finite.all():
        raise bad(path, f"frames.bin: row {int(np.argmin(finite))} holds a non-finite value")
    frames: dict[str, list[Frame]] = {"initial": [], "state": [], "trace": []}
    for k, (row, vector) in enumerate(zip(rows, vectors, strict=True), start=1):
        kind = row.get("kind")
        if not isinstance(kind, str) or kind not in frames:
            raise bad(path, f"frames.jsonl: line {k}: kind {kind!r}, expected initial, state or trace")
        if kind == "initial" and k != 1:
            raise bad(path, f"frames.jsonl: line {k}: the initial frame must be the first row")
        record = {a: b for a, b in row.items() if a != "kind"}
        _check_frame(record, kind == "trace", path, f"frames.jsonl: line {k}")
        if kind != "trace" and not np.abs(vector).max(initial=0.0) <= limits.max_state_value:
            # traces may hold an unstable step that was rolled back; states are what gets restored
            raise bad(
                path,
                f"frames.bin: row {k - 1} ({kind} {record['index']}) holds a value beyond +-{limits.max_state_value:g}",
            )
        frames[kind].append(Frame(kind, record, vector))
    if len(frames["initial"]) != 1:
        raise bad(path, f"frames.jsonl: {len(frames['initial'])} initial frames, expected exactly one")
    for kind, first in (("state", 1), ("trace", 0)):
        got = [f.index for f in frames[kind]]
        if got != list(range(first, first + len(got))):
            raise bad(
                path,
                f"frames.jsonl: {kind} indices {got[:8]}{'...' if len(got) > 8 else ''} are not {first}, {first + 1}, ... in order",
            )
    episode = EpisodeArchive(
        path,
        manifest,
        files,
        frames["initial"][0],
        frames["state"],
        frames["trace"],
        _jsonl(files, "calls.jsonl", path, limits),
        _jsonl(files, "events.jsonl", path, limits),
    )
    if episode.initial.index != 0:
        raise bad(path, "frames.jsonl: the initial frame's index must be 0")
    _check_groups(episode, path)
    _check_calls(episode, path)
    if manifest["lifecycle"] == "setup" and (episode.calls or episode.states or episode.traces or episode.events):
        raise bad(path, "manifest.json: lifecycle 'setup' with recorded calls, states, traces or events")
    return episode


def _is_int(v: Any, minimum: int = 0) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= minimum


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _vec3(v: Any) -> bool:
    return isinstance(v, list) and len(v) == 3 and all(_is_number(x) for x in v)


def _keys(obj: Any, required: set[str], optional: set[str], path: Path, where: str) -> dict[str, Any]:
    if not isinstance(obj, dict):
        raise InconsistentEpisodeError(path, f"{where}: expected an object")
    missing = required - set(obj)
    if missing:
        raise InconsistentEpisodeError(path, f"{where}: missing {sorted(missing)}")
    extra = set(obj) - required - optional
    if extra:
        raise InconsistentEpisodeError(path, f"{where}: unknown keys {sorted(extra)}")
    return obj


def _check_manifest(m: dict[str, Any], files: dict[str, bytes], path: Path) -> None:
    bad = InconsistentEpisodeError
    _keys(m, _MANIFEST_REQUIRED, _MANIFEST_OPTIONAL, path, "manifest.json")
    checks = [
        ("id", isinstance(m["id"], str) and bool(m["id"]), "a non-empty string"),
        ("name", isinstance(m["name"], str), "a string"),
        ("units", m["units"] in ("SI", "normalized"), "'SI' or 'normalized'"),
        ("stateSpec", _is_int(m["stateSpec"]), "an integer >= 0"),
        ("stateSize", _is_int(m["stateSize"], 1), "an integer >= 1"),
        ("lifecycle", m["lifecycle"] in ("setup", "active", "ended"), "'setup', 'active' or 'ended'"),
        ("originTime", _is_number(m["originTime"]), "a number"),
        (
            "requiredCapabilities",
            isinstance(m["requiredCapabilities"], list)
            and all(isinstance(c, str) for c in m["requiredCapabilities"])
            and len(set(m["requiredCapabilities"])) == len(m["requiredCapabilities"]),
            "a list of distinct strings",
        ),
        ("task", isinstance(m.get("task", ""), str), "a string"),
        ("objects", isinstance(m["objects"], list), "a list"),
    ]
    for key, ok, want in checks:
        if not ok:
            raise bad(path, f"manifest.json: {key} must be {want}, got {m[key]!r}")
    producer = _keys(m["producer"], _PRODUCER_REQUIRED, _PRODUCER_OPTIONAL, path, "manifest.json: producer")
    _check_producer(producer, path, "manifest.json: producer")
    runtime = _keys(m["runtime"], {"physics", "enabledTools"}, set(), path, "manifest.json: runtime")
    physics = _keys(runtime["physics"], _PHYSICS_KEYS, set(), path, "manifest.json: runtime.physics")
    for key in ("enabled", "detection", "response"):
        if not isinstance(physics[key], bool):
            raise bad(path, f"manifest.json: runtime.physics.{key} must be true or false")
    if not _vec3(physics["gravity"]) or physics["strategy"] not in ("fixed", "settle"):
        raise bad(path, "manifest.json: runtime.physics: gravity must be 3 numbers and strategy 'fixed' or 'settle'")
    for key in ("duration", "maxDuration", "quietDuration", "linearThreshold", "angularThreshold"):
        if not _is_number(physics[key]) or not 0 < physics[key] <= 60:
            raise bad(path, f"manifest.json: runtime.physics.{key} must lie in (0, 60], got {physics[key]!r}")
    tools = runtime["enabledTools"]
    if (
        not isinstance(tools, list)
        or len(set(map(str, tools))) != len(tools)
        or any(t not in TOOL_NAMES for t in tools)
    ):
        raise bad(path, f"manifest.json: runtime.enabledTools must be distinct tool names of {list(TOOL_NAMES)}")
    ids = []
    for k, obj in enumerate(m["objects"]):
        _keys(obj, {"id", "name", "type"}, {"collisionEnabled"}, path, f"manifest.json: objects[{k}]")
        if (
            not isinstance(obj["id"], str)
            or not obj["id"]
            or not isinstance(obj["name"], str)
            or obj["type"] != "rigid"
            or not isinstance(obj.get("collisionEnabled", False), bool)
        ):
            raise bad(
                path,
                f"manifest.json: objects[{k}]: expected {{id: non-empty string, name: string, type: 'rigid', collisionEnabled?: bool}}",
            )
        ids.append(obj["id"])
    if len(set(ids)) != len(ids):
        raise bad(path, "manifest.json: objects: object ids must be distinct")
    if (m["lifecycle"] == "ended") != ("end" in m):
        raise bad(path, "manifest.json: end is present exactly when lifecycle is 'ended'")
    if "end" in m:
        end = _keys(m["end"], {"reason"}, {"outcome"}, path, "manifest.json: end")
        if not isinstance(end["reason"], str) or not isinstance(end.get("outcome", ""), str):
            raise bad(path, "manifest.json: end: reason and outcome must be strings")
    if "model" in m and m["model"] != MJB_MODEL:
        raise bad(path, f"manifest.json: model must be {MJB_MODEL}, got {m['model']!r}")
    member = "world/" + (MJB_MODEL["path"] if "model" in m else "model.xml")
    if member not in files:
        raise bad(path, f"{member}: member missing (the episode's world)")


def _check_producer(producer: dict[str, Any], path: Path, where: str) -> None:
    ok = (
        producer["backend"] in ("wasm", "native")
        and producer["engine"] == ENGINE
        and isinstance(producer["implementation"], str)
        and bool(producer["implementation"])
        and isinstance(producer["language"], str)
        and bool(producer["language"])
        and isinstance(producer.get("renderer", ""), str)
        and all(
            _HEX64.fullmatch(producer[k])
            for k in ("build", "engineBuild")
            if k in producer and isinstance(producer[k], str)
        )
        and all(isinstance(producer[k], str) for k in ("build", "engineBuild") if k in producer)
    )
    if not ok:
        raise InconsistentEpisodeError(
            path,
            f"{where}: expected backend wasm|native, engine {ENGINE}, non-empty implementation and language, 64-hex build digests",
        )


def _check_frame(rec: dict[str, Any], trace: bool, path: Path, where: str) -> None:
    bad = InconsistentEpisodeError
    _keys(rec, _FRAME_KEYS | (_TRACE_REQUIRED if trace else set()), {"applied"} if trace else set(), path, where)
    camera = _keys(rec["camera"], {"position", "target"}, set(), path, f"{where}: camera")
    if not (
        _is_int(rec["index"]) and _is_int(rec["groupCounter"]) and _vec3(camera["position"]) and _vec3(camera["target"])
    ):
        raise bad(path, f"{where}: index and groupCounter must be integers >= 0, camera position/target 3 numbers")
    if math.dist(camera["position"], camera["target"]) < 0.001:
        raise bad(path, f"{where}: camera position and target less than 0.001 apart")
    if not isinstance(rec["groups"], list):
        raise bad(path, f"{where}: groups must be a list")
    for g in rec["groups"]:
        _keys(g, {"id", "name", "members"}, set(), path, f"{where}: group")
        members = g["members"]
        if not (
            isinstance(g["id"], str)
            and g["id"]
            and isinstance(g["name"], str)
            and isinstance(members, list)
            and len(members) >= 2
            and all(isinstance(x, str) and x for x in members)
            and len(set(members)) == len(members)
        ):
            raise bad(path, f"{where}: a group needs an id, a name and at least two distinct members")
    if trace:
        if not (
            isinstance(rec["call_id"], str)
            and rec["phase"] in _TRACE_PHASES
            and _is_int(rec["step"])
            and _is_number(rec["sim_time"])
        ):
            raise bad(
                path,
                f"{where}: a trace needs call_id, phase in {list(_TRACE_PHASES)}, step >= 0 and a numeric sim_time",
            )
        if "applied" in rec:
            applied = _keys(rec["applied"], {"body", "values"}, set(), path, f"{where}: applied")
            if not (_is_int(applied["body"], 1) and _vec3(applied["values"])):
                raise bad(path, f"{where}: applied needs body >= 1 and 3 values")


def _check_groups(ep: EpisodeArchive, path: Path) -> None:
    objects = set(ep.object_ids())
    for frame in [ep.initial, *ep.states, *ep.traces]:
        seen_groups: set[str] = set()
        seen_members: set[str] = set()
        for g in frame.record["groups"]:
            if g["id"] in objects or g["id"] in seen_groups:
                raise InconsistentEpisodeError(
                    path, f"frames.jsonl: {frame.kind} {frame.index}: group id {g['id']!r} repeats or names an object"
                )
            seen_groups.add(g["id"])
            for member in g["members"]:
                if member not in objects or member in seen_members:
                    raise InconsistentEpisodeError(
                        path,
                        f"frames.jsonl: {frame.kind} {frame.index}: group member {member!r} unknown or in two groups",
                    )
                seen_members.add(member)


def parse_timestamp(text: Any) -> datetime | None:
    """An ISO-8601 time (``Z`` allowed), or None when ``text`` is not one."""
    if not isinstance(text, str):
        return None
    try:
        return datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        return None


def iso_timestamp(moment: datetime) -> str:
    """The runtime's timestamp form: UTC, milliseconds, ``Z`` (``2026-01-02T03:04:05.678Z``)."""
    return moment.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _check_calls(ep: EpisodeArchive, path: Path) -> None:
    bad = InconsistentEpisodeError
    n_states, n_traces = len(ep.states), len(ep.traces)
    owners: dict[str, dict[str, Any]] = {}
    for k, call in enumerate(ep.calls):
        where = f"calls.jsonl: line {k + 1}"
        _keys(call, _CALL_REQUIRED, _CALL_OPTIONAL, path, where)
        if call["index"] != k or isinstance(call["index"], bool):
            raise bad(path, f"{where}: index {call['index']!r}, expected {k}")
        if not isinstance(call["id"], str) or call["id"] in owners:
            raise bad(path, f"{where}: id {call['id']!r} missing or repeated")
        if call["name"] not in CALL_NAMES:
            raise bad(path, f"{where}: name {call['name']!r} is not a tool or editor command")
        if call["actor"] not in ("agent", "human") or (call["name"] in HUMAN_COMMANDS and call["actor"] != "human"):
            raise bad(path, f"{where}: actor {call['actor']!r} (editor commands are 'human' only)")
        if not isinstance(call["arguments"], dict):
            raise bad(path, f"{where}: arguments must be an object")
        if parse_timestamp(call["timestamp"]) is None:
            raise bad(path, f"{where}: timestamp {call['timestamp']!r} is not an ISO-8601 time")
        _keys(call["producer"], _PRODUCER_REQUIRED, _PRODUCER_OPTIONAL, path, f"{where}: producer")
        _check_producer(call["producer"], path, f"{where}: producer")
        if call["status"] not in ("completed", "error") or (call["status"] == "error") != ("error" in call):
            raise bad(
                path, f"{where}: status must be completed or error, with an error message exactly when it is error"
            )
        if "error" in call and not isinstance(call["error"], str):
            raise bad(path, f"{where}: error must be a string")
        if "error_code" in call and call["error_code"] not in ERROR_CODES:
            raise bad(path, f"{where}: error_code {call['error_code']!r} is not one of {list(ERROR_CODES)}")
        if "cancellation" in call:
            c = _keys(call["cancellation"], {"phase", "step"}, set(), path, f"{where}: cancellation")
            if not isinstance(c["phase"], str) or not _is_int(c["step"]):
                raise bad(path, f"{where}: cancellation needs a phase string and step >= 0")
        if "transport" in call and not isinstance(call["transport"], str):
            raise bad(path, f"{where}: transport must be a string")
        if not all(
            _is_int(call[key]) for key in ("before_index", "state_index", "trace_start", "trace_end", "steps")
        ) or not all(_is_number(call[key]) for key in ("sim_start", "sim_end")):
            raise bad(path, f"{where}: indices and steps must be integers >= 0, sim_start/sim_end numbers")
        if call["before_index"] > n_states or call["state_index"] > n_states:
            raise bad(
                path,
                f"{where}: before_index {call['before_index']} / state_index {call['state_index']} name a state the archive lacks (0..{n_states})",
            )
        if not call["trace_start"] <= call["trace_end"] <= n_traces:
            raise bad(
                path, f"{where}: trace range [{call['trace_start']}, {call['trace_end']}) is outside 0..{n_traces}"
            )
        owners[call["id"]] = call
    for trace in ep.traces:
        owner = owners.get(trace.record["call_id"])
        if owner is None or not owner["trace_start"] <= trace.index < owner["trace_end"]:
            raise bad(
                path,
                f"frames.jsonl: trace {trace.index} lies outside the trace range of its call {trace.record['call_id']!r}",
            )
    _check_events(ep.events, path)


def _check_events(events: list[dict[str, Any]], path: Path) -> None:
    """Each ``events.jsonl`` row as the episode schema describes one, and nothing more.

    The official scorer's reader (assembly-world-bench ``episode_io.py``) checks events against
    ``episode.schema.json`` only: no rule ties them to the calls. A call cancelled while the page
    was exported has none (its physics traces follow the last state), and such an episode is
    scored (from its last state), so the order, number and owners of events are not checked.
    """
    for k, event in enumerate(events):
        where = f"events.jsonl: line {k + 1}"
        _keys(event, _EVENT_KEYS, set(), path, where)
        if not (
            _is_int(event["index"])
            and isinstance(event["call_id"], str)
            and event["kind"] in ("request", "complete")
            and isinstance(event["timestamp"], str)
            and _is_number(event["sim_time"])
        ):
            raise InconsistentEpisodeError(
                path,
                f"{where}: expected index >= 0, call_id and timestamp strings, "
                "kind request or complete, a numeric sim_time",
            )


# ---------------------------------------------------------------------------------------------------
# Writing


def _dumps(value: Any) -> str:
    return json.dumps(value, separators=(",", ":"), allow_nan=False)


def archive_bytes(ep: EpisodeArchive) -> bytes:
    """The archive of ``ep`` as the official writers lay it out: ``hashes`` recomputed, rows in
    the order initial, states, traces, members sorted, DEFLATE, fixed member dates (so the same
    episode always gives the same bytes). ``ep.files`` supplies ``world/`` and
    ``observations/``; the record members are made from the records."""
    files = {n: d for n, d in ep.files.items() if n.startswith(("world/", "observations/"))}
    frames = [ep.initial, *ep.states, *ep.traces]
    files["frames.bin"] = np.asarray([f.integration for f in frames], dtype="<f8").tobytes()
    files["frames.jsonl"] = "\n".join(_dumps({"kind": f.kind, **f.record}) for f in frames).encode()
    files["calls.jsonl"] = "\n".join(_dumps(c) for c in ep.calls).encode()
    files["events.jsonl"] = "\n".join(_dumps(e) for e in ep.events).encode()
    manifest = dict(ep.manifest, hashes={n: hashlib.sha256(d).hexdigest() for n, d in sorted(files.items())})
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, data in [*sorted(files.items()), ("manifest.json", _dumps(manifest).encode())]:
            info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o100644 << 16
            zf.writestr(info, data)
    return buffer.getvalue()


def write_archive(ep: EpisodeArchive, path: str | Path) -> EpisodeArchive:
    """Write ``ep`` to ``path`` (atomically) after checking that the reader accepts it; returns
    the archive as read back."""
    path = Path(path)
    data = archive_bytes(ep)
    tmp = path.with_name(path.name + ".tmp")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp.write_bytes(data)
    try:
        written = read_archive(tmp)
    except Exception:
        tmp.unlink(missing_ok=True)
        raise
    tmp.replace(path)
    written.path = path
    return written
