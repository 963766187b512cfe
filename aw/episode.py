"""One recorded assembly episode: the scene, its budget, captures, and the run directory.

This is the logic behind ``aw-serve`` that has nothing to do with MCP: every environment tool
of Table A-2 is a method reached through :meth:`Episode.call`, which validates, executes,
records one ``trajectory.jsonl`` line (ok or error) and returns a result that is safe to show
an agent (no vertices, faces, targets or file paths). The MCP adapter in ``aw_server`` only
turns these results and :class:`EpisodeError` into MCP content and tool errors.

Timing and recording rules (also in ``docs/harnesses.md``):

- The header line is written when the episode object is created (server start); its
  ``started_at`` is that time, and every record carries ``server_t``, seconds since then.
- The episode clock and the execution budget start at the first ``start_episode`` call or the
  first edit, whichever comes first, so an agent that never calls ``start_episode`` is still
  limited; later ``start_episode`` calls are idempotent (recorded, nothing changes). ``t`` is
  seconds on that clock. Calls before it are recorded with ``episode_active: false`` and no
  ``t``; the trajectory reader gives them their real, negative time before the clock start.
- After the budget runs out, pose and group edits are refused with an error (queries, camera
  moves and captures still work), the state is kept, ``final.json`` is written at once with
  reason ``timeout``, and the closing line says ``timeout``.
- :meth:`Episode.close` writes the closing line and ``final.json``; it is idempotent and is
  called however the session ends (client disconnect, signal, crash).
"""

from __future__ import annotations

import inspect
import io
import logging
import math
import shutil
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from aw.camera import IMAGE_HEIGHT, IMAGE_WIDTH, VERTICAL_FOV_DEG
from aw.formats import (
    EndReason,
    FinalState,
    RecordingError,
    Task,
    TrajectoryCall,
    TrajectoryEnd,
    TrajectoryHeader,
    TrajectoryWriter,
    write_final,
)
from aw.formats.task import MAX_BUDGET_MINUTES
from aw.formats.trajectory import CameraState
from aw.runlock import RunDirBusy, RunDirLock
from aw.scene import (
    MAX_ANGLE_DEG,
    MAX_COORDINATE,
    MAX_GROUP_NAME,
    PITCH_RANGE,
    YAW_RANGE,
    ZOOM_RANGE,
    Scene,
    SceneError,
    scene_from_meshes,
)

log = logging.getLogger(__name__)

TRAJECTORY_FILE = "trajectory.jsonl"
FINAL_FILE = "final.json"
CAPTURE_DIR = "captures"
# Tools whose effect is a pose or group edit: refused once the budget is exhausted.
EDIT_TOOLS = frozenset({"translate_objects", "rotate_objects", "set_object_pose", "group_objects", "ungroup_objects"})
# Recorded arguments are the agent's own input; cap their size so a runaway call cannot bloat the file.
MAX_RECORDED_ARGS_CHARS = 20_000
# Deeper argument values are recorded as a placeholder (JSON writers refuse a few hundred levels).
MAX_RECORDED_DEPTH = 32
PNG_COMPRESS_LEVEL = 3


class EpisodeError(Exception):
    """A refused or failed call. The message is meant for the agent: it says what was wrong and
    what is allowed, and never contains geometry, targets or file paths."""


class _RecordingFailed(Exception):
    """The run directory stopped taking writes (``reason``: the OS's words)."""

    def __init__(self, reason: str):
        self.reason = reason


class RunDirError(Exception):
    """The run directory cannot be used (it holds a recording, a live process is recording into
    it, or it is not writable)."""


@dataclass
class Capture:
    """A rendered view: ``png`` bytes, and ``path`` of the kept copy relative to the run dir."""

    png: bytes
    path: str
    width: int
    height: int
    camera: dict


@dataclass
class _Outcome:
    result: Any
    changed: list[str] = field(default_factory=list)
    image: str | None = None


def _utc_now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _recordable_text(s: str) -> str:
    """``s``, with what UTF-8 cannot hold (lone UTF-16 surrogates, as JSON's ``\\ud800`` decodes
    to) written as backslash escapes."""
    try:
        s.encode("utf-8")
        return s
    except UnicodeEncodeError:
        return s.encode("utf-8", "backslashreplace").decode("utf-8")


