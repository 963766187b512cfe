"""Staging folders: built beside the result, hidden, and cleaned up after a killed process."""

from __future__ import annotations

import os
import subprocess
import sys

from aw.formats.io import pid_alive, staging_dir


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_a_staging_folder_is_hidden_and_named_after_its_process(tmp_path):
    stage = staging_dir(tmp_path / "out", "partial-suite")
    assert stage.parent == tmp_path / "out" and stage.is_dir()
    assert stage.name.startswith(f".partial-suite-{os.getpid()}-")


def test_folders_a_dead_process_left_are_removed_and_live_ones_kept(tmp_path):
    dead = _dead_pid()
    assert not pid_alive(dead) and pid_alive(os.getpid())
    left = tmp_path / f".partial-suite-{dead}-abc"
    (left / "tasks").mkdir(parents=True)
    live = staging_dir(tmp_path, "partial-suite")
    other = tmp_path / f".aw-staging-{dead}-abc"  # another name: not this caller's to clean
    other.mkdir()
    staging_dir(tmp_path, "partial-suite")
    assert not left.exists() and live.is_dir() and other.is_dir()
