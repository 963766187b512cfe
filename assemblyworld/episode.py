"""The solver: one episode of one task, Inspect's ReAct agent on that task's ``aw-serve``.

Per sample, ``aw-serve TASK_DIR --record RUN_DIR`` runs as the agent's MCP server over stdio
(Inspect's own MCP client), with ONE connection for the whole sample, so every call acts on one
scene and lands in one recording. The agent is ``react()`` with no system prompt and no submit
tool: the model sees the task text as the user message and exactly the server's tools, and the
episode ends when it answers without a tool call (its last text is the report), as a Claude Code
or Codex session ends. It also ends when the server's execution budget runs out (the server has
written ``final.json``) or an Inspect limit is hit; either way the recording's final state is
scored. ``run.json`` is written beside the recording however the episode ends
(:mod:`assemblyworld.runinfo`).

Faults: a server that refuses to start or dies mid-episode fails the sample with an error that
names ``aw-serve`` and its last stderr lines (never a hang, never a score); every process the
server left behind is killed when the sample ends, Ctrl-C included (each carries the sample's
marker, :mod:`aw.runner.supervise`).
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import anyio
import psutil
from inspect_ai.agent import AgentState, react
from inspect_ai.model import ChatMessage, get_model
from inspect_ai.solver import Generate, Solver, TaskState, solver
from inspect_ai.tool import mcp_server_stdio
from inspect_ai.util import LimitExceededError, sample_limits, span

from assemblyworld.hooks import epochs_of
from assemblyworld.runinfo import EpisodeEnd, write_episode_run_info
from aw.formats import FormatError, read_final
from aw.runner.batch import aw_serve_command, episode_env
from aw.runner.supervise import MARKER_VAR, kill_all, marked_processes, new_marker

__all__ = ["EpisodeSettings", "assembly_episode", "run_dir_for", "system_label", "RUN_DIR_KEY", "ServerFailed"]

RUN_DIR_KEY = "assemblyworld:run_dir"  # the sample store key the scorer reads
STDERR_TAIL = 12  # lines of the server's stderr quoted in an error


class ServerFailed(RuntimeError):
    """``aw-serve`` refused to start or died during the episode."""


@dataclass(frozen=True)
class EpisodeSettings:
    """What every episode of a task shares (the task's arguments)."""

    suite_dir: Path
    runs_dir: Path
    system: str | None  # None: the model's name
    surface: str = "default"
    budget_minutes: float = 60.0
    overwrite: bool = False


def system_label(model_name: str) -> str:
    """A model name as a runs-folder name: ``org/model`` -> ``org-model``."""
    label = model_name.strip().replace("/", "-").replace("\\", "-")
    return label if label and label not in (".", "..") else "model"


def run_dir_for(runs_dir: Path, system: str, task_id: str, epoch: int, epochs: int) -> Path:
    """``RUNS/<system>/<task_id>``; with several epochs ``RUNS/<system>/attempt-<epoch>/<task_id>``,
    the layout ``aw-score`` reads as one system per attempt (as ``aw-serve --record-under`` writes)."""
    base = runs_dir / system
    return (base / f"attempt-{epoch}" / task_id) if epochs > 1 else (base / task_id)


class _StderrLines(logging.Handler):
    """Collects the server's stderr lines, which Inspect's MCP client logs under the server's name."""

    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


def _server_process(marker: str) -> psutil.Process | None:
    """The ``aw-serve`` process this sample started (the marked child of this process)."""
    me = os.getpid()
    for proc in marked_processes(marker):
        try:
            if proc.ppid() == me:
                return proc
        except psutil.Error:
            continue
    return None


def _alive(proc: psutil.Process | None) -> bool:
    try:
        return proc is not None and proc.is_running() and proc.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def _limit_reached() -> str | None:
    """The Inspect time or working limit this sample has reached, if any (they cancel the solver)."""
    try:
        limits = sample_limits()
    except RuntimeError:
        return None
    for kind, lim in (("time", limits.time), ("working", limits.working)):
        if lim.limit is not None and lim.usage >= lim.limit:
            return f"Inspect {kind} limit of {lim.limit:g} s reached"
    return None


@solver
def assembly_episode(settings: EpisodeSettings) -> Solver:
    """One recorded episode per sample (see the module doc)."""

    async def solve(state: TaskState, generate: Generate) -> TaskState:
        episode = _Episode(settings, state)
        agent_state = AgentState(messages=state.messages)
        try:
            async with episode.server:  # starts aw-serve; a refused start raises here, with the server's line
                episode.connected()
                agent = react(prompt=None, tools=[episode.server], submit=False, on_continue=episode.go_on)
                try:
                    async with span(name="react", type="agent"):
                        agent_state = await agent(agent_state)
                except BaseException:
                    episode.note_server()  # alive or not when the episode failed (leaving this block stops it)
                    raise
        except BaseException as exc:
            raise episode.ended_by(exc) from None
        finally:
            state.messages = agent_state.messages
            if agent_state.output:
                state.output = agent_state.output
            episode.close(agent_state.messages)
        return state

    return solve


class _Episode:
    """One sample's server, its liveness, how the episode ended, and its ``run.json``."""

    def __init__(self, settings: EpisodeSettings, state: TaskState) -> None:
        self.settings = settings
        self.task_id = str(state.sample_id)
        self.model = str(get_model())
        self.system = settings.system or system_label(get_model().name)
        self.epoch = state.epoch
        self.epochs = epochs_of(state.uuid) or state.epoch
        self.run_dir = run_dir_for(settings.runs_dir, self.system, self.task_id, self.epoch, self.epochs)
        self.run_dir.parent.mkdir(parents=True, exist_ok=True)
        state.store.set(RUN_DIR_KEY, str(self.run_dir))

        args = [str(settings.suite_dir / "tasks" / self.task_id), "--record", str(self.run_dir)]
        args += ["--system", self.system, "--budget-minutes", f"{settings.budget_minutes:g}"]
        args += ["--surface", settings.surface] + (["--overwrite"] if settings.overwrite else [])
        command = aw_serve_command()
        self.marker = new_marker()
        name = f"aw-serve-{self.marker[:8]}"
        env = {**episode_env(), MARKER_VAR: self.marker}
        self.server = mcp_server_stdio(name=name, command=command[0], args=command[1:] + args, env=env)
        # Inspect's MCP client logs the server's stderr under the server's name
        self.stderr = _StderrLines()
        self.server_log = logging.getLogger(f"inspect_ai.tool._mcp.{name}")
        self.server_log.setLevel(logging.INFO)
        self.server_log.addHandler(self.stderr)

        self.proc: psutil.Process | None = None
        self.is_connected = False
        self.server_gone = False  # when the agent failed
        self.end = EpisodeEnd()
        self.started_at = datetime.now(UTC).isoformat(timespec="seconds")
        self.t0 = time.monotonic()

    def connected(self) -> None:
        self.is_connected = True
        self.proc = _server_process(self.marker)

    def _server_gone(self) -> bool:
        return self.proc is not None and not _alive(self.proc)

    def note_server(self) -> None:
        self.server_gone = self._server_gone()

    def failed(self, what: str, cause: BaseException | None = None) -> ServerFailed:
        """The sample's error: what happened to aw-serve, its message and its last stderr lines."""
        said = str(cause) if cause is not None else ""
        tail = [ln for ln in self.stderr.lines[-STDERR_TAIL:] if ln.strip() and ln.strip() not in said]
        return ServerFailed(
            f"aw-serve ({self.task_id}) {what}"
            + (f": {said}" if said else "")
            + ("; its stderr:\n" + "\n".join(tail) if tail else "")
        )

    async def go_on(self, agent_state: AgentState) -> bool:
        """ReAct's continue hook: go on while the model calls tools, the server lives and the
        server's episode is open (it writes final.json at once when the budget is spent)."""
        if self._server_gone():
            raise self.failed("exited during the episode")
        if (self.run_dir / "final.json").is_file():
            self.end.server_ended = True
            return False
        return bool(agent_state.output.message.tool_calls)

    def ended_by(self, exc: BaseException) -> BaseException:
        """Record how ``exc`` ended the episode; the exception the sample should end with."""
        if isinstance(exc, LimitExceededError):
            self.end.ended, self.end.error = "timeout", exc.message
            return exc
        if isinstance(exc, anyio.get_cancelled_exc_class()):
            reached = _limit_reached()  # Inspect's time and working limits cancel the solver
            self.end.ended, self.end.error = ("timeout", reached) if reached else ("error", "interrupted")
            return exc
        if isinstance(exc, Exception) and not isinstance(exc, ServerFailed):
            if not self.is_connected:
                exc = self.failed("did not start", exc)
            elif self.server_gone:
                exc = self.failed("exited during the episode", exc)
        self.end.ended, self.end.error = "error", str(exc) or type(exc).__name__
        return exc

    def close(self, messages: list[ChatMessage]) -> None:
        """Stop whatever the server left running; write run.json for a recording this episode made."""
        self.server_log.removeHandler(self.stderr)
        kill_all(marked_processes(self.marker), grace=2.0)
        if not self.is_connected:  # a refused start: the folder (if any) is not this episode's
            return
        if self.end.ended == "finished" and self.end.server_ended:
            self.end.ended = "timeout" if _final_reason(self.run_dir) == "timeout" else "error"
            self.end.error = "the server ended the episode: " + (_final_reason(self.run_dir) or "unknown reason")
        self.end.wall_seconds = time.monotonic() - self.t0
        self.end.server_stderr = self.stderr.lines
        settings = {"budget_minutes": self.settings.budget_minutes, "surface": self.settings.surface}
        write_episode_run_info(
            self.run_dir,
            self.end,
            system=self.system,
            task_id=self.task_id,
            model=self.model,
            started_at=self.started_at,
            messages=messages,
            epoch=self.epoch,
            epochs=self.epochs,
            settings={**settings, "model": self.model},
        )


def _final_reason(run_dir: Path) -> str | None:
    try:
        return read_final(run_dir / "final.json").reason
    except (FormatError, OSError):
        return None