def _jsonable_args(args: Mapping[str, Any]) -> dict[str, Any]:
    """The call's arguments as plain JSON that any JSON writer takes: NaN/inf and integers beyond
    64 bits become strings, lone surrogates are escaped, nesting deeper than
    ``MAX_RECORDED_DEPTH`` becomes a named placeholder, and oversized input is cut."""

    def clean(v, depth):
        if isinstance(v, str):
            return _recordable_text(v)
        if isinstance(v, float) and not math.isfinite(v):
            return repr(v)
        if isinstance(v, int) and not isinstance(v, bool) and not -(2**63) <= v < 2**64:
            # beyond what JSON writers (orjson) take: kept as text, or its size if even that is huge
            return str(v) if v.bit_length() < 14_000 else f"<integer of {v.bit_length()} bits>"
        if isinstance(v, (int, float, bool)) or v is None:
            return v
        if isinstance(v, (Mapping, list, tuple, np.ndarray)) and depth >= MAX_RECORDED_DEPTH:
            return f"<nested deeper than {MAX_RECORDED_DEPTH} levels>"
        if isinstance(v, Mapping):
            return {_recordable_text(str(k)): clean(x, depth + 1) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [clean(x, depth + 1) for x in v]
        if isinstance(v, np.ndarray):
            return clean(v.tolist(), depth)
        return _recordable_text(repr(v))

    out = {_recordable_text(str(k)): clean(v, 1) for k, v in dict(args).items()}
    size = len(repr(out))
    if size > MAX_RECORDED_ARGS_CHARS:
        return {"_truncated": f"arguments of {size} characters were not recorded"}
    return out


class Episode:
    """The scene of one task plus its recorder and budget.

    ``meshes``: the baked part meshes in ``task.parts`` order (``aw.meshes.load_task_meshes``).
    ``renderer_factory(meshes)`` returns an object with ``render(poses (P, 7), camera) ->
    PIL.Image`` and ``close()``; it is called on the first capture (default:
    ``aw.render.OffscreenRenderer``). ``budget_minutes`` defaults to the task's budget.
    ``clock`` is a monotonic seconds counter. ``initial_poses`` (part id -> pose) starts the
    scene from those poses instead of the task's layout (identity); ``initial_poses_from`` names
    where they came from, recorded in the trajectory header.
    """

    def __init__(
        self,
        task: Task,
        meshes: Sequence,
        run_dir: str | Path,
        *,
        system: str = "",
        budget_minutes: float | None = None,
        renderer_factory: Callable[[list], Any] | None = None,
        clock: Callable[[], float] = time.monotonic,
        overwrite: bool = False,
        initial_poses: Mapping[str, Sequence[float]] | None = None,
        initial_poses_from: str | None = None,
    ):
        if len(meshes) != len(task.parts):
            raise ValueError(f"{len(meshes)} meshes for {len(task.parts)} parts")
        budget = task.budget_minutes if budget_minutes is None else float(budget_minutes)
        if not (math.isfinite(budget) and 0 < budget <= MAX_BUDGET_MINUTES):
            raise ValueError(
                f"budget_minutes must be a positive number of at most {MAX_BUDGET_MINUTES:g}, got {budget_minutes!r}"
            )
        self.task = task
        self.part_ids = task.part_ids
        self.budget_s = 60.0 * budget
        self.run_dir = Path(run_dir)
        self._meshes = list(meshes)
        self._renderer_factory = renderer_factory
        self._renderer: Any = (
            None  # the factory's renderer (aw.render.OffscreenRenderer by default), made on first capture
        )
        self._clock = clock
        self._lock = threading.RLock()
        self._seq = 0
        self._t0: float | None = None
        self._server_t0 = clock()
        self._timed_out = False
        self._closed = False
        self._timer: threading.Timer | None = None
        self.end_reason: EndReason | None = None
        # Why the recording failed (a full disk, ...); from then on no call is taken.
        self.recording_failure: str | None = None

        self.scene: Scene = scene_from_meshes(self.part_ids, self._meshes)
        self._initial_poses_from = initial_poses_from
        if initial_poses is not None:
            self._start_from(initial_poses)
        # Held until close(): a second server on this directory is refused, --overwrite or not.
        self._run_lock = RunDirLock(self.run_dir)
        try:
            self._run_lock.acquire()
        except RunDirBusy as exc:
            raise RunDirError(str(exc)) from None
        except OSError as exc:
            raise RunDirError(f"cannot create {self.run_dir}: {exc.strerror}") from None
        try:
            self._prepare_run_dir(overwrite)
            try:
                self._writer = self._open_trajectory(system)
            except RecordingError as exc:  # a full disk before the first line
                (self.run_dir / TRAJECTORY_FILE).unlink(missing_ok=True)
                raise RunDirError(f"cannot record in {self.run_dir}: {exc.reason}") from None
        except BaseException:
            self._run_lock.release()
            raise
        self._handlers: dict[str, Callable[..., _Outcome]] = {
            "list_objects": self._list_objects,
            "get_object": self._get_object,
            "get_scene": self._get_scene,
            "get_state": self._get_state,
            "translate_objects": self._translate,
            "rotate_objects": self._rotate,
            "set_object_pose": self._set_pose,
            "group_objects": self._group,
            "ungroup_objects": self._ungroup,
            "capture_scene": self._capture,
            "move_camera": self._move_camera,
            "start_episode": self._start,
        }

    def _start_from(self, poses: Mapping[str, Sequence[float]]) -> None:
        """Put every part at its given pose (before anything is recorded)."""
        if set(poses) != set(self.part_ids):
            raise ValueError(f"initial poses must name exactly the task's parts {self.part_ids}, got {sorted(poses)}")
        for pid in self.part_ids:
            pose = list(poses[pid])
            if len(pose) != 7:
                raise ValueError(f"initial pose of {pid}: 7 numbers [x, y, z, qw, qx, qy, qz], got {len(pose)}")
            try:
                self.scene.set_pose(pid, pose[:3], pose[3:])
            except SceneError as exc:
                raise ValueError(f"initial pose of {pid}: {exc}") from None

    # ------------------------------------------------------------------ run dir
    def _open_trajectory(self, system: str) -> TrajectoryWriter:
        header = TrajectoryHeader(
            task_id=self.task.task_id,
            system=system,
            started_at=_utc_now(),
            part_ids=self.part_ids,
            initial_poses=self.scene.pose_dict(),
            initial_poses_from=self._initial_poses_from,
            camera=CameraState(**self.scene.camera.to_dict()),
        )
        return TrajectoryWriter(self.run_dir / TRAJECTORY_FILE, header)

    def _prepare_run_dir(self, overwrite: bool) -> None:
        existing = [n for n in (TRAJECTORY_FILE, FINAL_FILE, CAPTURE_DIR) if (self.run_dir / n).exists()]
        if existing and not overwrite:
            raise RunDirError(
                f"{self.run_dir} already holds a recording ({', '.join(existing)}); use a fresh run directory "
                "or pass overwrite=True (aw-serve --overwrite)"
            )
        for n in existing:
            p = self.run_dir / n
            shutil.rmtree(p) if p.is_dir() else p.unlink()
        try:
            (self.run_dir / CAPTURE_DIR).mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise RunDirError(f"cannot create {self.run_dir / CAPTURE_DIR}: {exc.strerror}") from None

    # ------------------------------------------------------------------ state
    @property
    def meshes(self) -> tuple:
        """The baked part meshes, in ``task.parts`` order (never shown to the agent)."""
        return tuple(self._meshes)

    @property
    def tools(self) -> list[str]:
        return list(self._handlers)

    @property
    def started(self) -> bool:
        return self._t0 is not None

    @property
    def closed(self) -> bool:
        return self._closed

    def _server_t(self) -> float:
        return round(self._clock() - self._server_t0, 6)

    def elapsed(self) -> float:
        """Seconds on the episode clock (0 before it starts)."""
        return 0.0 if self._t0 is None else self._clock() - self._t0

    @property
    def timed_out(self) -> bool:
        with self._lock:
            self._check_budget()
            return self._timed_out

    def _check_budget(self) -> None:
        if self._t0 is not None and not self._timed_out and not self._closed and self.elapsed() >= self.budget_s:
            self._expire()

    def _expire(self) -> None:
        with self._lock:
            if self._timed_out or self._closed:
                return
            self._timed_out = True
            # Keep the final state now, in case the process is killed before it can close.
            self._write_final("timeout")
            log.info("execution budget of %.4g min exhausted; edits are refused from now on", self.budget_s / 60)

    def _on_timer(self) -> None:
        with self._lock:
            self._check_budget()

    def poses_array(self) -> np.ndarray:
        """``(P, 7)`` current poses in ``task.parts`` order."""
        return np.array([self.scene.poses[pid] for pid in self.part_ids])

    def episode_info(self) -> dict:
        return {
            "started": self.started,
            "elapsed_s": round(self.elapsed(), 3),
            "budget_minutes": self.budget_s / 60.0,
            "remaining_s": round(max(0.0, self.budget_s - self.elapsed()), 3),
            "timed_out": self._timed_out,
        }

    # ------------------------------------------------------------------ dispatch
    def call(self, tool: str, args: Mapping[str, Any] | None = None) -> Any:
        """Execute one tool call and record it. ``args`` are the validated keyword arguments
        (optional ones may be ``None``, meaning "not given"). Raises :class:`EpisodeError`.

        A call takes effect only once its line is written: if the recording fails (a full
        disk), the call is undone, the reply says so, and the episode takes no further calls."""
        args = {k: v for k, v in dict(args or {}).items() if v is not None}
        with self._lock:
            if self._closed:
                raise EpisodeError("the episode has ended; no further calls are accepted")
            try:
                return self._call(tool, args)
            except _RecordingFailed:
                raise EpisodeError(self._recording_failed_message()) from None

    def _call(self, tool: str, args: dict[str, Any]) -> Any:
        if self.recording_failure is not None:
            raise _RecordingFailed(self.recording_failure)
        handler = self._handlers.get(tool)
        if handler is None:
            msg = f"unknown tool {tool!r}; the tools are: {', '.join(self._handlers)}"
            self._record(tool, args, ok=False, error=msg)
            raise EpisodeError(msg)
        try:
            inspect.signature(handler).bind(**args)
        except TypeError as exc:
            # Unknown or missing keyword: the adapter's closed schema normally catches this first.
            msg = f"invalid arguments for {tool}: {exc}"
            self._record(tool, args, ok=False, error=msg)
            raise EpisodeError(msg) from None
        before = self.scene.snapshot()
        clock_was = self._t0
        if tool in EDIT_TOOLS and self._t0 is None:
            self._begin()  # the first edit starts the clock if start_episode was skipped
        self._check_budget()
        out = None
        try:
            if tool in EDIT_TOOLS and self._timed_out:
                raise EpisodeError(
                    f"the execution budget of {self.budget_s / 60:.4g} minutes is exhausted: edits are refused "
                    "and the final state is kept; queries, camera moves and captures still work"
                )
            out = handler(**args)
        except (SceneError, EpisodeError) as exc:
            self._record(tool, args, ok=False, error=str(exc))
            raise EpisodeError(str(exc)) from None
        except _RecordingFailed:
            raise
        except Exception as exc:  # a bug or a renderer failure: keep serving, say nothing internal
            log.exception("internal error in %s", tool)
            self.scene.restore(before)
            self._record(tool, args, ok=False, error=f"internal error: {type(exc).__name__}: {exc}")
            raise EpisodeError(f"{tool} failed with an internal error; the scene is unchanged") from None
        try:
            self._record(tool, args, ok=True, changed=out.changed, image=out.image)
        except _RecordingFailed:
            # Not recorded, so not done: the scene, the clock and the capture file go back.
            self.scene.restore(before)
            if clock_was is None and self._t0 is not None:
                self._stop_clock()
            if out.image is not None:
                (self.run_dir / out.image).unlink(missing_ok=True)
            raise
        return out.result

    def _recording_failed_message(self) -> str:
        return (
            f"recording failed ({self.recording_failure}): this call was not carried out and the episode "
            "takes no further calls"
        )

    def reject(self, tool: str, raw_args: Mapping[str, Any] | Any, message: str) -> str:
        """Record a call that the adapter refused before it reached the scene (schema errors).
        Returns the reply for the agent: ``message``, or why the call could not be recorded."""
        args = raw_args if isinstance(raw_args, Mapping) else {"_raw": raw_args}
        with self._lock:
            if self._closed:
                return message
            try:
                if self.recording_failure is not None:
                    raise _RecordingFailed(self.recording_failure)
                self._record(tool, args, ok=False, error=message)
            except _RecordingFailed:
                return self._recording_failed_message()
        return message

    def _record(
        self,
        tool: str,
        args: Mapping[str, Any],
        *,
        ok: bool,
        error: str | None = None,
        changed: Sequence[str] = (),
        image: str | None = None,
    ) -> None:
        """Write one call line; raises ``_RecordingFailed`` (and latches it) if it cannot be written."""
        rec = TrajectoryCall(
            seq=self._seq + 1,
            t=round(self.elapsed(), 6) if self.started else None,
            server_t=self._server_t(),
            tool=_recordable_text(tool),
            args=_jsonable_args(args),
            ok=ok,
            error=None if error is None else _recordable_text(error),
            changed=list(changed),
            poses=self.scene.pose_dict() if changed else None,
            camera=CameraState(**self.scene.camera.to_dict()),
            image=image,
            episode_active=self.started,
        )
        try:
            self._writer.call(rec)
        except RecordingError as exc:
            self._fail_recording(exc.reason)
        self._seq += 1

    def _fail_recording(self, reason: str) -> None:
        """Latch a recording failure; logged once, as one line."""
        if self.recording_failure is None:
            self.recording_failure = reason
            log.error("recording in %s failed (%s): the episode takes no further calls", self.run_dir, reason)
        raise _RecordingFailed(reason)

    # ------------------------------------------------------------------ ending
    def close(self, reason: EndReason = "disconnect", message: str = "") -> EndReason:
        """Write the closing line and ``final.json``; idempotent. Returns the recorded reason
        (``timeout`` wins if the budget ran out)."""
        with self._lock:
            if self._closed:
                return self.end_reason or reason
            self._check_budget()
            final_reason: EndReason = "timeout" if self._timed_out else reason
            self._closed = True
            self.end_reason = final_reason
            if self._timer is not None:
                self._timer.cancel()
            if self.recording_failure is not None and not message:
                message = f"recording failed ({self.recording_failure})"
            try:
                self._writer.end(
                    TrajectoryEnd(
                        reason=final_reason,
                        t=round(self.elapsed(), 6) if self.started else None,
                        server_t=self._server_t(),
                        message=_recordable_text(message),
                        poses=self.scene.pose_dict(),
                    )
                )
            except RecordingError as exc:
                log.error("the closing line of %s could not be written (%s)", self.run_dir, exc.reason)
            self._write_final(final_reason)
            renderer, self._renderer = self._renderer, None
            self._run_lock.release()
        if renderer is not None:
            try:
                renderer.close()
            except Exception:
                log.exception("renderer close failed")
        return final_reason

    def _write_final(self, reason: EndReason) -> None:
        try:
            write_final(
                self.run_dir / FINAL_FILE,
                FinalState(task_id=self.task.task_id, reason=reason, poses=self.scene.pose_dict()),
            )
        except OSError as exc:  # write_final is atomic: an older final.json, if any, is left whole
            log.error("%s could not be written (%s)", self.run_dir / FINAL_FILE, exc.strerror or exc)

    # ------------------------------------------------------------------ queries
    def _object_or_group(self, id) -> dict:
        if not isinstance(id, str):
            raise SceneError("id must be a string")
        if id in self.scene.parts:
            return {"type": "object", **self.scene.object_record(id)}
        if id in self.scene.groups:
            return {"type": "group", **self.scene.group_record(id)}
        raise SceneError(f"unknown id {id!r}; use list_objects for the object and group ids")

    def _list_objects(self) -> _Outcome:
        return _Outcome(
            {
                "objects": [{"id": pid, "name": self.scene.parts[pid].name} for pid in self.part_ids],
                "groups": self.scene.groups_list(),
            }
        )

    def _get_object(self, id) -> _Outcome:
        return _Outcome(self._object_or_group(id))

    def settings(self) -> dict:
        return {
            "image_size": [IMAGE_WIDTH, IMAGE_HEIGHT],
            "vertical_fov_deg": VERTICAL_FOV_DEG,
            "max_coordinate": MAX_COORDINATE,
            "max_angle_deg": MAX_ANGLE_DEG,
            "max_group_name_chars": MAX_GROUP_NAME,
            "move_camera_ranges": {"yaw": list(YAW_RANGE), "pitch": list(PITCH_RANGE), "zoom": list(ZOOM_RANGE)},
            "default_rotation_pivot": "mean of the selected objects' body origins",
            "rotation": "angles in degrees applied about the X, then Y, then Z axes of the chosen space "
            "(world X/Y/Z, or camera right/up/forward), right-hand rule",
            "camera_space_axes": "right, up, forward (forward points from the camera into the scene)",
            "initial_poses": "identity: initial placements are baked into the part meshes, so body origins "
            "need not coincide with visual part centers",
        }

    def _get_scene(self) -> _Outcome:
        return _Outcome(
            {
                "units": self.task.conventions.get("units", "normalized scene units"),
                "conventions": dict(self.task.conventions),
                "settings": self.settings(),
                "reference": {"condition": self.task.condition, "images": len(self.task.references)},
                "objects": [self.scene.object_record(pid) for pid in self.part_ids],
                "groups": self.scene.groups_list(),
                "camera": self.scene.camera.describe(),
                "episode": self.episode_info(),
            }
        )

    def _get_state(self) -> _Outcome:
        poses = {
            pid: {"position": [float(v) for v in p[:3]], "quaternion": [float(v) for v in p[3:]]}
            for pid, p in self.scene.poses.items()
        }
        return _Outcome(
            {
                "poses": poses,
                "groups": self.scene.groups_list(),
                "camera": self.scene.camera.describe(),
                "episode": self.episode_info(),
            }
        )

    # ------------------------------------------------------------------ edits
    @staticmethod
    def _status(changed: list[str]) -> dict:
        return {"status": "ok", "changed": changed}

    def _translate(self, ids, delta, space="world") -> _Outcome:
        changed = self.scene.translate(ids, delta, space)
        return _Outcome(self._status(changed), changed)

    def _rotate(self, ids, angles, space="world", pivot=None) -> _Outcome:
        changed = self.scene.rotate(ids, angles, space, pivot)
        return _Outcome(self._status(changed), changed)

    def _set_pose(self, id, position=None, quaternion=None) -> _Outcome:
        changed = self.scene.set_pose(id, position, quaternion)
        return _Outcome(self._status(changed), changed)

    def _group(self, ids, name=None, exclusive=False) -> _Outcome:
        g = self.scene.group(ids, name, exclusive)
        return _Outcome({"status": "ok", "group": self.scene.group_record(g.id), "changed": []})

    def _ungroup(self, ids) -> _Outcome:
        removed = self.scene.ungroup(ids)
        return _Outcome({"status": "ok", "removed": removed, "changed": []})

    def _move_camera(self, yaw=0.0, pitch=0.0, zoom=1.0, right=0.0, up=0.0) -> _Outcome:
        cam = self.scene.move_camera(yaw, pitch, zoom, right, up)
        return _Outcome({"status": "ok", "camera": cam.describe()})

    def ensure_started(self) -> None:
        """Start the episode clock and budget if they are not running, without recording a call:
        the official surface starts the episode with the agent's first page-tool call."""
        with self._lock:
            if self._t0 is None and not self._closed:
                self._begin()

    def _begin(self) -> None:
        self._t0 = self._clock()
        self._timer = threading.Timer(self.budget_s + 0.05, self._on_timer)
        self._timer.daemon = True
        self._timer.start()

    def _stop_clock(self) -> None:
        """Undo :meth:`_begin` (the call that started the clock was not recorded)."""
        self._t0 = None
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _start(self, task=None) -> _Outcome:
        if task is not None and (not isinstance(task, str) or len(task) > MAX_GROUP_NAME):
            raise SceneError(f"task must be a string of at most {MAX_GROUP_NAME} characters")
        if self._t0 is not None:
            return _Outcome(
                {
                    "status": "ok",
                    "message": f"the episode was already started {self.elapsed():.1f} s ago; nothing changed",
                    "episode": self.episode_info(),
                }
            )
        self._begin()
        return _Outcome(
            {
                "status": "ok",
                "message": f"episode started; the execution budget is {self.budget_s / 60:.4g} minutes",
                "episode": self.episode_info(),
            }
        )

    # ------------------------------------------------------------------ capture
    def _render_png(self) -> tuple[bytes, int, int]:
        if self._renderer is None:
            factory = self._renderer_factory
            if factory is None:
                from aw.render import OffscreenRenderer  # lazy: GL set-up only when a capture is asked for

                factory = OffscreenRenderer
            self._renderer = factory(self._meshes)
        image = self._renderer.render(self.poses_array(), self.scene.camera)
        buf = io.BytesIO()
        image.save(buf, format="PNG", compress_level=PNG_COMPRESS_LEVEL)
        return buf.getvalue(), image.width, image.height

    def _capture(self) -> _Outcome:
        png, w, h = self._render_png()
        rel = f"{CAPTURE_DIR}/{self._seq + 1:06d}.png"
        try:
            (self.run_dir / rel).write_bytes(png)
        except OSError as exc:
            (self.run_dir / rel).unlink(missing_ok=True)
            self._fail_recording(exc.strerror or type(exc).__name__)
        cap = Capture(png=png, path=rel, width=w, height=h, camera=self.scene.camera.describe())
        return _Outcome(cap, image=rel)
