"""Run a system on the tasks of a suite: one supervised process per episode, ``jobs`` at a time.

Leaves ``OUT/<system>/<task_id>/`` as ``aw-score`` reads it: ``trajectory.jsonl``, ``final.json``
and ``captures/`` (written by ``aw-serve``), and ``run.json`` (written here). An episode that
crashes, hangs or runs out of time is recorded as such and the batch goes on.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from aw.formats import (
    FormatError,
    RunEnded,
    RunInfo,
    read_manifest,
    read_run_info,
    read_task,
    read_trajectory,
    write_run_info,
)
from aw.formats.io import parse_model, read_tail
from aw.formats.run import BATCH_FILE, BatchPlan, ExistingRuns, existing_runs, system_label_problem, write_batch_plan
from aw.formats.strict_json import read_json, read_json_object
from aw.formats.suite import suite_paths
from aw.formats.task import MAX_BUDGET_MINUTES
from aw.formats.trajectory import FinalState, write_final
from aw.runlock import holder_of
from aw.runner.supervise import MARKER_VAR, WorkerProcess, kill_everything, new_marker, run_supervised

DEFAULT_AGENT_TIMEOUT_MIN = 10.0
DEFAULT_HARNESS_TIMEOUT_MIN = 65.0  # the paper's 60-minute budget plus startup and export


class RunnerError(ValueError):
    """Bad arguments or inputs for a batch (said before anything runs)."""


def aw_serve_command() -> list[str]:
    """The command that starts ``aw-serve``: the entry point beside this interpreter if installed,
    else one on PATH, else the module through this interpreter."""
    beside = Path(sys.executable).with_name("aw-serve")
    if beside.is_file() and os.access(beside, os.X_OK):
        return [str(beside)]
    found = shutil.which("aw-serve")
    if found:
        return [found]
    return [sys.executable, "-c", "from aw_server.cli import run; run()"]


def episode_env() -> dict[str, str]:
    """Environment for servers: ours, with the offscreen GL platform chosen once for all episodes
    (otherwise every server would probe EGL on its own)."""
    env = dict(os.environ)
    if not env.get("PYOPENGL_PLATFORM"):
        try:
            from aw.render_platform import select_platform

            env["PYOPENGL_PLATFORM"] = select_platform()
        except Exception:  # the server will choose (or explain) on its own
            pass
    return env


@dataclass
class BatchConfig:
    """One system on a suite. Exactly one of ``agent`` (a baseline agent) or ``harness``."""

    suite_dir: Path
    system: str
    out_dir: Path
    agent: str | None = None
    harness: str | None = None
    jobs: int = 1
    tasks: list[str] | None = None
    seed: int = 0
    noise: float | None = None
    timeout_minutes: float | None = None
    budget_minutes: float | None = None
    think_seconds: float = 0.0
    call_timeout: float = 120.0
    overwrite: bool = False
    keep_failed: bool = False  # keep runs that failed (default: a rerun retries them)
    agent_options: dict[str, Any] = field(default_factory=dict)
    harness_bin: str | None = None
    harness_model: str | None = None
    harness_args: list[str] = field(default_factory=list)
    price_table: Path | None = None
    progress: bool = True
    initial_poses: Path | None = None  # start states: <task_id>/final.json or <task_id>.json under it

    @property
    def limit_seconds(self) -> float:
        default = DEFAULT_HARNESS_TIMEOUT_MIN if self.harness else DEFAULT_AGENT_TIMEOUT_MIN
        return 60.0 * (self.timeout_minutes if self.timeout_minutes is not None else default)


@dataclass
class Episode:
    task_id: str
    task_dir: Path
    targets_path: Path
    run_dir: Path
    initial_poses: Path | None = None


def check_config(cfg: BatchConfig) -> None:
    from aw.agents import AGENT_OPTIONS, AGENTS
    from aw.runner.harness import HARNESSES

    if (cfg.agent is None) == (cfg.harness is None):
        raise RunnerError("give exactly one of --agent or --harness")
    if cfg.agent is not None and cfg.agent not in AGENTS:
        raise RunnerError(f"unknown agent {cfg.agent!r}; available: {', '.join(sorted(AGENTS))}")
    if cfg.harness is not None and cfg.harness not in HARNESSES:
        raise RunnerError(f"unknown harness {cfg.harness!r}; available: {', '.join(sorted(HARNESSES))}")
    if cfg.agent_options:
        known = AGENT_OPTIONS.get(cfg.agent or "", frozenset())
        unknown = sorted(set(cfg.agent_options) - known)
        if unknown:
            who = f"agent {cfg.agent!r}" if cfg.agent else f"harness {cfg.harness!r}"
            raise RunnerError(
                f"unknown --agent-option {', '.join(unknown)} for {who}; known: {', '.join(sorted(known)) or 'none'}"
            )
    if cfg.noise is not None and cfg.agent != "oracle":
        raise RunnerError("--noise applies to the oracle agent only")
    if cfg.noise is not None and not (cfg.noise >= 0 and cfg.noise < float("inf")):
        raise RunnerError(f"--noise must be a finite number >= 0, got {cfg.noise}")
    if cfg.jobs < 1:
        raise RunnerError("--jobs must be at least 1")
    if not (cfg.limit_seconds > 0):
        raise RunnerError("--timeout-minutes must be positive")
    if cfg.budget_minutes is not None and not 0 < cfg.budget_minutes <= MAX_BUDGET_MINUTES:
        raise RunnerError(f"--budget-minutes must be positive and at most {MAX_BUDGET_MINUTES:g}")
    if cfg.think_seconds < 0 or cfg.call_timeout <= 0:
        raise RunnerError("--think-seconds must be >= 0 and --call-timeout positive")
    problem = system_label_problem(cfg.system)
    if problem:
        raise RunnerError(f"--system {problem} (it becomes a folder and a row of the reports)")


def system_label(agent: str | None, harness: str | None, options: dict[str, Any] | None = None) -> str:
    """The default system label: the agent or harness name, with the oracle's noise level when one
    is set (``oracle-noise0.5``), so that two noise levels never share a runs folder."""
    label = agent or harness or ""
    noise = (options or {}).get("noise")
    return f"{label}-noise{noise:g}" if isinstance(noise, (int, float)) else label


def effective_options(cfg: BatchConfig) -> dict[str, Any]:
    """The agent options an episode gets: ``agent_options`` with ``noise`` from ``--noise``."""
    options = dict(cfg.agent_options)
    if cfg.noise is not None:
        options["noise"] = cfg.noise
    return options


# The options that change what an episode does, and the flag that sets each (run.json keeps them
# as ``extra.settings``). Not here: --jobs, --call-timeout, --harness-bin (how, not what, is run).
SETTING_FLAGS = {
    "agent": "--agent",
    "harness": "--harness",
    "seed": "--seed",
    "think_seconds": "--think-seconds",
    "budget_minutes": "--budget-minutes",
    "timeout_minutes": "--timeout-minutes",
    "harness_model": "--harness-model",
    "harness_args": "--harness-arg",
}


def run_settings(cfg: BatchConfig) -> dict[str, Any]:
    """The behaviour-changing options of ``cfg`` (agent options as ``option.<name>``)."""
    out: dict[str, Any] = {"timeout_minutes": cfg.limit_seconds / 60.0, "budget_minutes": cfg.budget_minutes}
    if cfg.agent is not None:
        out.update(agent=cfg.agent, seed=cfg.seed, think_seconds=cfg.think_seconds)
        out.update({f"option.{k}": v for k, v in sorted(effective_options(cfg).items())})
    else:
        out.update(harness=cfg.harness, harness_model=cfg.harness_model, harness_args=list(cfg.harness_args))
    return out


def _recorded_settings(info: RunInfo) -> dict[str, Any]:
    """What an existing run.json says about its options; for one written before ``settings``
    was kept, what its other fields tell (agent, seed, think seconds, limit, agent options)."""
    ex = info.extra
    if isinstance(ex.get("settings"), dict):
        return dict(ex["settings"])
    if info.harness is not None:
        return {"timeout_minutes": ex["limit_seconds"] / 60.0} if "limit_seconds" in ex else {}
    out: dict[str, Any] = {"agent": info.agent}
    for key, name in (("seed", "seed"), ("think_seconds", "think_seconds")):
        if key in ex:
            out[name] = ex[key]
    if "limit_seconds" in ex:
        out["timeout_minutes"] = ex["limit_seconds"] / 60.0
    out.update({f"option.{k}": v for k, v in (ex.get("options") or {}).items()})
    return out


def _flag(key: str) -> str:
    if key == "option.noise":
        return "--noise"
    if key.startswith("option."):
        return f"--agent-option {key[7:]}"
    return SETTING_FLAGS.get(key, key)


def _shown(v: Any) -> str:
    if v is None:
        return "not set"
    if isinstance(v, float):
        return f"{v:g}"
    return json.dumps(v) if isinstance(v, (list, dict)) else str(v)


def settings_differences(recorded: dict[str, Any], now: dict[str, Any]) -> list[str]:
    """``"--noise 0.5 there, 1.5 now"`` for every option whose value differs. Agent options are
    compared over both sides' keys (one left unset is a difference); other keys only where the
    recorded side has them (older run.json files lack some)."""
    keys = [k for k in now if k in recorded or k.startswith("option.")]
    keys += [k for k in recorded if k.startswith("option.") and k not in now]
    out = []
    for k in keys:
        a, b = recorded.get(k), now.get(k)
        if _shown(a) != _shown(b):
            out.append(f"{_flag(k)} {_shown(a)} there, {_shown(b)} now")
    return out


def check_reuse(cfg: BatchConfig, planned: list[Episode]) -> None:
    """Refuse a batch that would leave runs of other options under this label: the existing runs
    it would skip, and (with ``--tasks``) those of other tasks it does not touch, which aw-score
    would read as one system. Names the option that differs and the flags that resolve it."""
    system_dir = cfg.out_dir / cfg.system
    if not system_dir.is_dir():
        return
    replaced = (
        {ep.task_id for ep in planned}
        if cfg.overwrite
        else set(existing_runs({ep.task_id: ep.run_dir for ep in planned}, cfg.keep_failed).retry)
    )
    now = run_settings(cfg)
    clashes: dict[str, list[str]] = {}
    for path in sorted(system_dir.glob("*/run.json")):
        if path.parent.name in replaced:
            continue
        try:
            info = read_run_info(path)
        except FormatError:  # unreadable: aw-score reports it; nothing to compare
            continue
        for diff in settings_differences(_recorded_settings(info), now):
            clashes.setdefault(diff, []).append(path.parent.name)
    if not clashes:
        return
    tasks = sorted({t for ts in clashes.values() for t in ts})
    outside = [t for t in tasks if t not in {ep.task_id for ep in planned}]
    fix = (
        "--overwrite to replace those runs"
        if not outside
        else "--overwrite without --tasks (or with --tasks also naming "
        + ", ".join(outside[:3])
        + (", ..." if len(outside) > 3 else "")
        + ") to replace them"
    )
    raise RunnerError(
        f"{system_dir} holds {len(tasks)} run{'s' if len(tasks) != 1 else ''} made with other options "
        f"({'; '.join(clashes)}); pass --system LABEL to run these options as another system, or {fix}"
    )


def plan_episodes(cfg: BatchConfig) -> list[Episode]:
    """The suite's tasks (or the ``tasks`` subset, in suite order), checked before anything runs."""
    try:
        ids = read_manifest(cfg.suite_dir).select(cfg.tasks)
    except ValueError as exc:  # FormatError too
        raise RunnerError(str(exc)) from None
    out = []
    for tid in ids:
        task_dir, targets = suite_paths(cfg.suite_dir, tid)
        if not task_dir.is_dir():
            raise RunnerError(f"task directory missing: {task_dir}")
        if cfg.agent == "oracle" and not targets.is_file():
            raise RunnerError(f"the oracle needs the targets file, missing: {targets}")
        start = None
        if cfg.initial_poses is not None:
            from aw.formats.poses import initial_poses_file, read_initial_poses

            start = initial_poses_file(cfg.initial_poses, tid)
            if start is None:
                raise RunnerError(
                    f"--initial-poses {cfg.initial_poses}: no start state for {tid} ({tid}/final.json or {tid}.json)"
                )
            start = start.resolve()
            try:  # the server reads it again; a bad file is named here, before anything runs
                read_initial_poses(start, tid, read_task(task_dir).part_ids)
            except FormatError as exc:
                raise RunnerError(str(exc)) from None
        out.append(
            Episode(tid, task_dir.resolve(), targets.resolve(), (cfg.out_dir / cfg.system / tid).resolve(), start)
        )
    return out


