"""What a harness adapter does: prepare one task's command line and parse its transcript."""

from __future__ import annotations

import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from aw.formats import TokenUsage, read_task

SERVER_NAME = "assemblyworld"


class HarnessError(RuntimeError):
    """The harness cannot be prepared (missing binary, unreadable task, prompt failure)."""


@dataclass
class HarnessOptions:
    binary: str | None = None  # default: the harness's usual executable on PATH
    model: str | None = None
    extra_args: list[str] = field(default_factory=list)
    price_table: Path | None = None  # Codex only: overrides the built-in price schedule


@dataclass
class PreparedRun:
    """The command to run, in a fresh empty working directory ``cwd`` (no project instructions)."""

    command: list[str]
    env: dict[str, str]
    cwd: Path
    stdin: bytes | None = None
    display_command: str = ""


@dataclass
class HarnessUsage:
    """What a transcript says: tokens (input including cache reads and creation), cost, report."""

    tokens: TokenUsage | None = None
    cost_usd: float | None = None
    model: str | None = None
    version: str | None = None
    report: str | None = None
    is_error: bool = False
    error: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)


class HarnessAdapter(Protocol):
    name: str
    transcript_name: str

    def prepare(
        self,
        task_dir: Path,
        serve_base: list[str],
        serve_args: list[str],
        env: dict[str, str],
        marker: str,
        opts: HarnessOptions,
    ) -> PreparedRun:
        """``serve_base + serve_args`` starts aw-serve for this task (stdio)."""
        ...

    def parse(self, transcript: Path, opts: HarnessOptions) -> HarnessUsage: ...

    def label(self, usage: HarnessUsage) -> str: ...


def task_prompt_from_server(serve_base: list[str], task_dir: Path, env: dict[str, str]) -> str:
    """The task text exactly as ``aw-serve TASK_DIR --print-prompt`` prints it."""
    try:
        proc = subprocess.run(
            [*serve_base, str(task_dir), "--print-prompt"],
            capture_output=True,
            text=True,
            env=env,
            timeout=120,
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise HarnessError(f"could not get the task prompt from aw-serve: {exc}") from None
    if proc.returncode != 0 or not proc.stdout.strip():
        raise HarnessError(f"aw-serve --print-prompt failed (code {proc.returncode}): {proc.stderr.strip()[-500:]}")
    return proc.stdout.strip()


def reference_images(task_dir: Path) -> list[Path]:
    """The task's reference images, in order, as absolute paths."""
    task = read_task(task_dir)
    return [p.resolve() for p in task.reference_paths()]


def server_env(env: dict[str, str], marker: str) -> dict[str, str]:
    """Variables the server needs that an MCP client might not pass on: harnesses start servers
    with a reduced environment."""
    from aw.runner.supervise import MARKER_VAR

    keep = (
        "PYOPENGL_PLATFORM",
        "JAX_PLATFORMS",
        "JAX_COMPILATION_CACHE_DIR",
        "LP_NUM_THREADS",
        "MESA_GL_VERSION_OVERRIDE",
    )
    out = {k: env[k] for k in keep if env.get(k)}
    out[MARKER_VAR] = marker
    return out


def read_json_events(transcript: Path) -> tuple[list[dict], int]:
    """The JSON-object lines of a harness transcript (JSONL) and the count of unparsable lines.

    A missing, unreadable or oversized transcript gives no events; blank lines and non-object
    values are skipped. Lines are read one at a time, each within the JSON reader's limits.
    """
    from aw.formats import FormatError
    from aw.formats.strict_json import LIMITS, JsonError, iter_lines, open_bounded, parse_json

    try:
        fh = open_bounded(transcript, LIMITS.max_file_bytes)
    except FormatError:
        return [], 0
    events, n_bad = [], 0
    with fh:
        for _, line in iter_lines(fh, LIMITS.max_document_bytes):
            if line is None:
                n_bad += 1
                continue
            line = line.strip()
            if not line:
                continue
            try:
                ev = parse_json(line)
            except JsonError:
                n_bad += 1
                continue
            if isinstance(ev, dict):
                events.append(ev)
    return events, n_bad
