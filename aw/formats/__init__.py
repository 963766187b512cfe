"""On-disk formats: task directory, hidden targets, suite manifest, trajectory JSONL, final.json.

Every reader validates and raises :class:`FormatError` naming the file and the problem.
The schemas are documented in ``docs/formats.md``.
"""

from aw.formats.errors import FormatError
from aw.formats.run import RunInfo, TokenUsage, read_run_info, write_run_info
from aw.formats.suite import SuiteEntry, SuiteManifest, read_manifest, suite_paths, write_manifest
from aw.formats.targets import PartTarget, Targets, read_targets, write_targets
from aw.formats.task import CONVENTIONS, Task, TaskPart, read_task, write_task
from aw.formats.trajectory import (
    FinalState,
    RecordingError,
    Trajectory,
    TrajectoryCall,
    TrajectoryEnd,
    TrajectoryFollower,
    TrajectoryHeader,
    TrajectoryWriter,
    read_final,
    read_trajectory,
    write_final,
)

__all__ = [
    "RunInfo",
    "TokenUsage",
    "read_run_info",
    "write_run_info",
    "FormatError",
    "CONVENTIONS",
    "Task",
    "TaskPart",
    "read_task",
    "write_task",
    "PartTarget",
    "Targets",
    "read_targets",
    "write_targets",
    "SuiteEntry",
    "SuiteManifest",
    "suite_paths",
    "read_manifest",
    "write_manifest",
    "Trajectory",
    "TrajectoryHeader",
    "TrajectoryCall",
    "TrajectoryEnd",
    "TrajectoryFollower",
    "TrajectoryWriter",
    "RecordingError",
    "FinalState",
    "read_trajectory",
    "read_final",
    "write_final",
]