def _server_args(cfg: BatchConfig, ep: Episode) -> list[str]:
    args = [str(ep.task_dir), "--record", str(ep.run_dir), "--system", cfg.system]
    if cfg.budget_minutes is not None:
        args += ["--budget-minutes", f"{cfg.budget_minutes:g}"]
    if ep.initial_poses is not None:
        args += ["--initial-poses", str(ep.initial_poses)]
    return args


def _progress_state(path: Path) -> dict[str, Any] | None:
    try:
        return read_json_object(path)
    except FormatError:
        return None


def trajectory_facts(run_dir: Path) -> dict[str, Any]:
    """Server-side truth about the episode: call counts, end reason, final poses."""
    path = run_dir / "trajectory.jsonl"
    if not path.is_file():
        return {}
    try:
        traj = read_trajectory(path)
    except FormatError as exc:
        return {"trajectory_problem": str(exc)}
    counts = Counter(c.tool for c in traj.calls)
    return {
        "traj": traj,
        "call_counts": dict(counts),
        "tool_errors": sum(1 for c in traj.calls if not c.ok),
        "n_calls": len(traj.calls),
        "edits": sum(1 for c in traj.calls if c.poses is not None),
        "server_end": traj.end.reason if traj.end else None,
        "episode_seconds": traj.end.t if traj.end else (traj.calls[-1].t if traj.calls else 0.0),
    }


