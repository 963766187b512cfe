"""``assemblyworld/assemblyworld``: the benchmark as one Inspect task.

    inspect eval assemblyworld/assemblyworld --model PROVIDER/MODEL [-T ARG=VALUE ...]

Each sample is one suite task (:mod:`assemblyworld.samples`); its solver runs Inspect's ReAct
agent on that task's ``aw-serve`` and records into ``RUNS/<system>/<task_id>/``
(:mod:`assemblyworld.episode`); its scorer scores the recorded final state by the protocol, and
the metrics are the paper's Overall (:mod:`assemblyworld.scorer`). ``aw-score SUITE RUNS`` reads
the same recordings beside any other system's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from inspect_ai import Task, task

from assemblyworld.episode import EpisodeSettings, assembly_episode
from assemblyworld.samples import suite_samples
from assemblyworld.scorer import assembly_score
from assemblyworld.suite import resolve_suite
from aw.formats.task import MAX_BUDGET_MINUTES

__all__ = ["assemblyworld", "SURFACES", "DEFAULT_BUDGET_MINUTES", "LIMIT_MARGIN_MINUTES"]

SURFACES = ("default", "official")
DEFAULT_BUDGET_MINUTES = 60.0  # the paper's execution limit
# The sample's Inspect time limit: the budget plus this margin (aw-run gives a harness 65 minutes).
LIMIT_MARGIN_MINUTES = 5.0


def _budget(value: float | str) -> float:
    try:
        minutes = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"budget_minutes={value!r}: not a number") from None
    if not (math.isfinite(minutes) and 0 < minutes <= MAX_BUDGET_MINUTES):
        raise ValueError(
            f"budget_minutes={value!r}: must be a positive number of minutes, at most {MAX_BUDGET_MINUTES:g}"
        )
    return minutes


def _system(value: str | None) -> str | None:
    if value is None:
        return None
    label = str(value)
    if not label or "/" in label or label in (".", "..") or label.startswith("."):
        raise ValueError(f"system={value!r}: must be a plain folder name (it becomes RUNS/<system>/)")
    return label


@task
def assemblyworld(
    suite: str | None = None,
    tasks: str | Sequence[str] | None = None,
    surface: str = "default",
    budget_minutes: float = DEFAULT_BUDGET_MINUTES,
    runs: str = "runs",
    system: str | None = None,
    overwrite: bool = False,
) -> Task:
    """AssemblyWorld: assemble 3D objects from their parts through ``aw-serve``'s MCP tools.

    Args:
        suite: suite directory (``aw-prepare`` output); default: the embedded synthetic suite,
            built on first use into ``~/.cache/assemblyworld/suites/``.
        tasks: task ids to run (comma-separated or a list); default: every task of the suite.
        surface: ``default`` (the project's scene tools) or ``official`` (the official
            benchmark's four page tools).
        budget_minutes: the episode's execution budget (default 60, the paper's); the sample's
            Inspect time limit is this plus 5 minutes unless ``--time-limit`` says otherwise.
        runs: the runs folder; episodes record into ``RUNS/<system>/<task_id>/``
            (``RUNS/<system>/attempt-<epoch>/<task_id>/`` with several epochs).
        system: the system label (a folder name); default: the model's name.
        overwrite: replace earlier recordings in those folders (default: refuse them).
    """
    if surface not in SURFACES:
        raise ValueError(f"surface={surface!r}: expected one of {', '.join(SURFACES)}")
    minutes = _budget(budget_minutes)
    suite_dir = resolve_suite(suite)
    settings = EpisodeSettings(
        suite_dir=suite_dir,
        runs_dir=Path(runs).expanduser().resolve(),
        system=_system(system),
        surface=surface,
        budget_minutes=minutes,
        overwrite=bool(overwrite),
    )
    return Task(
        dataset=suite_samples(suite_dir, tasks),
        solver=assembly_episode(settings),
        scorer=assembly_score(suite_dir),
        time_limit=int(math.ceil(60 * (minutes + LIMIT_MARGIN_MINUTES))),
        metadata={
            "suite": str(suite_dir),
            "runs": str(settings.runs_dir),
            "surface": surface,
            "budget_minutes": minutes,
        },
    )
