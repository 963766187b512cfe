"""Initial-poses files: the state an episode or a refiner starts from instead of the task's layout.

An ``assemblyworld.poses`` file (``{"format": "assemblyworld.poses", "format_version": 1,
"task_id": ..., "poses": {part id: [x, y, z, qw, qx, qy, qz]}, "source": ...}``), or a run's
``final.json`` (``assemblyworld.final``), whose poses are used as they are. The poses must name
exactly the task's parts.
"""

from __future__ import annotations

from pathlib import Path
from typing import Final, Literal

from pydantic import BaseModel, ConfigDict, Field

from aw.formats.common import PoseList
from aw.formats.errors import FormatError
from aw.formats.io import parse_model, write_json_atomic
from aw.formats.strict_json import read_json
from aw.formats.trajectory import FinalState

__all__ = ["POSES_FORMAT", "PosesFile", "initial_poses_file", "read_initial_poses", "write_poses"]

POSES_FORMAT: Final = "assemblyworld.poses"


class PosesFile(BaseModel):
    model_config = ConfigDict(extra="forbid")
    format: Literal["assemblyworld.poses"] = POSES_FORMAT
    format_version: Literal[1] = 1
    task_id: str
    poses: dict[str, PoseList] = Field(min_length=1)
    source: str = Field(default="", description="what produced these poses (a refiner, a run), informational")


def write_poses(path: str | Path, poses: PosesFile) -> None:
    write_json_atomic(path, poses)


def read_initial_poses(path: str | Path, task_id: str, part_ids: list[str]) -> dict[str, list[float]]:
    """The poses of an ``assemblyworld.poses`` file or a ``final.json`` for task ``task_id``;
    :class:`FormatError` naming the file when it is unreadable, for another task, or does not
    name exactly ``part_ids``."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(path, "initial-poses file not found")
    data = read_json(path)
    kind = data.get("format") if isinstance(data, dict) else None
    if kind == "assemblyworld.final":
        doc: PosesFile | FinalState = parse_model(FinalState, data, path)
    elif kind == POSES_FORMAT:
        doc = parse_model(PosesFile, data, path)
    else:
        raise FormatError(path, f"expected an {POSES_FORMAT} file or a final.json, got format {kind!r}")
    if doc.task_id != task_id:
        raise FormatError(path, f"poses are for task {doc.task_id!r}, not {task_id!r}")
    missing = [p for p in part_ids if p not in doc.poses]
    unknown = [p for p in doc.poses if p not in part_ids]
    if missing or unknown:
        raise FormatError(
            path,
            "poses must name exactly the task's parts"
            + (f"; missing {missing}" if missing else "")
            + (f"; unknown {unknown}" if unknown else ""),
        )
    return {p: list(doc.poses[p]) for p in part_ids}


def initial_poses_file(source: str | Path, task_id: str) -> Path | None:
    """A task's start-state file under the directory ``source``: ``source/<task_id>/final.json``
    (a system's runs) or ``source/<task_id>.json`` (poses files); None when neither exists."""
    source = Path(source)
    for path in (source / task_id / "final.json", source / f"{task_id}.json"):
        if path.is_file():
            return path
    return None
