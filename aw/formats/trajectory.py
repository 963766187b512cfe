"""Episode recordings: ``trajectory.jsonl`` (append-only, flushed per line) and ``final.json``.

Line types, in order: one ``header``, any number of ``call`` lines, at most one ``end``.
A call line carries ``poses`` (every part's pose after the call) only when some pose changed.
A checkpoint for scoring is the initial state plus the state after every pose-changing call.
"""

from __future__ import annotations

import os
import stat
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import orjson
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from aw.formats.common import PoseList
from aw.formats.errors import FormatError
from aw.formats.io import (
    check_format_tag,
    describe_validation_error,
    parse_json_text,
    parse_model,
    read_model,
    write_json_atomic,
)

TRAJECTORY_FORMAT = "assemblyworld.trajectory"
END_REASONS = ("finished", "timeout", "error", "disconnect", "interrupted")


class CameraState(BaseModel):
    model_config = ConfigDict(extra="forbid")
    target: list[float] = Field(min_length=3, max_length=3)
    yaw: float
    pitch: float
    distance: float = Field(gt=0)


class TrajectoryHeader(BaseModel):
    model_config = ConfigDict(extra="forbid")
    type: Literal["header"] = "header"
    format: Literal["assemblyworld.trajectory"] = TRAJECTORY_FORMAT
    format_version: Literal[1] = 1
    task_id: str
    system: str = ""
    started_at: str = Field(description="ISO 8601 UTC time of start_episode (or of the server start)")
    part_ids: list[str] = Field(min_length=1)
    initial_poses: dict[str, PoseList]
    initial_poses_from: str | None = Field(
        default=None,
        description="the poses file the episode started from (aw-serve --initial-poses); absent: the task's layout",
    )
    camera: CameraState | None = None


class TrajectoryCall(BaseModel):
    model_config = ConfigDict(extra="forbid")
    type: Literal["call"] = "call"
    seq: int = Field(ge=1)
    t: float | None = Field(
        default=None,
        description="seconds since the episode clock started (start_episode or "
        "the first edit); absent in the file for calls before it, and filled in by "
        "read_trajectory as a negative time from server_t",
    )
    server_t: float | None = Field(
        default=None, description="seconds since the server started (the header's started_at)"
    )
    tool: str
    args: dict[str, Any] = Field(default_factory=dict)
    ok: bool
    error: str | None = None
    changed: list[str] = Field(default_factory=list)
    poses: dict[str, PoseList] | None = None
    camera: CameraState | None = None
    image: str | None = Field(default=None, description="captured PNG, relative to the run dir")
    episode_active: bool = True


class TrajectoryEnd(BaseModel):
    model_config = ConfigDict(extra="forbid")
    type: Literal["end"] = "end"
    reason: Literal["finished", "timeout", "error", "disconnect", "interrupted"]
    t: float | None = Field(default=None, description="as in a call line; absent if the clock never started")
    server_t: float | None = None
    message: str = ""
    poses: dict[str, PoseList]


class FinalState(BaseModel):
    model_config = ConfigDict(extra="forbid")
    format: Literal["assemblyworld.final"] = "assemblyworld.final"
    format_version: Literal[1] = 1
    task_id: str
    reason: Literal["finished", "timeout", "error", "disconnect", "interrupted"]
    poses: dict[str, PoseList]


@dataclass
class Checkpoint:
    """A scorable state: ``seq`` 0 is the initial state."""

    seq: int
    t: float
    poses: dict[str, list[float]]


@dataclass
class Trajectory:
    path: Path
    header: TrajectoryHeader
    calls: list[TrajectoryCall] = field(default_factory=list)
    end: TrajectoryEnd | None = None
    truncated: bool = False
    problems: list[str] = field(default_factory=list)

    def checkpoints(self) -> list[Checkpoint]:
        """Initial state, then the state after every pose-changing call, in order."""
        out = [Checkpoint(0, 0.0, dict(self.header.initial_poses))]
        for c in self.calls:
            if c.poses is not None:
                out.append(Checkpoint(c.seq, c.t, dict(c.poses)))
        return out

    def final_poses(self) -> dict[str, list[float]]:
        """The end line's poses if the episode closed, else the last recorded state."""
        if self.end is not None:
            return dict(self.end.poses)
        return self.checkpoints()[-1].poses


