"""``run.json``: resource figures and outcome of one episode, written by the runner or a harness adapter."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from aw.formats.io import read_model, write_json_atomic

RUN_ENDINGS = ("finished", "timeout", "error", "crashed", "hung")


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
    ended: Literal["finished", "timeout", "error", "crashed", "hung"] = "finished"
    error: str | None = None
    tokens: TokenUsage | None = None
    cost_usd: float | None = Field(default=None, ge=0)
    declared_complete: bool | None = None
    report: str | None = None
    extra: dict[str, Any] = Field(default_factory=dict)


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
