"""Fixtures for refiner tests: a small fracture suite written with the format writers."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from fracture_suite import make_fracture_suite  # noqa: E402


@pytest.fixture(scope="session")
def fracture_suite(tmp_path_factory) -> Path:
    return make_fracture_suite(tmp_path_factory.mktemp("fractures") / "suite")


@pytest.fixture(scope="session")
def break_suite(tmp_path_factory) -> Path:
    """Objects of the refiners' break families: two planar cuts, a 3-piece break, a rough break
    with scan noise, a planar cut with chipped rims, and two rough breaks of the seeded fracture
    block whose sides the segmentation cuts unlike each other."""
    objects = (
        ("breaks_planar/0", 0),
        ("breaks_planar/2", 0),
        ("breaks_pieces/0", 0),
        ("breaks_noisy/11", 0),
        ("breaks_eroded/10", 0),
        ("fantastic_breaks/8", 0),
        ("fantastic_breaks/14", 0),
    )
    return make_fracture_suite(tmp_path_factory.mktemp("breaks") / "suite", objects)
