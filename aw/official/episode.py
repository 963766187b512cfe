"""3DWebAgent episode archives: recorded states restored to part poses with MuJoCo.

An archive (checked by :func:`aw.official.archive.read_archive` first) holds::

    manifest.json     files + sha256, and the episode record:
                        sample_id | task_id, system, started_at (optional),
                        state: {"layout": "qpos" (default) | "mjstate", "spec": <mjtState bits>,
                                "width": <floats per row>},
                        bodies: {part id: body name} (default: the body named like the part)
    frames.jsonl      one line per recorded state: {"frame": i, "t": seconds, "call": seq | null}
    frames.bin        the states: little-endian float64 rows, one per line of frames.jsonl
    calls.jsonl       tool calls: {"seq", "t", "tool" | "name", "args" | "arguments", "ok", "error"}
    events.jsonl      episode events: {"t", "type" | "event": "start" | "end" | ..., "reason"}
    world/model.xml   the MJCF scene (one body with a free joint per part); other world/ files
                      are its assets

A part's pose in a frame is its body's world pose after forward kinematics
(``xpos``, ``xquat`` (w, x, y, z)): the same ``[x, y, z, qw, qx, qy, qz]`` that maps the baked
initial geometry into the scene, as in this project's trajectories.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aw.formats import FormatError
from aw.official.archive import ArchiveContents, read_archive

__all__ = ["Frame", "Call", "Episode", "read_episode", "restore_poses"]


@dataclass
class Frame:
    index: int
    t: float
    call: int | None


@dataclass
class Call:
    seq: int
    t: float
    tool: str
    args: dict[str, Any]
    ok: bool
    error: str | None = None


@dataclass
class Episode:
    """A read episode: ``poses (F, P, 7)`` per frame for ``part_ids``, plus calls and events."""

    path: Path
    sample_id: str
    system: str
    started_at: str
    part_ids: list[str]
    frames: list[Frame]
    poses: np.ndarray
    calls: list[Call] = field(default_factory=list)
    events: list[dict[str, Any]] = field(default_factory=list)
    manifest: dict[str, Any] = field(default_factory=dict)

    def end_event(self) -> dict[str, Any] | None:
        ends = [e for e in self.events if (e.get("type") or e.get("event")) == "end"]
        return ends[-1] if ends else None

    def final_poses(self) -> np.ndarray:
        """``(P, 7)``: the last recorded state."""
        return self.poses[-1]


def _jsonl(contents: ArchiveContents, name: str) -> list[dict[str, Any]]:
    out = []
    for i, line in enumerate(contents.text(name).splitlines(), start=1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except ValueError as exc:
            raise FormatError(contents.path, f"{name}: line {i}: not valid JSON ({exc})") from None
        if not isinstance(rec, dict):
            raise FormatError(contents.path, f"{name}: line {i}: expected a JSON object")
        out.append(rec)
    return out


def _number(value: Any, where: Path, field_name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise FormatError(where, f"{field_name}: expected a finite number, got {value!r}")
    return float(value)


def _model(contents: ArchiveContents):
    import mujoco

    xml = contents.text("world/model.xml")
    assets = {name[len("world/"):]: data for name, data in contents.files.items() if name.startswith("world/") and name != "world/model.xml"}
    try:
        return mujoco.MjModel.from_xml_string(xml, assets)
    except ValueError as exc:
        raise FormatError(contents.path, f"world/model.xml: MuJoCo cannot load it ({exc})") from None


def restore_poses(model, rows: np.ndarray, bodies: list[str], layout: str = "qpos", spec: int | None = None,
                  where: str | Path = "<model>") -> np.ndarray:
    """World poses ``(F, len(bodies), 7)`` of the named bodies for each state row ``(F, W)``."""
    import mujoco

    ids = []
    for name in bodies:
        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        if bid < 0:
            raise FormatError(where, f"world/model.xml: no body named {name!r}")
        ids.append(bid)
    data = mujoco.MjData(model)
    out = np.empty((len(rows), len(ids), 7))
    for f, row in enumerate(rows):
        if layout == "qpos":
            data.qpos[:] = row
        else:
            mujoco.mj_setState(model, data, row, spec)
        mujoco.mj_kinematics(model, data)
        out[f, :, :3] = data.xpos[ids]
        out[f, :, 3:] = data.xquat[ids]
    return out


def read_episode(path: str | Path, part_ids: list[str] | None = None) -> Episode:
    """Verify and read an episode archive, restoring the poses of ``part_ids`` (default: the
    manifest's ``bodies`` keys, else every body with a free joint, in name order)."""
    import mujoco

    contents = read_archive(path)
    path = contents.path
    man = contents.manifest
    sample_id = man.get("sample_id", man.get("task_id"))
    if not isinstance(sample_id, str) or not sample_id:
        raise FormatError(path, "manifest.json: sample_id (or task_id): missing")
    model = _model(contents)

    state = man.get("state") or {}
    if not isinstance(state, dict):
        raise FormatError(path, "manifest.json: state: expected an object")
    layout = state.get("layout", "qpos")
    spec = None
    if layout == "qpos":
        width = model.nq
    elif layout == "mjstate":
        spec = state.get("spec")
        if isinstance(spec, bool) or not isinstance(spec, int) or spec <= 0:
            raise FormatError(path, "manifest.json: state.spec: an mjtState bit mask is needed for layout 'mjstate'")
        width = mujoco.mj_stateSize(model, spec)
    else:
        raise FormatError(path, f"manifest.json: state.layout: expected 'qpos' or 'mjstate', got {layout!r}")
    if "width" in state and state["width"] != width:
        raise FormatError(path, f"manifest.json: state.width is {state['width']} but the model's {layout} has {width} values")

    raw = contents.files["frames.bin"]
    if len(raw) % (8 * width):
        raise FormatError(path, f"frames.bin: {len(raw)} bytes is not a whole number of {width}-float64 rows")
    rows = np.frombuffer(raw, dtype="<f8").reshape(-1, width)
    if not np.isfinite(rows).all():
        bad = int(np.argmax(~np.isfinite(rows).all(axis=1)))
        raise FormatError(path, f"frames.bin: non-finite values in row {bad}")
    frame_recs = _jsonl(contents, "frames.jsonl")
    if len(frame_recs) != len(rows):
        raise FormatError(path, f"frames.jsonl has {len(frame_recs)} lines but frames.bin has {len(rows)} rows")
    if not frame_recs:
        raise FormatError(path, "frames.jsonl: no frames (the initial state is needed)")
    frames = []
    for k, rec in enumerate(frame_recs):
        idx = rec.get("frame", rec.get("index", k))
        if idx != k:
            raise FormatError(path, f"frames.jsonl: line {k + 1}: frame index {idx!r}, expected {k}")
        call = rec.get("call", rec.get("call_seq"))
        if call is not None and (isinstance(call, bool) or not isinstance(call, int)):
            raise FormatError(path, f"frames.jsonl: line {k + 1}: call: expected an integer or null")
        frames.append(Frame(k, _number(rec.get("t", 0.0), path, f"frames.jsonl: line {k + 1}: t"), call))

    bodies_map = man.get("bodies")
    if part_ids is None:
        if isinstance(bodies_map, dict) and bodies_map:
            part_ids = sorted(bodies_map)
        else:
            free = sorted(
                mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, int(model.jnt_bodyid[j]))
                for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE
            )
            part_ids = [b for b in free if b]
    if not part_ids:
        raise FormatError(path, "world/model.xml: no part bodies (no free joints and no manifest bodies)")
    bodies = [bodies_map.get(p, p) if isinstance(bodies_map, dict) else p for p in part_ids]
    poses = restore_poses(model, rows, bodies, layout, spec, path)

    calls = []
    for k, rec in enumerate(_jsonl(contents, "calls.jsonl")):
        seq = rec.get("seq", rec.get("index", k + 1))
        if isinstance(seq, bool) or not isinstance(seq, int):
            raise FormatError(path, f"calls.jsonl: line {k + 1}: seq: expected an integer")
        tool = rec.get("tool", rec.get("name"))
        if not isinstance(tool, str) or not tool:
            raise FormatError(path, f"calls.jsonl: line {k + 1}: tool: missing")
        args = rec.get("args", rec.get("arguments")) or {}
        if not isinstance(args, dict):
            raise FormatError(path, f"calls.jsonl: line {k + 1}: args: expected an object")
        err = rec.get("error")
        calls.append(Call(seq, _number(rec.get("t", 0.0), path, f"calls.jsonl: line {k + 1}: t"), tool, args,
                          bool(rec.get("ok", err is None)), None if err is None else str(err)))
    seqs = [c.seq for c in calls]
    if seqs != sorted(set(seqs)):
        raise FormatError(path, "calls.jsonl: seq values must be unique and increasing")
    known = set(seqs)
    for fr in frames:
        if fr.call is not None and calls and fr.call not in known:
            raise FormatError(path, f"frames.jsonl: frame {fr.index} names call {fr.call}, which calls.jsonl lacks")
    events = _jsonl(contents, "events.jsonl")
    return Episode(
        path=path,
        sample_id=sample_id,
        system=str(man.get("system", "")),
        started_at=str(man.get("started_at", "")),
        part_ids=list(part_ids),
        frames=frames,
        poses=poses,
        calls=calls,
        events=events,
        manifest=man,
    )
