"""The harness check (``aw-run --check`` and before a harness batch), the harness binary resolved
up front, and aw-run's exit status when no episode finished. Driven through the stand-in harness
(``fake_harness.py``), which starts the real ``aw-serve`` over stdio with the MCP SDK client."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from aw.runner.check import check_harness, credential_sources, find_binary

FAKE = Path(__file__).with_name("fake_harness.py")


@pytest.fixture
def fake_bin(tmp_path) -> Path:
    path = tmp_path / "bin" / "fake-harness"
    path.parent.mkdir()
    path.write_text(f'#!/bin/sh\nexec {sys.executable} {FAKE} "$@"\n')
    path.chmod(0o755)
    return path


def _env(tmp_path: Path, **extra: str) -> dict[str, str]:
    """Our environment with a HOME of its own (no login files) and no API keys, plus ``extra``."""
    env = {
        k: v
        for k, v in os.environ.items()
        if k
        not in (
            "ANTHROPIC_API_KEY",
            "ANTHROPIC_AUTH_TOKEN",
            "CLAUDE_CODE_OAUTH_TOKEN",
            "CLAUDE_CODE_USE_BEDROCK",
            "CLAUDE_CODE_USE_VERTEX",
            "OPENAI_API_KEY",
            "CODEX_API_KEY",
            "CLAUDE_CONFIG_DIR",
            "CODEX_HOME",
        )
    }
    env["HOME"] = str(tmp_path / "home")
    env.update(extra)
    return env


def _aw_run(args: list[str], env: dict[str, str], cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "aw.runner.cli", *args], capture_output=True, text=True, env=env, cwd=cwd, timeout=300
    )


@pytest.mark.parametrize("harness, key", [("claude-code", "ANTHROPIC_API_KEY"), ("codex", "OPENAI_API_KEY")])
def test_check_passes_when_the_harness_lists_the_tools(harness, key, tiny_suite, tmp_path, fake_bin):
    env = _env(tmp_path, **{key: "set-for-the-test"})
    steps = check_harness(harness, str(fake_bin), tiny_suite / "tasks" / "tiny_table_none", env=env)
    assert [s.name for s in steps] == ["binary", "version", "credentials", "probe"]
    assert all(s.ok for s in steps), [s.line() for s in steps]
    assert "0.0-fake" in steps[1].detail and key in steps[2].detail


def test_check_stops_at_the_first_failure_with_what_to_do(tiny_suite, tmp_path, fake_bin):
    task = tiny_suite / "tasks" / "tiny_table_none"
    steps = check_harness("claude-code", str(tmp_path / "nope"), task, env=_env(tmp_path))
    assert [(s.name, s.ok) for s in steps] == [("binary", False)] and "no such file" in steps[0].detail
    steps = check_harness("claude-code", str(fake_bin), task, env=_env(tmp_path))
    assert [(s.name, s.ok) for s in steps][-1] == ("credentials", False)
    assert "ANTHROPIC_API_KEY" in steps[-1].fix
    # A login file counts as credentials (its contents are never read).
    login = tmp_path / "home" / ".codex" / "auth.json"
    login.parent.mkdir(parents=True)
    login.write_text("{}")
    assert credential_sources("codex", _env(tmp_path)) == [str(login)]
    # Logged out: the probe session reports it, and the fix says how to log in.
    steps = check_harness(
        "claude-code", str(fake_bin), task, env=_env(tmp_path, ANTHROPIC_API_KEY="x", FAKE_HARNESS_MODE="nologin")
    )
    assert steps[-1].name == "probe" and not steps[-1].ok
    assert "Not logged in" in steps[-1].detail and "login" in steps[-1].fix
    assert "ended with success" not in steps[-1].detail


def test_a_harness_that_never_answers_fails_the_probe_at_its_limit(tiny_suite, tmp_path, fake_bin):
    """Codex without network retries until its limit: the probe's own, short limit catches it."""
    env = _env(tmp_path, OPENAI_API_KEY="x")
    sleeper = tmp_path / "bin" / "sleeper"
    sleeper.write_text("#!/bin/sh\n[ \"$1\" = --version ] && { echo 'sleeper 1.0'; exit 0; }\nsleep 600\n")
    sleeper.chmod(0o755)
    steps = check_harness("codex", str(sleeper), tiny_suite / "tasks" / "tiny_table_none", env=env, probe_limit_s=3)
    assert steps[-1].name == "probe" and not steps[-1].ok and "no answer within 3 s" in steps[-1].detail


def test_find_binary_resolves_relative_paths_and_refuses_non_executables(tmp_path, fake_bin, monkeypatch):
    monkeypatch.chdir(fake_bin.parent)
    assert find_binary("codex", "./fake-harness") == fake_bin.resolve()
    assert find_binary("codex", "fake-harness") == fake_bin.resolve()  # a file here wins over PATH
    plain = tmp_path / "plain"
    plain.write_text("not a program")
    with pytest.raises(ValueError, match="not an executable"):
        find_binary("codex", str(plain))
    with pytest.raises(ValueError, match="not found"):
        find_binary("codex", "no-such-harness-anywhere")


def test_aw_run_check_alone_and_before_a_batch(tiny_suite, tmp_path, fake_bin):
    env = _env(tmp_path, ANTHROPIC_API_KEY="x")
    ok = _aw_run(
        [
            str(tiny_suite),
            "--harness",
            "claude-code",
            "--harness-bin",
            str(fake_bin),
            "--check",
            "--tasks",
            "tiny_table_none",
        ],
        env,
    )
    assert ok.returncode == 0, ok.stderr
    assert "ok   probe" in ok.stderr
    # Not logged in: the batch stops before its first episode with one line naming the fix.
    out = tmp_path / "runs"
    bad = _aw_run(
        [
            str(tiny_suite),
            "--harness",
            "claude-code",
            "--harness-bin",
            str(fake_bin),
            "--out",
            str(out),
            "--tasks",
            "tiny_table_none",
        ],
        {**env, "FAKE_HARNESS_MODE": "nologin"},
    )
    assert bad.returncode == 1
    last = bad.stderr.strip().splitlines()[-1]
    assert last.startswith("aw-run: error: claude-code is not ready (probe") and "login" in last
    assert not out.exists()


def test_aw_run_resolves_a_relative_harness_bin_and_exits_1_when_no_episode_finished(tiny_suite, tmp_path, fake_bin):
    env = _env(tmp_path, FAKE_HARNESS_MODE="fail")
    out = tmp_path / "runs"
    proc = _aw_run(
        [
            str(tiny_suite),
            "--harness",
            "codex",
            "--harness-bin",
            "bin/fake-harness",
            "--skip-check",
            "--out",
            str(out),
            "--tasks",
            "tiny_table_none",
            "--no-progress",
        ],
        env,
        cwd=tmp_path,
    )
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "no episode finished" in proc.stderr and "Traceback" not in proc.stderr
    assert (out / "codex" / "tiny_table_none" / "run.json").is_file()  # it ran: the relative path was found
    plain = tmp_path / "plain"
    plain.write_text("x")
    refused = _aw_run([str(tiny_suite), "--harness", "codex", "--harness-bin", str(plain), "--out", str(out)], env)
    assert refused.returncode == 2 and "not an executable" in refused.stderr