_RECORDS: dict[str, type[BaseModel]] = {"header": TrajectoryHeader, "call": TrajectoryCall, "end": TrajectoryEnd}


class _BadJSON(Exception):
    def __init__(self, detail: str):
        self.detail = detail


def _parse_line(raw: bytes, lineno: int, path: Path) -> BaseModel:
    try:
        obj = parse_json_text(raw)
    except ValueError as exc:
        raise _BadJSON(str(exc)) from None
    kind = obj.get("type") if isinstance(obj, dict) else None
    if not isinstance(kind, str):
        raise FormatError(path, f"line {lineno}: not a trajectory record (no 'type')")
    model = _RECORDS.get(kind)
    if model is None:
        raise FormatError(path, f"line {lineno}: unknown record type {kind!r}")
    if kind == "header":
        problem = check_format_tag(TrajectoryHeader, obj)
        if problem:
            raise FormatError(path, f"line {lineno}: {problem}")
    try:
        return model.model_validate(obj, strict=True)
    except ValidationError as exc:
        raise FormatError(path, f"line {lineno}: {describe_validation_error(exc)}") from None


def _check_pose_ids(poses: dict | None, part_ids: list[str], what: str, path: Path) -> None:
    """Every recorded pose set names exactly the header's parts."""
    if poses is None:
        return
    if set(poses) != set(part_ids):
        missing = sorted(set(part_ids) - set(poses))
        extra = sorted(set(poses) - set(part_ids))
        raise FormatError(
            path, f"{what}: poses do not match the header's part ids (missing {missing}, unknown {extra})"
        )


class _Records:
    """The ordering rules of a trajectory, applied one record at a time (shared by
    :func:`read_trajectory` and :class:`TrajectoryFollower`). ``keep_calls=False`` keeps only the
    last call (and the count), for readers that need a summary of a long recording."""

    def __init__(self, path: Path, keep_calls: bool = True):
        self.path = path
        self.keep_calls = keep_calls
        self.traj: Trajectory | None = None
        self.n_calls = 0
        self.last_call: TrajectoryCall | None = None
        self.last_image: str | None = None  # the latest capture (relative to the run directory)
        self.clock_offset: float | None = None  # server_t - t: when the episode clock started

    def add(self, rec: BaseModel, i: int) -> None:
        path, traj = self.path, self.traj
        if traj is None:
            if not isinstance(rec, TrajectoryHeader):
                raise FormatError(path, f"line {i}: the first record must be the header")
            if len(set(rec.part_ids)) != len(rec.part_ids):
                raise FormatError(path, f"line {i}: duplicate part ids in the header")
            _check_pose_ids(rec.initial_poses, rec.part_ids, f"line {i}", path)
            self.traj = Trajectory(path=path, header=rec)
            return
        if traj.end is not None:
            raise FormatError(path, f"line {i}: record after the end record")
        if isinstance(rec, TrajectoryHeader):
            raise FormatError(path, f"line {i}: a second header")
        assert isinstance(rec, TrajectoryCall | TrajectoryEnd)
        _check_pose_ids(rec.poses, traj.header.part_ids, f"line {i}", path)
        if isinstance(rec, TrajectoryCall):
            unknown = [c for c in rec.changed if c not in traj.header.part_ids]
            if unknown:
                raise FormatError(path, f"line {i}: changed names unknown part ids {unknown}")
            if rec.changed and rec.poses is None:
                raise FormatError(path, f"line {i}: parts changed but the poses after the call are missing")
            if rec.t is None and rec.server_t is None:
                raise FormatError(path, f"line {i}: a call needs t or server_t")
            if self.last_call is not None and rec.seq <= self.last_call.seq:
                raise FormatError(path, f"line {i}: sequence number {rec.seq} is not increasing")
            self.n_calls += 1
            self.last_call = rec
            if rec.image is not None:
                self.last_image = rec.image
            if self.clock_offset is None and rec.t is not None and rec.server_t is not None:
                self.clock_offset = rec.server_t - rec.t
            if self.keep_calls:
                traj.calls.append(rec)
        else:
            traj.end = rec


