"""Fixtures for runner tests: a tiny suite written with the format writers, and helpers."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from tiny_suite import make_tiny_suite  # noqa: E402


@pytest.fixture(scope="session")
def tiny_suite(tmp_path_factory) -> Path:
    return make_tiny_suite(tmp_path_factory.mktemp("tiny") / "suite")
