"""The one JSON reader: every file the project reads (suites, recordings, initial poses, run
logs, official packages and archives, refiner results, harness transcripts) is parsed here, by
one rule and within one set of named limits, so that a hostile file is a one-line error naming
the file and the problem, never a traceback or a value that a later stage cannot use.

The rule: UTF-8 JSON (RFC 8259) with no ``NaN``/``Infinity`` literals (they are not JSON, and
would make the official ``metrics.jsonl`` invalid), no duplicate keys (a duplicate part id would
otherwise silently replace the first), and numbers that a double holds (``10**400`` is refused;
an integer beyond 64 bits reads as the nearest double). The limits (:class:`JsonLimits`):

- ``max_depth``: arrays/objects nested inside each other (the records nest at most 5 deep;
  Python's ``json`` raises ``RecursionError`` near 1000 and ``orjson`` writes at most 254);
- ``max_string_chars``: one string (a key or a value);
- ``max_document_bytes``: one JSON file, or one line of a JSON-lines file;
- ``max_file_bytes``: a JSON-lines file as a whole.

Files are read in bounded pieces: a file or a line over its limit is refused before it is read
whole.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import orjson

from aw.formats.errors import FormatError

__all__ = [
    "LIMITS",
    "MAX_DEPTH",
    "JsonError",
    "JsonLimits",
    "iter_lines",
    "open_bounded",
    "parse_json",
    "read_json",
    "read_json_lines",
    "read_json_object",
]

MAX_DEPTH = 64


@dataclass(frozen=True)
class JsonLimits:
    """What the reader accepts; a caller with other needs passes its own (e.g. an official
    archive's rows: ``JsonLimits(max_document_bytes=4 << 20)``)."""

    max_depth: int = MAX_DEPTH
    max_string_chars: int = 16 << 20
    max_document_bytes: int = 64 << 20
    max_file_bytes: int = 1 << 30

    def __post_init__(self) -> None:
        # orjson refuses nesting beyond 1024 itself; 254 keeps every accepted value writable
        # and the duplicate-key search below (Python's json, recursive) far from its limit.
        if not 1 <= self.max_depth <= 254:
            raise ValueError(f"max_depth must be within 1..254, got {self.max_depth}")


LIMITS = JsonLimits()

ErrorFactory = Callable[[Path, str], Exception]


class JsonError(ValueError):
    """A document refused by the rule or a limit; the message names the problem in one line."""


def parse_json(data: bytes | str, limits: JsonLimits = LIMITS) -> Any:
    """Parse strict JSON within ``limits``; :class:`JsonError` says why a document is refused."""
    if len(data) > limits.max_document_bytes:
        raise JsonError(f"{len(data)} bytes, over the limit of {limits.max_document_bytes} for a JSON document")
    try:
        value = orjson.loads(data)
    except orjson.JSONDecodeError as exc:
        raise JsonError(_decode_problem(data, exc, limits)) from None
    members, colons_in_strings = _check_tree(value, limits)
    if _colons(data) != members + colons_in_strings or _may_escape_colon(data):
        _find_duplicate_key(data)
    return value


def _decode_problem(data: bytes | str, exc: orjson.JSONDecodeError, limits: JsonLimits) -> str:
    message = str(exc)
    if isinstance(data, bytes) and message.startswith("str is not valid UTF-8"):
        try:
            data.decode("utf-8")
        except UnicodeDecodeError as bad:
            return f"not valid JSON: not UTF-8 text (byte {bad.start})"
    if message.startswith("depth limit exceeded"):
        return f"JSON nested deeper than {limits.max_depth} levels"
    if message.startswith("number is infinity when parsed as double"):
        return f"not valid JSON: a number beyond the range of a double (+-1.8e308) at char {exc.pos}"
    text = exc.doc[exc.pos : exc.pos + 9] if isinstance(exc.doc, str) else ""
    word = next((w for w in ("NaN", "Infinity") if text.startswith(w)), None)
    if word is not None:
        return f"not valid JSON: {word} at char {exc.pos} (NaN and Infinity are not JSON numbers)"
    return f"not valid JSON ({message})"


def _check_tree(value: Any, limits: JsonLimits) -> tuple[int, int]:
    """Check depth and string lengths without recursion; return the number of object members
    and of ``:`` characters inside strings (keys and values)."""
    if isinstance(value, str):
        return 0, _check_string(value, limits)
    members = colons = 0
    stack: list[tuple[Any, int]] = [(value, 1)] if isinstance(value, (dict, list)) else []
    while stack:
        item, depth = stack.pop()
        if depth > limits.max_depth:
            raise JsonError(f"JSON nested deeper than {limits.max_depth} levels")
        if isinstance(item, dict):
            members += len(item)
            for key, child in item.items():
                colons += _check_string(key, limits)
                if isinstance(child, (dict, list)):
                    stack.append((child, depth + 1))
                elif isinstance(child, str):
                    colons += _check_string(child, limits, key)
        else:  # a list
            for child in item:
                if isinstance(child, (dict, list)):
                    stack.append((child, depth + 1))
                elif isinstance(child, str):
                    colons += _check_string(child, limits)
    return members, colons


def _check_string(text: str, limits: JsonLimits, key: str | None = None) -> int:
    if len(text) > limits.max_string_chars:
        where = "" if key is None else f"{_short(key)}: "
        raise JsonError(f"{where}a string of {len(text)} characters, over the limit of {limits.max_string_chars}")
    return text.count(":")


def _short(key: str) -> str:
    return repr(key if len(key) <= 40 else key[:37] + "...")


# Duplicate keys. orjson keeps the last of duplicate keys, so they are found by counting: in
# valid JSON every ``:`` outside a string separates one object member, so the text holds exactly
# (members kept + colons inside the kept strings) colons, and more when a member was dropped.
# A colon written as an escape (``\u003a``) would break the count: such a text, and any that
# fails it, is parsed again by Python's json, which names the duplicate key.


def _colons(data: bytes | str) -> int:
    return data.count(b":") if isinstance(data, bytes) else data.count(":")


def _may_escape_colon(data: bytes | str) -> bool:
    if isinstance(data, bytes):
        return b"\\u003a" in data or b"\\u003A" in data
    return "\\u003a" in data or "\\u003A" in data


class _DuplicateKey(Exception):
    pass


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKey(key)
        out[key] = value
    return out


def _find_duplicate_key(data: bytes | str) -> None:
    try:
        json.loads(data, object_pairs_hook=_no_duplicates)  # depth already checked: no recursion limit near
    except _DuplicateKey as exc:
        raise JsonError(f"duplicate key {_short(exc.args[0])}") from None


# --- files ---------------------------------------------------------------------------------------


def open_bounded(path: Path, max_bytes: int, error: ErrorFactory = FormatError, what: str = "a JSON file") -> IO[bytes]:
    """``path`` opened for reading, refused by ``error(path, problem)`` when it is missing, not a
    file, unreadable or (by its size on disk) over ``max_bytes``."""
    try:
        fh = open(path, "rb")  # the caller closes it
    except FileNotFoundError:
        raise error(path, "file not found") from None
    except IsADirectoryError:
        raise error(path, "is a directory, not a file") from None
    except OSError as exc:
        raise error(path, f"cannot be read ({exc.strerror or exc})") from None
    size = os.fstat(fh.fileno()).st_size
    if size > max_bytes:
        fh.close()
        raise error(path, f"{size} bytes, over the limit of {max_bytes} for {what}")
    return fh


def read_json(path: str | Path, *, limits: JsonLimits = LIMITS, error: ErrorFactory = FormatError) -> Any:
    """A JSON file by the module's rule; ``error(path, problem)`` (a :class:`FormatError` unless
    the caller names its own kind) for a missing, oversized or refused file."""
    path = Path(path)
    with open_bounded(path, limits.max_document_bytes, error) as fh:
        try:
            data = fh.read(limits.max_document_bytes + 1)  # a file that grows, or a pipe, stops here
        except OSError as exc:
            raise error(path, f"cannot be read ({exc.strerror or exc})") from None
    if len(data) > limits.max_document_bytes:
        raise error(path, f"over the limit of {limits.max_document_bytes} bytes for a JSON file")
    try:
        return parse_json(data, limits)
    except JsonError as exc:
        raise error(path, str(exc)) from None


def read_json_object(
    path: str | Path, *, limits: JsonLimits = LIMITS, error: ErrorFactory = FormatError
) -> dict[str, Any]:
    """A JSON file that must hold an object."""
    value = read_json(path, limits=limits, error=error)
    if not isinstance(value, dict):
        raise error(Path(path), f"expected a JSON object, got {_kind(value)}")
    return value


def _kind(value: Any) -> str:
    return {dict: "an object", list: "an array", str: "a string", bool: "a boolean"}.get(
        type(value), "null" if value is None else "a number"
    )


def iter_lines(fh: IO[bytes], max_line_bytes: int) -> Iterator[tuple[int, bytes | None]]:
    """``(line number from 1, line)`` for each line of ``fh``, the line with its ``\\n`` when it
    has one; a line longer than ``max_line_bytes`` is skipped unread (``None``)."""
    number = 0
    while True:
        line = fh.readline(max_line_bytes + 1)
        if not line:
            return
        number += 1
        if len(line) > max_line_bytes and not line.endswith(b"\n"):
            while line and not line.endswith(b"\n"):  # the rest of the line, in bounded pieces
                line = fh.readline(1 << 20)
            yield number, None
        else:
            yield number, line


def read_json_lines(
    path: str | Path, *, limits: JsonLimits = LIMITS, error: ErrorFactory = FormatError
) -> Iterator[tuple[int, Any]]:
    """``(line number, value)`` for each non-blank line of a JSON-lines file; ``error(path,
    "line N: problem")`` for the first line refused."""
    path = Path(path)
    with open_bounded(path, limits.max_file_bytes, error, "a JSON-lines file") as fh:
        for number, line in iter_lines(fh, limits.max_document_bytes):
            if line is None:
                raise error(path, f"line {number}: over the limit of {limits.max_document_bytes} bytes for one line")
            if not line.strip():
                continue
            try:
                yield number, parse_json(line.rstrip(b"\n"), limits)
            except JsonError as exc:
                raise error(path, f"line {number}: {exc}") from None