def read_trajectory(path: str | Path) -> Trajectory:
    """Read a trajectory. A last line cut mid-write is dropped (``truncated=True``); any other
    malformed line raises :class:`FormatError` naming the file and line."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise FormatError(path, "file not found") from None
    except IsADirectoryError:
        raise FormatError(path, "is a directory, not a file") from None
    except OSError as exc:
        raise FormatError(path, f"cannot be read ({exc.strerror})") from None
    lines = data.split(b"\n")
    complete_tail = data.endswith(b"\n")
    if complete_tail:
        lines = lines[:-1]
    records = _Records(path)
    truncated = False
    for i, raw in enumerate(lines, start=1):
        if not raw.strip():
            continue
        is_last = i == len(lines)
        try:
            rec = _parse_line(raw, i, path)
        except _BadJSON as exc:
            if is_last and not complete_tail:
                truncated = True
                break
            raise FormatError(path, f"line {i}: not valid JSON ({exc.detail})") from None
        records.add(rec, i)
    traj = records.traj
    if traj is None:
        raise FormatError(path, "empty or truncated before the header line")
    _resolve_times(traj)
    traj.truncated = truncated or (traj.end is None)
    if truncated:
        traj.problems.append("last line was cut mid-write and was dropped")
    if traj.end is None:
        traj.problems.append("no end record (the episode did not close)")
    return traj


class TrajectoryFollower:
    """Reads a trajectory while it is being written: each :meth:`poll` reads only the bytes added
    since the last one and applies the rules of :func:`read_trajectory` to every complete line. A
    last line without its newline yet is waited for, not an error; a file replaced by a new
    recording (another inode, or shorter than what was read) is read again from its start, and
    a deleted one is forgotten (``generation`` counts those restarts). Times are as recorded (``t`` is None for calls
    before the episode clock started). Raises :class:`FormatError` naming the file and line;
    ``max_line_bytes`` bounds the memory a hostile file can take."""

    def __init__(self, path: str | Path, keep_calls: bool = True, max_line_bytes: int = 16 << 20):
        self.path = Path(path)
        self.keep_calls = keep_calls
        self.max_line_bytes = max_line_bytes
        self._read_limit = max(2 * max_line_bytes, 64 << 20)  # per poll: a huge file is read in steps
        self.generation = 0
        self._identity: tuple[int, int] | None = None
        self._restart()

    def _restart(self) -> None:
        self._error: FormatError | None = None
        self._records = _Records(self.path, self.keep_calls)
        self._offset = 0
        self._lineno = 0
        self._pending = b""

    @property
    def trajectory(self) -> Trajectory | None:
        """What has been read so far (None before the header line is complete)."""
        return self._records.traj

    @property
    def n_calls(self) -> int:
        return self._records.n_calls

    @property
    def last_call(self) -> TrajectoryCall | None:
        return self._records.last_call

    @property
    def last_image(self) -> str | None:
        """The latest call's capture (relative to the run directory), or None."""
        return self._records.last_image

    @property
    def clock_offset(self) -> float | None:
        """``server_t`` at which the episode clock started, once a call says it."""
        return self._records.clock_offset

    @property
    def waiting(self) -> bool:
        """Whether a line is still being written (bytes after the last newline)."""
        return bool(self._pending)

    def poll(self) -> bool:
        """Read what was appended; True when the file was replaced or complete lines were added.
        A damaged line raises the same :class:`FormatError` on every poll until the file is replaced."""
        try:
            fd = os.open(self.path, os.O_RDONLY)
        except FileNotFoundError:
            if self._identity is not None:  # deleted: what was read of it is dropped
                self.generation += 1
                self._identity = None
                self._restart()
            raise FormatError(self.path, "file not found") from None
        except OSError as exc:
            raise FormatError(self.path, f"cannot be read ({exc.strerror})") from None
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                raise FormatError(self.path, "is not a regular file")
            identity = (st.st_dev, st.st_ino)
            replaced = self._identity is not None and (
                identity != self._identity or st.st_size < self._offset + len(self._pending)
            )
            if replaced:
                self.generation += 1
                self._restart()
            self._identity = identity
            if self._error is not None:
                raise self._error
            start = self._offset + len(self._pending)
            want = min(st.st_size - start, self._read_limit)
            if want <= 0:
                return replaced
            added = os.pread(fd, want, start)
        finally:
            os.close(fd)
        try:
            return self._take(self._pending + added) or replaced
        except FormatError as exc:
            self._error = exc
            raise

    def _take(self, data: bytes) -> bool:
        cut = data.rfind(b"\n") + 1
        complete, self._pending = data[:cut], data[cut:]
        lines = complete.split(b"\n")[:-1]
        for raw in lines:
            self._lineno += 1
            self._offset += len(raw) + 1
            if len(raw) > self.max_line_bytes:
                raise FormatError(self.path, f"line {self._lineno}: longer than {self.max_line_bytes} bytes")
            if not raw.strip():
                continue
            try:
                rec = _parse_line(raw, self._lineno, self.path)
            except _BadJSON as exc:
                raise FormatError(self.path, f"line {self._lineno}: not valid JSON ({exc.detail})") from None
            self._records.add(rec, self._lineno)
        if len(self._pending) > self.max_line_bytes:
            raise FormatError(self.path, f"line {self._lineno + 1}: longer than {self.max_line_bytes} bytes")
        return bool(lines)


