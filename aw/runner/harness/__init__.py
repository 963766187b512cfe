"""Adapters that run real agent harnesses (Claude Code, Codex) on AssemblyWorld tasks."""

from aw.runner.harness.base import HarnessAdapter, HarnessError, HarnessOptions, HarnessUsage, PreparedRun
from aw.runner.harness.claude_code import ClaudeCode
from aw.runner.harness.codex import Codex

HARNESSES: dict[str, HarnessAdapter] = {"claude-code": ClaudeCode(), "codex": Codex()}

__all__ = ["HARNESSES", "HarnessAdapter", "HarnessError", "HarnessOptions", "HarnessUsage", "PreparedRun"]
