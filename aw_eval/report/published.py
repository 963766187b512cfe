"""The paper's eight systems as published, beside a study's own rows in Table 1 and Table A-3.

The figures live in one data file, ``published.json`` beside this module, which names its
source (the paper's Table 1 and Table A-3). They are shown only when the suite is the official
benchmark (its 100 tasks, by the package's identity: :func:`aw.official.convert.official_benchmark_problem`),
marked "published, not rescored", never bolded and never in a paired test (no per-task data is
published). On any other suite the report says in one line why they are absent.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import Any

from aw.official.convert import official_benchmark_problem

__all__ = ["PUBLISHED_FILE", "MARK", "load_published", "published_section"]

PUBLISHED_FILE = Path(__file__).with_name("published.json")
MARK = "published, not rescored"


@functools.lru_cache(maxsize=1)
def load_published() -> dict[str, Any]:
    """The data file (see :data:`PUBLISHED_FILE`)."""
    return json.loads(PUBLISHED_FILE.read_text(encoding="utf-8"))


def published_section(suite_dir: str) -> dict[str, Any]:
    """``scores.json``'s ``published``: ``shown`` (bool), ``why`` (None when shown, else the reason
    in a phrase), the source, the cells ``[source, condition]`` and the systems' rows when shown."""
    data = load_published()
    why = official_benchmark_problem(suite_dir) if suite_dir else "no suite directory was given"
    return {
        "shown": why is None,
        "why": why,
        "source": data["source"],
        "benchmark": data["benchmark"],
        "mark": MARK,
        "cells": data["cells"] if why is None else [],
        "systems": data["systems"] if why is None else [],
    }
