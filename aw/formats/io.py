"""Models read and written as JSON by the format modules (parsed by :mod:`aw.formats.strict_json`,
validated with pydantic), atomic writes, and bounded reading of what child processes write."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import TypeVar, get_args

import orjson
from pydantic import BaseModel, ValidationError

from aw.formats.errors import FormatError
from aw.formats.strict_json import read_json

M = TypeVar("M", bound=BaseModel)

JSON_OPTIONS = orjson.OPT_INDENT_2 | orjson.OPT_SORT_KEYS | orjson.OPT_SERIALIZE_NUMPY


def describe_validation_error(exc: ValidationError) -> str:
    """One line per problem: ``field.path: message``."""
    lines = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"]) or "<root>"
        lines.append(f"{loc}: {err['msg']}")
    return "; ".join(lines)


def check_format_tag(model: type[BaseModel], data: object) -> str | None:
    """A clear message if ``data`` names another format or an unsupported version of ``model``'s."""
    fields = model.model_fields
    if not isinstance(data, dict) or "format" not in fields or "format_version" not in fields:
        return None
    expected = fields["format"].default
    supported = get_args(fields["format_version"].annotation)
    if "format" in data and data["format"] != expected:
        return f"format is {data['format']!r}, expected {expected!r}"
    if "format_version" in data and data["format_version"] not in supported:
        versions = ", ".join(str(v) for v in supported)
        return f"unsupported format_version {data['format_version']!r} (this reader knows {versions})"
    return None


def parse_model(model: type[M], data: object, path: str | Path) -> M:
    problem = check_format_tag(model, data)
    if problem:
        raise FormatError(path, problem)
    try:
        # Strict on read: a file must hold the right JSON types ("no" is not a boolean, "3" not
        # an integer); Python callers constructing models keep pydantic's usual coercions.
        return model.model_validate(data, strict=True)
    except ValidationError as exc:
        raise FormatError(path, describe_validation_error(exc)) from None


def read_model(model: type[M], path: str | Path) -> M:
    return parse_model(model, read_json(path), path)


def dump_json(obj: object) -> bytes:
    if isinstance(obj, BaseModel):
        obj = obj.model_dump(mode="json")
    return orjson.dumps(obj, option=JSON_OPTIONS) + b"\n"


def write_json_atomic(path: str | Path, obj: object) -> None:
    """Write JSON through a temporary file and rename, so readers never see half a file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        with open(tmp, "wb") as fh:
            fh.write(dump_json(obj))
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)  # a full disk leaves no half-written temporary behind
        raise


def pid_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists on this machine (one of another user's counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def staging_dir(parent: str | Path, name: str) -> Path:
    """A new hidden folder ``parent/.NAME-<pid>-<random>`` to build in before the result is moved
    into place (readers skip hidden folders). Folders of the same ``name`` that a killed process
    left are removed first."""
    parent = Path(parent)
    parent.mkdir(parents=True, exist_ok=True)
    prefix = f".{name}-"
    for old in parent.glob(prefix + "*"):
        pid = old.name[len(prefix) :].split("-")[0]
        if pid.isdigit() and not pid_alive(int(pid)):
            shutil.rmtree(old, ignore_errors=True)
    return Path(tempfile.mkdtemp(dir=parent, prefix=f"{prefix}{os.getpid()}-"))


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    """Write ``data`` through a temporary file and rename, so readers never see half a file. On
    failure (a full disk, an interrupt) no temporary file is left; an ``OSError`` names ``path``."""
    path = Path(path)
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise OSError(exc.errno, exc.strerror, str(path)) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def read_tail(path: str | Path, max_bytes: int = 64 << 10) -> str:
    """The last ``max_bytes`` of a file a child process wrote (its log or output), decoded with
    replacement; "" when it cannot be read. Memory stays bounded however large the file grew."""
    try:
        with open(path, "rb") as fh:
            fh.seek(max(0, os.fstat(fh.fileno()).st_size - max_bytes))
            data = fh.read(max_bytes)
    except OSError:
        return ""
    return data.decode("utf-8", errors="replace")


def last_line(path: str | Path, max_chars: int = 300) -> str:
    """The last non-blank line of a child's log (its own verdict, usually), at most ``max_chars``
    printable characters (a log padded with NUL bytes or escape codes shows its text)."""
    lines = ["".join(c for c in line if c.isprintable()).strip() for line in read_tail(path).splitlines()]
    lines = [line for line in lines if line]
    return lines[-1][:max_chars] if lines else ""