def ensure_final(run_dir: Path, facts: dict[str, Any], task_id: str) -> str | None:
    """Where final.json came from: the server, or (if it was killed before writing it) the last
    state its trajectory recorded. None if there is no record at all."""
    if (run_dir / "final.json").is_file():
        return "server"
    traj = facts.get("traj")
    if traj is None:
        return None
    write_final(run_dir / "final.json", FinalState(task_id=task_id, reason="interrupted", poses=traj.final_poses()))
    return "runner: last state recorded in trajectory.jsonl"


def recorded_episode(run_dir: Path, task_id: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """What the server recorded in ``run_dir``, for run.json: ``(facts, extra)``, the
    :func:`trajectory_facts` and the ``extra`` entries every runner writes from them (call counts,
    tool errors, edits, how the server ended, episode time, where final.json came from, and a
    trajectory problem where there is one), final.json made sure of (:func:`ensure_final`)."""
    facts = trajectory_facts(run_dir)
    extra: dict[str, Any] = {
        "call_counts": facts.get("call_counts", {}),
        "tool_errors": facts.get("tool_errors"),
        "edits": facts.get("edits"),
        "server_end": facts.get("server_end"),
        "episode_seconds": facts.get("episode_seconds"),
        "final_source": ensure_final(run_dir, facts, task_id),
    }
    if "trajectory_problem" in facts:
        extra["trajectory_problem"] = facts["trajectory_problem"]
    return facts, extra


def new_worker(env: dict[str, str]) -> WorkerProcess:
    """A worker process for baseline-agent episodes. Its own stderr (anything before the first
    episode redirects it to that episode's ``agent.log``) goes to a temporary file that is
    removed when the worker closes, unless it has something in it."""
    fd, log = tempfile.mkstemp(prefix="aw-run-worker-", suffix=".log")
    os.close(fd)
    return WorkerProcess([sys.executable, "-m", "aw.runner.episode", "--worker"], env, Path(log))


def _run_agent_episode(cfg: BatchConfig, ep: Episode, env: dict[str, str], worker: WorkerProcess) -> RunInfo:
    from aw.runner.episode import EpisodeResult, EpisodeSpec

    if cfg.agent is None:
        raise ValueError("an agent episode needs the batch's agent")
    work = ep.run_dir / ".runner"
    work.mkdir(parents=True, exist_ok=True)
    episode_marker = new_marker()
    options = effective_options(cfg)
    spec = EpisodeSpec(
        task_id=ep.task_id,
        agent=cfg.agent,
        server_command=aw_serve_command() + _server_args(cfg, ep),
        server_env={**env, MARKER_VAR: episode_marker},
        server_log=str(ep.run_dir / "server.log"),
        agent_log=str(ep.run_dir / "agent.log"),
        seed=cfg.seed,
        think_seconds=cfg.think_seconds,
        options=options,
        targets_path=str(ep.targets_path) if cfg.agent == "oracle" else None,
        call_timeout=cfg.call_timeout,
        progress_path=str(work / "progress.json"),
        result_path=str(work / "result.json"),
    )
    started = datetime.now(UTC).isoformat(timespec="seconds")
    sup = worker.run(spec.model_dump_json(), cfg.limit_seconds, episode_marker)
    result: EpisodeResult | None = None
    if Path(spec.result_path).is_file():
        try:
            result = parse_model(EpisodeResult, read_json(spec.result_path), spec.result_path)
        except FormatError as exc:  # the agent process wrote something else: a crash of its own
            result = EpisodeResult(ended="crashed", error=f"the agent process left an unreadable result ({exc})")
    extra: dict[str, Any] = {
        "seed": cfg.seed,
        "think_seconds": cfg.think_seconds,
        "limit_seconds": cfg.limit_seconds,
        "settings": run_settings(cfg),
    }
    if options:
        extra["options"] = options
    ended: RunEnded
    error: str | None
    if sup.timed_out:
        # No progress file yet: the agent was still connecting to the server.
        state = _progress_state(Path(spec.progress_path)) or {
            "in_flight": "connect",
            "since": time.time() - sup.wall_seconds,
        }
        in_flight = state.get("in_flight")
        stalled = time.time() - float(state.get("since", 0.0))
        hung_after = min(60.0, 0.25 * cfg.limit_seconds)
        if in_flight and stalled > hung_after:
            ended, error = (
                "hung",
                f"killed at the {cfg.limit_seconds:g} s limit; {in_flight} had been waiting for the server for {stalled:.0f} s",
            )
        else:
            ended, error = "timeout", f"killed at the {cfg.limit_seconds:g} s limit while the agent was still working"
        extra["killed_pids"] = sup.killed
    elif result is None:
        ended = "crashed"
        tail = read_tail(ep.run_dir / "agent.log", 1500).strip()
        error = f"the agent process died (exit code {sup.returncode}) without a result" + (f":\n{tail}" if tail else "")
    else:
        ended, error = result.ended, result.error
    facts, recorded = recorded_episode(ep.run_dir, ep.task_id)
    if "call_counts" not in facts and result is not None:  # no recording: what the client counted
        recorded["call_counts"] = result.call_counts
    extra.update(recorded)
    extra["client_call_counts"] = result.call_counts if result else {}
    extra["exit_code"] = sup.returncode
    if result is not None:
        extra["agent_stats"] = result.stats
    return RunInfo(
        system=cfg.system,
        task_id=ep.task_id,
        agent=cfg.agent or "",
        harness=None,
        started_at=started,
        wall_seconds=round(sup.wall_seconds, 3),
        mcp_calls=facts.get("n_calls", sum(result.call_counts.values()) if result else None),
        ended=ended,
        error=error,
        declared_complete=result.declared_complete if result else None,
        report=result.report if result else None,
        extra=extra,
    )


def _run_harness_episode(cfg: BatchConfig, ep: Episode, env: dict[str, str]) -> RunInfo:
    from aw.runner.harness import HARNESSES, HarnessOptions

    if cfg.harness is None:
        raise ValueError("a harness episode needs the batch's harness")
    adapter = HARNESSES[cfg.harness]
    opts = HarnessOptions(
        binary=cfg.harness_bin,
        model=cfg.harness_model,
        extra_args=list(cfg.harness_args),
        price_table=cfg.price_table,
    )
    work = ep.run_dir / ".runner"
    work.mkdir(parents=True, exist_ok=True)
    marker = new_marker()
    prepared = adapter.prepare(ep.task_dir, aw_serve_command(), _server_args(cfg, ep), env, marker, opts)
    started = datetime.now(UTC).isoformat(timespec="seconds")
    sup = run_supervised(
        prepared.command,
        env=prepared.env,
        marker=marker,
        limit_seconds=cfg.limit_seconds,
        cwd=prepared.cwd,
        stdin_data=prepared.stdin,
        stdout_path=ep.run_dir / adapter.transcript_name,
        stderr_path=ep.run_dir / "harness.log",
    )
    usage = adapter.parse(ep.run_dir / adapter.transcript_name, opts)
    shutil.rmtree(prepared.cwd, ignore_errors=True)
    facts, recorded = recorded_episode(ep.run_dir, ep.task_id)
    ended: RunEnded
    error: str | None
    if sup.timed_out:
        ended, error = "timeout", f"killed at the {cfg.limit_seconds:g} s limit"
    elif sup.returncode == 0 and not usage.is_error:
        ended, error = "finished", None
    elif sup.returncode is not None and sup.returncode < 0:
        ended, error = "crashed", f"the harness died from signal {-sup.returncode}"
    else:
        ended = "error"
        error = usage.error or f"the harness exited with code {sup.returncode}"
        if not usage.error:
            tail = read_tail(ep.run_dir / "harness.log", 1500).strip()
            error += f":\n{tail}" if tail else ""
    extra: dict[str, Any] = {
        "harness_command": prepared.display_command,
        **recorded,
        "exit_code": sup.returncode,
        "limit_seconds": cfg.limit_seconds,
        "transcript": adapter.transcript_name,
        "settings": run_settings(cfg),
        **usage.extra,
    }
    if sup.killed:
        extra["killed_pids"] = sup.killed
    return RunInfo(
        system=cfg.system,
        task_id=ep.task_id,
        agent=usage.model or cfg.harness_model or "",
        harness=adapter.label(usage),
        started_at=started,
        wall_seconds=round(sup.wall_seconds, 3),
        mcp_calls=facts.get("n_calls"),
        ended=ended,
        error=error,
        tokens=usage.tokens,
        cost_usd=usage.cost_usd,
        declared_complete=None,
        report=usage.report,
        extra=extra,
    )


def run_episode(
    cfg: BatchConfig,
    ep: Episode,
    env: dict[str, str],
    worker: WorkerProcess | None = None,
    cancel: threading.Event | None = None,
) -> RunInfo:
    """Run one episode from a clean run directory and write its ``run.json``. Baseline agents
    run in ``worker`` (one is started for this episode alone if none is given). An episode cut
    short by ``cancel`` (Ctrl-C) leaves no run directory, so that a rerun resumes with it. A run
    directory that a live server is still recording into is left untouched (an ``error`` run)."""
    busy = holder_of(ep.run_dir)
    if busy is not None:
        return RunInfo(
            system=cfg.system,
            task_id=ep.task_id,
            agent=cfg.agent or cfg.harness_model or "",
            harness=cfg.harness,
            ended="error",
            error=f"runner refused: {ep.run_dir} is being recorded by {busy}; left untouched",
        )
    if ep.run_dir.exists():
        shutil.rmtree(ep.run_dir)
    ep.run_dir.mkdir(parents=True)
    try:
        if cfg.harness:
            info = _run_harness_episode(cfg, ep, env)
        elif worker is not None:
            info = _run_agent_episode(cfg, ep, env, worker)
        else:
            own = new_worker(env)
            try:
                info = _run_agent_episode(cfg, ep, env, own)
            finally:
                own.close()
    except Exception as exc:  # the runner's own failure for this episode: record it, go on
        info = RunInfo(
            system=cfg.system,
            task_id=ep.task_id,
            agent=cfg.agent or cfg.harness_model or "",
            harness=cfg.harness,
            ended="error",
            error=f"runner failed: {type(exc).__name__}: {exc}",
        )
    if cancel is not None and cancel.is_set():
        shutil.rmtree(ep.run_dir, ignore_errors=True)
        return info
    if ep.initial_poses is not None:
        info.extra["initial_poses"] = str(ep.initial_poses)
    write_run_info(ep.run_dir / "run.json", info)
    shutil.rmtree(ep.run_dir / ".runner", ignore_errors=True)
    return info


@dataclass
class BatchResult:
    runs: list[RunInfo]
    skipped: list[str]
    wall_seconds: float
    existing: ExistingRuns = field(default_factory=ExistingRuns)  # what was done with the runs already there

    def endings(self) -> Counter[str]:
        return Counter(r.ended for r in self.runs)


def _write_plan(cfg: BatchConfig, episodes: list[Episode]) -> BatchPlan:
    """Say in ``RUNS/<system>/.aw-batch.json`` which episodes this batch runs (watchers show
    those not started yet as queued)."""
    plan = BatchPlan(
        system=cfg.system,
        suite_dir=str(Path(cfg.suite_dir).resolve()),
        tasks=[ep.task_id for ep in episodes],
        pid=os.getpid(),
        host=socket.gethostname(),
        started_unix=time.time(),
        budget_minutes=cfg.budget_minutes,
    )
    write_batch_plan(cfg.out_dir / cfg.system / BATCH_FILE, plan)
    return plan


def _close_plan(cfg: BatchConfig, plan: BatchPlan) -> None:
    plan.finished_unix = time.time()
    try:
        write_batch_plan(cfg.out_dir / cfg.system / BATCH_FILE, plan)
    except OSError:  # a full disk: the batch's own error, if any, is the one to report
        pass


def run_batch(
    cfg: BatchConfig, on_done: Callable[[RunInfo], None] | None = None, log: Callable[[str], None] | None = None
) -> BatchResult:
    """Run every planned episode, ``cfg.jobs`` at a time, with a progress bar. Without
    ``overwrite``, tasks with a finished run are skipped and runs that failed are retried (said
    through ``log``), or kept with ``keep_failed``."""
    check_config(cfg)
    episodes = plan_episodes(cfg)
    check_reuse(cfg, episodes)
    skipped: list[str] = []
    existing = None
    if not cfg.overwrite:
        existing = existing_runs({ep.task_id: ep.run_dir for ep in episodes}, cfg.keep_failed)
        skipped = existing.kept
        episodes = [ep for ep in episodes if ep.task_id not in set(skipped)]
        if log is not None and existing.retry:
            log(existing.retry_line())
    (cfg.out_dir / cfg.system).mkdir(parents=True, exist_ok=True)
    plan = _write_plan(cfg, episodes)
    env = episode_env()
    t0 = time.monotonic()
    runs: list[RunInfo] = []
    lock = threading.Lock()
    bar = None
    if cfg.progress:
        from aw.progress import progress

        bar = progress(len(episodes), cfg.system, "task")
    counts: Counter[str] = Counter()
    workers: list[WorkerProcess] = []
    local = threading.local()

    cancel = threading.Event()

    def job(ep: Episode) -> RunInfo:
        if cfg.agent is None:
            return run_episode(cfg, ep, env, cancel=cancel)
        if getattr(local, "worker", None) is None:
            local.worker = new_worker(env)
            with lock:
                workers.append(local.worker)
        return run_episode(cfg, ep, env, local.worker, cancel=cancel)

    pool = ThreadPoolExecutor(max_workers=cfg.jobs)
    try:
        futures = [pool.submit(job, ep) for ep in episodes]
        for fut in as_completed(futures):
            info = fut.result()
            with lock:
                runs.append(info)
                counts[info.ended] += 1
                if bar is not None:
                    bar.set_postfix_str(", ".join(f"{k}={v}" for k, v in sorted(counts.items())), refresh=False)
                    bar.update(1)
            if on_done is not None:
                on_done(info)
    except KeyboardInterrupt:
        # Stop everything now: episode processes run in sessions of their own, so Ctrl-C
        # reached none of them. Episodes cut short leave no run directory.
        cancel.set()
        pool.shutdown(wait=False, cancel_futures=True)
        kill_everything()
        pool.shutdown(wait=True)
        raise
    finally:
        pool.shutdown(wait=True)
        for w in workers:
            w.close()
        if bar is not None:
            bar.close()
        _close_plan(cfg, plan)
    order = {ep.task_id: i for i, ep in enumerate(episodes)}
    runs.sort(key=lambda r: order.get(r.task_id, 0))
    return BatchResult(
        runs=runs,
        skipped=skipped,
        wall_seconds=time.monotonic() - t0,
        existing=existing or ExistingRuns(todo=[ep.task_id for ep in episodes]),
    )
