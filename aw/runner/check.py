"""Pre-flight check of an agent harness (``aw-run --check``, and before a harness batch).

A misconfigured harness otherwise fails every episode late (Claude Code: "Not logged in" after
starting; Codex: network retries until the episode limit). The check runs, in order:

1. binary: the executable exists and may be run;
2. version: ``BIN --version`` answers;
3. credentials: an API key in the environment or the CLI's own login file (presence only; the
   contents are never read);
4. probe: one short session on the suite's first task, through the same adapter and MCP config
   as an episode, whose prompt asks the model to name the ``aw-serve`` tools without calling
   them. It passes when the harness ends cleanly and its reply names ``start_episode``: the
   model was reached, and ``aw-serve`` started under the harness and listed its tools.

The first failing step stops the check; :class:`CheckStep` says what failed and what to do.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from aw.formats.io import read_tail

__all__ = ["CheckStep", "PROBE_PROMPT", "find_binary", "credential_sources", "check_harness", "DEFAULT_BINARIES"]

DEFAULT_BINARIES = {"claude-code": "claude", "codex": "codex"}
PROBE_LIMIT_S = 180.0
PROBE_PROMPT = (
    "AssemblyWorld connection check. Do not call any tool. Look at the tools the MCP server "
    "'assemblyworld' offers and reply with one line: TOOLS: followed by their names separated by spaces."
)

# Where each CLI keeps a login (presence is all the check looks at).
_CREDENTIAL_ENV = {
    "claude-code": (
        "ANTHROPIC_API_KEY",
        "ANTHROPIC_AUTH_TOKEN",
        "CLAUDE_CODE_OAUTH_TOKEN",
        "CLAUDE_CODE_USE_BEDROCK",
        "CLAUDE_CODE_USE_VERTEX",
    ),
    "codex": ("OPENAI_API_KEY", "CODEX_API_KEY"),
}
_LOGIN_HINT = {
    "claude-code": "log in once with 'claude' (then /login), or set ANTHROPIC_API_KEY",
    "codex": "log in once with 'codex login', or set OPENAI_API_KEY",
}


@dataclass
class CheckStep:
    name: str  # binary, version, credentials, probe
    ok: bool
    detail: str
    fix: str = ""

    def line(self) -> str:
        mark = "ok  " if self.ok else "FAIL"
        return f"{mark} {self.name}: {self.detail}" + (f" -> {self.fix}" if not self.ok and self.fix else "")


def find_binary(harness: str, given: str | None) -> Path:
    """The harness executable as an absolute path: ``given`` (a path, relative to the current
    directory, or a name on PATH) or the harness's usual name on PATH. Raises ValueError with a
    one-line reason when it is missing or not executable."""
    name = given or DEFAULT_BINARIES[harness]
    flag = "--harness-bin" if given else f"{name!r} on PATH"
    if os.sep in name or (given and Path(name).exists()):
        path = Path(name).expanduser().resolve()
        if not path.exists():
            raise ValueError(f"--harness-bin {given}: no such file")
        if path.is_dir() or not os.access(path, os.X_OK):
            raise ValueError(f"--harness-bin {given}: not an executable file (chmod +x?)")
        return path
    found = shutil.which(name)
    if found is None:
        hint = "install it or pass --harness-bin PATH" if not given else "no such command on PATH"
        raise ValueError(f"{flag}: not found; {hint}")
    return Path(found).resolve()


def credential_sources(harness: str, env: dict[str, str]) -> list[str]:
    """Names of the places a login for ``harness`` was found (variables set, login files present)."""
    found = [v for v in _CREDENTIAL_ENV[harness] if env.get(v)]
    home = Path(env.get("HOME") or Path.home())
    if harness == "claude-code":
        config = Path(env["CLAUDE_CONFIG_DIR"]) if env.get("CLAUDE_CONFIG_DIR") else home / ".claude"
        files = [config / ".credentials.json"]
    else:
        files = [Path(env["CODEX_HOME"]) / "auth.json" if env.get("CODEX_HOME") else home / ".codex" / "auth.json"]
    found += [str(f) for f in files if f.is_file()]
    return found


def _version(binary: Path, env: dict[str, str]) -> CheckStep:
    try:
        proc = subprocess.run(
            [str(binary), "--version"], capture_output=True, text=True, timeout=60, env=env, stdin=subprocess.DEVNULL
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        return CheckStep("version", False, f"{binary} --version failed: {exc}", "reinstall the harness CLI")
    text = (proc.stdout.strip() or proc.stderr.strip()).splitlines()
    if proc.returncode != 0 or not text:
        return CheckStep(
            "version",
            False,
            f"{binary} --version exited with code {proc.returncode}",
            "check that this is the harness CLI, or reinstall it",
        )
    return CheckStep("version", True, text[0][:200])


def _probe(
    harness: str,
    binary: Path,
    task_dir: Path,
    env: dict[str, str],
    model: str | None,
    extra_args: list[str],
    limit_s: float,
) -> CheckStep:
    from aw.runner.batch import aw_serve_command
    from aw.runner.harness import HARNESSES, HarnessOptions
    from aw.runner.supervise import new_marker, run_supervised

    adapter = HARNESSES[harness]
    opts = HarnessOptions(binary=str(binary), model=model, extra_args=list(extra_args))
    with tempfile.TemporaryDirectory(prefix="aw-check-") as tmp:
        run_dir = Path(tmp) / "probe"
        run_dir.mkdir()
        marker = new_marker()
        prepared = adapter.prepare(
            task_dir,
            aw_serve_command(),
            [str(task_dir), "--record", str(run_dir), "--system", "check"],
            env,
            marker,
            opts,
        )
        transcript, log = run_dir / adapter.transcript_name, run_dir / "harness.log"
        sup = run_supervised(
            prepared.command,
            env=prepared.env,
            marker=marker,
            limit_seconds=limit_s,
            cwd=prepared.cwd,
            stdin_data=PROBE_PROMPT.encode(),
            stdout_path=transcript,
            stderr_path=log,
        )
        usage = adapter.parse(transcript, opts)
        shutil.rmtree(prepared.cwd, ignore_errors=True)
        tail = read_tail(log).strip().splitlines()[-1:]
    if sup.timed_out:
        return CheckStep(
            "probe",
            False,
            f"no answer within {limit_s:g} s (the model is likely unreachable: network, proxy or credentials)",
            "run the CLI by hand once and fix what it reports",
        )
    if sup.returncode != 0 or usage.is_error:
        why = usage.error or f"exit code {sup.returncode}" + (f": {tail[0][:300]}" if tail else "")
        return CheckStep(
            "probe",
            False,
            why,
            _LOGIN_HINT[harness] if "log" in why.lower() else "run the CLI by hand once and fix what it reports",
        )
    if "start_episode" not in (usage.report or ""):
        return CheckStep(
            "probe",
            False,
            f"the harness answered but did not see aw-serve's tools (reply: {(usage.report or '')[:200]!r})",
            "check that aw-serve runs: aw-serve TASK_DIR --print-prompt",
        )
    return CheckStep(
        "probe",
        True,
        "the model answered and listed aw-serve's tools" + (f" (model {usage.model})" if usage.model else ""),
    )


def check_harness(
    harness: str,
    binary: str | None,
    task_dir: Path,
    *,
    model: str | None = None,
    extra_args: list[str] | None = None,
    env: dict[str, str] | None = None,
    probe_limit_s: float = PROBE_LIMIT_S,
) -> list[CheckStep]:
    """Run the check's steps in order until one fails; return the steps run."""
    env = dict(os.environ if env is None else env)
    try:
        path = find_binary(harness, binary)
    except ValueError as exc:
        return [
            CheckStep(
                "binary", False, str(exc), f"install the {DEFAULT_BINARIES[harness]} CLI or pass --harness-bin PATH"
            )
        ]
    steps = [CheckStep("binary", True, str(path))]
    steps.append(_version(path, env))
    if not steps[-1].ok:
        return steps
    sources = credential_sources(harness, env)
    if not sources and harness == "claude-code" and sys.platform == "darwin":
        sources = ["none in the environment or ~/.claude (the macOS keychain is not looked at; the probe will tell)"]
    steps.append(
        CheckStep(
            "credentials", bool(sources), ", ".join(sources) if sources else "no login found", _LOGIN_HINT[harness]
        )
    )
    if not steps[-1].ok:
        return steps
    steps.append(_probe(harness, path, task_dir, env, model, extra_args or [], probe_limit_s))
    return steps
