"""The bidirectional refinement study: four arms over one suite, written as four systems.

1. ``agent``: the agent alone, from the task's layout;
2. ``refiner``: the refiner alone, from the layout;
3. ``agent_refiner``: the refiner started from the agent's final states (agent -> refiner);
4. ``refiner_agent``: the agent started from the refiner's poses (refiner -> agent), the same
   prompt, no history of the refiner's work.

``RUNS/refinement_study.json`` names the arms' systems and says how each went, so that
``aw-score`` writes the study's table. A failing arm is marked failed (with its first error)
and the others go on; an arm that depends on a failed one runs on the tasks that have its input.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aw.formats.io import write_json_atomic

if TYPE_CHECKING:  # the runner is imported when a study runs, not when aw-score reads one
    from aw.refine.runs import RefineConfig
    from aw.runner.batch import BatchConfig

__all__ = ["ARMS", "STUDY_FILE", "StudyArm", "arm_systems", "run_study"]

STUDY_FILE = "refinement_study.json"
STUDY_FORMAT = "assemblyworld.refinement-study"
ARMS = ("agent", "refiner", "agent_refiner", "refiner_agent")


def arm_systems(agent_label: str, refiner_label: str) -> dict[str, str]:
    """The system label of each arm (they become directories under RUNS)."""
    return {
        "agent": agent_label,
        "refiner": refiner_label,
        "agent_refiner": f"{agent_label}-then-{refiner_label}",
        "refiner_agent": f"{refiner_label}-then-{agent_label}",
    }


@dataclass
class StudyArm:
    arm: str
    system: str
    tasks: int = 0
    failed: dict[str, str] = field(default_factory=dict)  # task id -> one-line reason

    @property
    def status(self) -> str:
        if not self.failed:
            return "ok"
        return "failed" if len(self.failed) >= self.tasks else "partial"

    def doc(self) -> dict[str, Any]:
        return {
            "arm": self.arm,
            "system": self.system,
            "status": self.status,
            "tasks": self.tasks,
            "failed_tasks": dict(sorted(self.failed.items())),
        }


def _first_line(text: str | None) -> str:
    return (text or "").strip().splitlines()[0] if (text or "").strip() else "no reason recorded"


def run_study(
    agent_cfg: BatchConfig, refine_cfg: RefineConfig, task_ids: list[str], log: Callable[[str], None] = lambda _m: None
) -> list[StudyArm]:
    """Run the four arms (``agent_cfg.system`` / ``refine_cfg.system`` label the first two) and
    write ``RUNS/refinement_study.json``. ``task_ids``: the suite's tasks to run, in order."""
    from aw.refine.runs import refine_suite
    from aw.runner.batch import run_batch

    out = agent_cfg.out_dir
    systems = arm_systems(agent_cfg.system, refine_cfg.system)
    arms = {a: StudyArm(a, systems[a], len(task_ids)) for a in ARMS}

    def agent_arm(arm: StudyArm, tasks: list[str], start_from: Path | None) -> None:
        if not tasks:
            return
        cfg = dataclasses.replace(agent_cfg, system=arm.system, tasks=tasks, initial_poses=start_from)
        log(f"arm {arm.arm}: {cfg.agent or cfg.harness} on {len(tasks)} tasks -> {out / arm.system}")
        result = run_batch(cfg)
        for info in result.runs:
            if info.ended != "finished":
                arm.failed[info.task_id] = f"{info.ended}: {_first_line(info.error)}"
        _note_skipped(arm, out, result.skipped)

    def refiner_arm(arm: StudyArm, tasks: list[str], start_from: Path | None) -> None:
        if not tasks:
            return
        cfg = dataclasses.replace(refine_cfg, system=arm.system, tasks=tasks, start_from=start_from)
        log(f"arm {arm.arm}: refiner {cfg.spec.name} on {len(tasks)} tasks -> {out / arm.system}")
        infos, skipped = refine_suite(cfg)
        for info in infos:
            if info.ended != "finished":
                arm.failed[info.task_id] = _first_line(info.error)
        _note_skipped(arm, out, skipped)

    agent_arm(arms["agent"], task_ids, None)
    refiner_arm(arms["refiner"], task_ids, None)
    # a composed arm runs where its first stage produced a state; elsewhere it fails, by name
    for first, arm, run in (("agent", "agent_refiner", refiner_arm), ("refiner", "refiner_agent", agent_arm)):
        # an agent run that ended early still has a final state; a failed refiner run has none of its own
        def has_start(t: str) -> bool:
            if first == "refiner":
                return t not in arms[first].failed
            return (out / systems[first] / t / "final.json").is_file()

        ok = [t for t in task_ids if has_start(t)]
        for t in task_ids:
            if t not in ok:
                arms[arm].failed[t] = f"no start state: arm {first} failed on this task"
        run(arms[arm], ok, out / systems[first])
    write_study(out, agent_cfg, refine_cfg, list(arms.values()), task_ids)
    return list(arms.values())


def _note_skipped(arm: StudyArm, out: Path, skipped: list[str]) -> None:
    """Runs kept from an earlier call count with the ending their run.json records."""
    from aw.formats import FormatError, read_run_info

    for tid in skipped:
        try:
            info = read_run_info(out / arm.system / tid / "run.json")
        except FormatError as exc:
            arm.failed[tid] = str(exc)
            continue
        if info.ended != "finished":
            arm.failed[tid] = f"{info.ended}: {_first_line(info.error)}"


def write_study(
    out: Path, agent_cfg: BatchConfig, refine_cfg: RefineConfig, arms: list[StudyArm], task_ids: list[str]
) -> Path:
    spec = refine_cfg.spec
    doc = {
        "format": STUDY_FORMAT,
        "format_version": 1,
        "suite": str(Path(agent_cfg.suite_dir).resolve()),
        "agent": agent_cfg.agent or agent_cfg.harness,
        "agent_seed": agent_cfg.seed,
        "refiner": spec.name,
        "refiner_command": list(spec.command) if spec.command else None,
        "refiner_seed": refine_cfg.seed,
        "refiner_steps": refine_cfg.steps,
        "tasks": list(task_ids),
        "arms": [a.doc() for a in arms],
        "counts": dict(Counter(a.status for a in arms)),
    }
    path = out / STUDY_FILE
    write_json_atomic(path, doc)
    return path
