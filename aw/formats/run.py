"""``run.json``: resource figures and outcome of one episode, written by the runner or a harness adapter."""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from aw.formats.common import RunEnded
from aw.formats.errors import FormatError
from aw.formats.io import read_model, write_json_atomic

RUN_ENDINGS = ("finished", "timeout", "error", "crashed", "hung")
# A system label names a folder under RUNS and a row of every report (Markdown, HTML, CSV): so
# letters, digits and a few marks, nothing that Markdown or HTML reads as markup.
SYSTEM_LABEL_RULE = "letters, digits and . _ + = @ - (starting with a letter or digit, at most 100 characters)"
_SYSTEM_LABEL = re.compile(r"[^\W_][\w.+=@-]{0,99}")


def system_label_problem(name: str) -> str | None:
    """Why ``name`` cannot be a system label (``aw-run --system``, a system folder under RUNS),
    or None when it can. The name is quoted with its escapes, so the message is one safe line."""
    if _SYSTEM_LABEL.fullmatch(name):
        return None
    return f"{ascii(name)} is not a system label: use {SYSTEM_LABEL_RULE}"


# Endings of a run that failed (the runner, the harness or the refiner erred, crashed, hung or
# was killed at its time limit): ``aw-run`` retries them unless told to keep them.
FAILED_ENDINGS = ("timeout", "error", "crashed", "hung")


class TokenUsage(BaseModel):
    model_config = ConfigDict(extra="forbid")
    input: int | None = Field(default=None, ge=0, description="including cache reads (and cache creation)")
    output: int | None = Field(default=None, ge=0)
    total: int | None = Field(default=None, ge=0)


class RunInfo(BaseModel):
    model_config = ConfigDict(extra="allow")
    format: Literal["assemblyworld.run"] = "assemblyworld.run"
    format_version: Literal[1] = 1
    system: str
    task_id: str
    agent: str = ""
    harness: str | None = None
    started_at: str = ""
    wall_seconds: float | None = Field(default=None, ge=0)
    mcp_calls: int | None = Field(default=None, ge=0)
    ended: RunEnded = "finished"
    error: str | None = None
    tokens: TokenUsage | None = None
    cost_usd: float | None = Field(default=None, ge=0)
    declared_complete: bool | None = None
    report: str | None = None
    extra: dict[str, Any] = Field(default_factory=dict)

    @property
    def failure(self) -> str | None:
        """Why the run failed, in one line (``"error: <first line>"``), or None when it did not."""
        if self.ended not in FAILED_ENDINGS:
            return None
        first = (self.error or "").strip().splitlines()
        return f"{self.ended}: {first[0]}" if first else self.ended


def read_run_info(path: str | Path) -> RunInfo:
    return read_model(RunInfo, path)


def write_run_info(path: str | Path, info: RunInfo) -> None:
    write_json_atomic(path, info)


BATCH_FILE = ".aw-batch.json"


class BatchPlan(BaseModel):
    """``RUNS/<system>/.aw-batch.json``: what an ``aw-run`` batch is running, for watchers
    (``aw-view`` shows the tasks not yet started as queued, and finds their public task files)."""

    model_config = ConfigDict(extra="forbid")
    format: Literal["assemblyworld.batch"] = "assemblyworld.batch"
    format_version: Literal[1] = 1
    system: str
    suite_dir: str = Field(description="absolute path of the suite")
    tasks: list[str] = Field(description="the episodes this batch runs, in order")
    pid: int = Field(description="the aw-run process")
    host: str
    started_unix: float = Field(description="seconds since the epoch when the batch started")
    finished_unix: float | None = Field(default=None, description="when the batch ended (None while it runs)")
    budget_minutes: float | None = Field(default=None, description="--budget-minutes (None: each task's own)")


def read_batch_plan(path: str | Path) -> BatchPlan:
    return read_model(BatchPlan, path)


def write_batch_plan(path: str | Path, plan: BatchPlan) -> None:
    write_json_atomic(path, plan)


@dataclass
class ExistingRuns:
    """What a rerun does with the runs already recorded: ``kept`` (task ids; finished runs, and
    failed ones under ``--keep-failed``, whose reasons ``kept_failed`` gives), ``retry`` (task id ->
    why it failed: run again), and the tasks without a run.json (``todo``, run as new)."""

    kept: list[str] = field(default_factory=list)
    kept_failed: dict[str, str] = field(default_factory=dict)
    retry: dict[str, str] = field(default_factory=dict)
    todo: list[str] = field(default_factory=list)

    def kept_line(self) -> str:
        """``"skipped 3 with an existing run.json (same options), 1 of them failed (kept: --keep-failed)"``."""
        out = f"skipped {len(self.kept)} with an existing run.json (same options)"
        if self.kept_failed:
            out += f", {len(self.kept_failed)} of them failed (kept: --keep-failed)"
        return out

    def retry_line(self) -> str:
        """``"retrying 1 run that failed: t1 (error: ...)"``; "" when none is retried."""
        if not self.retry:
            return ""
        n = len(self.retry)
        shown = "; ".join(f"{t} ({why})" for t, why in list(self.retry.items())[:3]) + ("; ..." if n > 3 else "")
        return f"retrying {n} run{'s' if n != 1 else ''} that failed: {shown} (--keep-failed keeps failed runs)"


def existing_runs(run_dirs: Mapping[str, Path], keep_failed: bool = False) -> ExistingRuns:
    """Sort the tasks of a rerun (``task id -> run directory``) by what their run.json says. A
    run.json that cannot be read is kept as it is (aw-score reports it)."""
    out = ExistingRuns()
    for tid, run_dir in run_dirs.items():
        path = Path(run_dir) / "run.json"
        if not path.is_file():
            out.todo.append(tid)
            continue
        try:
            failure = read_run_info(path).failure
        except FormatError:
            failure = None
        if failure is None:
            out.kept.append(tid)
        elif keep_failed:
            out.kept.append(tid)
            out.kept_failed[tid] = failure
        else:
            out.retry[tid] = failure
    return out
