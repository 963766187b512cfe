"""Fixtures for the aw-serve tests (task directories are written once per session)."""

from __future__ import annotations

from pathlib import Path

import pytest
from aw_server_helpers import make_task


@pytest.fixture(scope="session")
def suite_root(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("suite")


@pytest.fixture(scope="session")
def box_task(suite_root):
    """A no-reference task: (task_dir, targets_path, targets)."""
    return make_task(suite_root, "none", task_id="box3_none")


@pytest.fixture(scope="session")
def manual_task(suite_root):
    """A manual task with three reference pages."""
    return make_task(suite_root, "manual", task_id="box3_manual")


@pytest.fixture
def anyio_backend():
    return "asyncio"
