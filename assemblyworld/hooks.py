"""Inspect hooks of the AssemblyWorld task.

- **Epochs.** A solver sees its own epoch, not how many there are; the recording layout depends
  on it (one folder per epoch only when there are several). The task-start hook reads the
  eval's epochs and the sample-start hook hands them to each sample (:func:`epochs_of`).
- **Exit status.** ``inspect eval`` exits 0 even when samples failed; ``aw-run`` exits 1 when
  episodes failed. When the ``inspect eval`` (or ``inspect eval-retry``) command ran this task
  and any of its samples failed, or the eval ended in error or was cancelled, the run-end hook
  makes the command exit with status 1 (the logs are written by then). From Python
  (``inspect_ai.eval``) nothing is raised: the logs' ``status`` says the same.
"""

from __future__ import annotations

import sys
from typing import Any

from inspect_ai.hooks import Hooks, RunEnd, SampleEnd, SampleStart, TaskStart, hooks
from inspect_ai.log import EvalLog

__all__ = ["TASK_NAME", "AssemblyWorldHooks", "epochs_of", "failed_samples", "is_assemblyworld_log"]

TASK_NAME = "assemblyworld"
EXIT_FAILED = 1
_CLI_COMMANDS = ("eval", "eval-retry")

_epochs_by_eval: dict[str, int] = {}
_epochs_by_sample: dict[str, int] = {}
_failed_by_eval: dict[str, int] = {}


def epochs_of(sample_uuid: str) -> int | None:
    """How many epochs the running sample's eval has (None when no hook saw it start)."""
    return _epochs_by_sample.get(sample_uuid)


def is_assemblyworld_log(log: EvalLog) -> bool:
    return log.eval.task.split("/")[-1] == TASK_NAME


def failed_samples(log: EvalLog) -> str | None:
    """Why ``log`` counts as failed (an error, a cancel, samples that failed), or None. The
    sample-end hook counts failed samples: a header-only log (the CLI's) does not list them."""
    if log.status != "success":
        return f"the eval ended with status {log.status}" + (f": {log.error.message}" if log.error else "")
    failed = _failed_by_eval.get(log.eval.eval_id, 0)
    if log.samples is not None:
        failed = sum(1 for s in log.samples if s.error is not None)
    return f"{failed} sample{'s' if failed != 1 else ''} failed" if failed else None


def _inspect_cli_context() -> Any:
    """The click context of the ``inspect eval`` / ``inspect eval-retry`` command running this
    process, or None (Python API, other commands)."""
    import click

    ctx = click.get_current_context(silent=True)
    if ctx is None or ctx.find_root().info_name != "inspect" or ctx.info_name not in _CLI_COMMANDS:
        return None
    return ctx


def _exit_failed() -> None:
    import click

    raise click.exceptions.Exit(EXIT_FAILED)


@hooks(
    name="assemblyworld", description="AssemblyWorld: epochs for the recording layout; exit status 1 on failed samples"
)
class AssemblyWorldHooks(Hooks):
    async def on_task_start(self, data: TaskStart) -> None:
        _epochs_by_eval[data.eval_id] = int(data.spec.config.epochs or 1)

    async def on_sample_start(self, data: SampleStart) -> None:
        if data.eval_id in _epochs_by_eval:
            _epochs_by_sample[data.sample_id] = _epochs_by_eval[data.eval_id]

    async def on_sample_end(self, data: SampleEnd) -> None:
        _epochs_by_sample.pop(data.sample_id, None)
        if data.sample.error is not None:
            _failed_by_eval[data.eval_id] = _failed_by_eval.get(data.eval_id, 0) + 1

    async def on_run_end(self, data: RunEnd) -> None:
        ctx = _inspect_cli_context()
        if data.exception is not None or ctx is None:
            return
        why = [f"{log.location}: {w}" for log in data.logs if is_assemblyworld_log(log) and (w := failed_samples(log))]
        if why:
            print(f"assemblyworld: error: {'; '.join(why)}", file=sys.stderr, flush=True)
            # the command's exit status, set when click closes its context after the command returns
            ctx.call_on_close(_exit_failed)