def _resolve_times(traj: Trajectory) -> None:
    """Give every call (and the end) a time on the episode clock: calls recorded before the clock
    started carry only ``server_t`` and get ``t = server_t - (server_t at the clock start)`` < 0.
    An episode whose clock never started has its start taken at its last record, so all its
    times are <= 0."""
    start = next((c.server_t - c.t for c in traj.calls if c.t is not None and c.server_t is not None), None)
    end = traj.end
    if start is None and end is not None and end.t is not None and end.server_t is not None:
        start = end.server_t - end.t
    if start is None:
        stamps = [c.server_t for c in traj.calls if c.server_t is not None]
        if end is not None and end.server_t is not None:
            stamps.append(end.server_t)
        start = max(stamps, default=0.0)
    for c in traj.calls:
        if c.t is None:
            c.t = round(c.server_t - start, 6)
    if end is not None and end.t is None:
        end.t = round(end.server_t - start, 6) if end.server_t is not None else 0.0


class RecordingError(Exception):
    """A record could not be written (``reason``: the OS's words, e.g. "No space left on device").
    Nothing of that record is left in the file."""

    def __init__(self, path: Path, reason: str):
        super().__init__(f"{path.name}: {reason}")
        self.path = path
        self.reason = reason


class TrajectoryWriter:
    """Appends records, each written whole and synced before ``call`` returns, so a crash loses at
    most the call in flight.

    Unbuffered on purpose: a buffered file keeps the bytes of a failed write (a full disk) and
    writes them with the next record, so a call the agent was told had failed would appear later
    as recorded. Here a record that cannot be written is cut off again (``RecordingError``) and
    the file ends at the last complete record. Thread-safe; ``close`` is idempotent.
    """

    def __init__(self, path: str | Path, header: TrajectoryHeader):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.exists() and self.path.stat().st_size > 0:
            # Appending a second episode would make the file unreadable (a second header).
            raise FormatError(self.path, "already holds a recording; a trajectory file is written once")
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        self._size = os.fstat(self._fd).st_size
        self._lock = threading.Lock()
        self._closed = False
        try:
            self._write(header)
        except RecordingError:
            self.close()
            raise

    def _write(self, rec: BaseModel) -> None:
        line = encode_record(rec) + b"\n"
        with self._lock:
            if self._closed:
                raise RuntimeError("trajectory already closed")
            try:
                view = memoryview(line)
                while view:
                    view = view[os.write(self._fd, view) :]
                os.fsync(self._fd)
            except OSError as exc:
                try:
                    os.ftruncate(self._fd, self._size)  # drop the part of the line that got written
                except OSError:
                    pass
                raise RecordingError(self.path, exc.strerror or type(exc).__name__) from None
            self._size += len(line)

    def call(self, rec: TrajectoryCall) -> None:
        self._write(rec)

    def end(self, rec: TrajectoryEnd) -> None:
        try:
            self._write(rec)
        finally:
            self.close()

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        with self._lock:
            if not self._closed:
                self._closed = True
                os.close(self._fd)


def encode_record(rec: BaseModel) -> bytes:
    """One record as a JSON line's bytes (no newline)."""
    return orjson.dumps(rec.model_dump(mode="json", exclude_none=True), option=orjson.OPT_SERIALIZE_NUMPY)


def read_final(path: str | Path) -> FinalState:
    return read_model(FinalState, path)


def write_final(path: str | Path, final: FinalState) -> None:
    write_json_atomic(path, final)


def parse_final(data: Any, path: str | Path) -> FinalState:
    return parse_model(FinalState, data, path)
