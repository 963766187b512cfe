"""Strict JSON for the official files (run logs, packages, archives): one rule for what a file may
hold, so that a hostile file is a named error naming the file, never a traceback.

A document must be strict JSON (``NaN`` and ``Infinity`` are not numbers in JSON and would make
the official ``metrics.jsonl`` invalid), nest at most :data:`MAX_DEPTH` arrays/objects deep
(``json`` raises ``RecursionError`` near 1000 levels and ``orjson`` writes at most 254, so a
deeper value cannot be written back), and a run-log file is at most :data:`MAX_FILE_BYTES`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import orjson

from aw.formats import FormatError

__all__ = ["MAX_DEPTH", "MAX_FILE_BYTES", "nested_deeper", "parse", "read_json", "read_json_object"]

MAX_DEPTH = 64  # arrays/objects inside each other; official records nest at most 5 deep
MAX_FILE_BYTES = 64 << 20  # one run.json / input.json / result.json / package JSON file


def nested_deeper(value: Any, limit: int = MAX_DEPTH) -> bool:
    """Whether arrays/objects in ``value`` nest deeper than ``limit`` (without recursion)."""
    stack = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        children = item.values() if isinstance(item, dict) else item if isinstance(item, list) else None
        if children is None:
            continue
        if depth > limit:
            return True
        stack.extend((c, depth + 1) for c in children if isinstance(c, (dict, list)))
    return False


def parse(data: bytes | str, max_depth: int = MAX_DEPTH) -> Any:
    """Parse strict JSON; ``ValueError`` says why a document is refused."""
    try:
        value = orjson.loads(data)
    except orjson.JSONDecodeError as exc:
        text = exc.doc[exc.pos : exc.pos + 9] if isinstance(exc.doc, str) else ""
        word = next((w for w in ("NaN", "Infinity", "-Infinity") if text.startswith(w)), None)
        if word is not None:
            raise ValueError(
                f"not valid JSON: {word} at char {exc.pos} (NaN and Infinity are not JSON numbers)"
            ) from None
        raise ValueError(f"not valid JSON ({exc})") from None
    if nested_deeper(value, max_depth):
        raise ValueError(f"JSON nested deeper than {max_depth} levels")
    return value


def read_json(path: str | Path, error: type[FormatError] = FormatError, max_bytes: int = MAX_FILE_BYTES) -> Any:
    """A JSON file by the module's rule; ``error(path, problem)`` for a missing, oversized or
    refused file."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > max_bytes:
            raise error(path, f"{size} bytes, over the limit of {max_bytes} for a JSON file")
        data = path.read_bytes()
    except FileNotFoundError:
        raise error(path, "file not found") from None
    except OSError as exc:
        raise error(path, f"cannot be read ({exc.strerror or exc})") from None
    try:
        return parse(data)
    except ValueError as exc:
        raise error(path, str(exc)) from None


def read_json_object(path: str | Path, error: type[FormatError] = FormatError) -> dict[str, Any]:
    value = read_json(path, error)
    if not isinstance(value, dict):
        raise error(path, f"expected a JSON object, got {type(value).__name__}")
    return value
