"""Hostile JSON values that every reader's callers must refuse by name (tests of aw-serve, aw-run,
aw-score, aw-prepare and the readers beneath them use them): each :class:`Fragment` is JSON text
no writer of this project makes, and the piece of the one-line error it must produce."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class Fragment:
    name: str
    text: str  # JSON text put where a value belongs
    message: str  # a piece of the error it must produce


DEEP = Fragment("deep-3000", "[" * 3000 + "]" * 3000, "JSON nested deeper than 64 levels")
HUGE = Fragment(
    "integer-401-digits", "1" + "0" * 400, "not valid JSON: a number beyond the range of a double (+-1.8e308) at char "
)
NAN = Fragment("nan", "NaN", "(NaN and Infinity are not JSON numbers)")
DUPLICATE = Fragment("duplicate-key", '{"k": 1, "k": 2}', "duplicate key 'k'")
FRAGMENTS = [DEEP, HUGE, NAN, DUPLICATE]
IDS = [f.name for f in FRAGMENTS]

_PLACEHOLDER = "@HOSTILE@"


def inject(doc: Any, path: tuple[str | int, ...], fragment: Fragment) -> str:
    """``doc`` as JSON text with the value at ``path`` (keys and indices) replaced by the fragment."""
    doc = json.loads(json.dumps(doc))
    *parents, last = path
    holder = doc
    for key in parents:
        holder = holder[key]
    holder[last] = _PLACEHOLDER
    return json.dumps(doc).replace(json.dumps(_PLACEHOLDER), fragment.text, 1)


def inject_line(path: Path, number: int, fragment: Fragment) -> None:
    """Line ``number`` of a JSON-lines file (an object) gets one more key holding the fragment."""
    lines = path.read_text().split("\n")
    lines[number - 1] = lines[number - 1][:-1] + f', "extra": {fragment.text}' + "}"
    path.write_text("\n".join(lines))
