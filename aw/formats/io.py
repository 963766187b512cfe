"""Models read and written as JSON by the format modules (parsed by :mod:`aw.formats.strict_json`,
validated with pydantic), atomic writes, and bounded reading of what child processes write."""

from __future__ import annotations

import os
import shutil
import tempfile
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
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


def _named(exc: OSError, path: Path) -> OSError:
    """``exc`` naming ``path`` (a write error of a temporary file, or one without a file name)."""
    return OSError(exc.errno, exc.strerror or str(exc), str(path))


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path`` (same extension, so writers that read the format from it
    still do) for the block to write; renamed onto ``path`` when the block succeeds. The rename
    gives ``path`` a new file: a hard link to an older file (a staged copy) keeps the old bytes.
    On failure the temporary file is removed, and an ``OSError`` names ``path``."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}-{threading.get_ident()}{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise _named(exc, path) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text_atomic(path: str | Path, text: str) -> None:
    """:func:`write_bytes_atomic` of ``text`` in UTF-8."""
    write_bytes_atomic(path, text.encode("utf-8"))


def link_tree(src: Path, dst: Path, skip: Callable[[str], bool] = lambda _name: False) -> None:
    """``dst`` a copy of the folder ``src`` made of hard links (a real copy where the file system
    refuses them), without the files whose name ``skip`` accepts: a staged folder that starts
    as the published one at no cost. Write into it only through :func:`atomic_path`."""

    def link(s: str, d: str) -> None:
        try:
            os.link(s, d)
        except OSError:
            shutil.copy2(s, d)

    shutil.copytree(src, dst, copy_function=link, ignore=lambda _d, names: [n for n in names if skip(n)])


def publish_staged(stage: Path, dest: Path) -> list[Path]:
    """Move every entry of the folder ``stage`` onto the same name in ``dest``: a file by one
    rename (atomic), a folder by renaming the published one aside, the new one in, and removing
    the old. Returns the published paths. Call it with signals deferred (``aw.interrupts``)."""
    published = []
    for entry in sorted(p for p in stage.iterdir() if not p.name.startswith(".published-")):
        target = dest / entry.name
        if entry.is_dir() and not entry.is_symlink():
            old = stage / f".published-{entry.name}"  # removed with the stage, or by the next staging_dir
            if target.exists():
                os.replace(target, old)
            os.replace(entry, target)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(entry, target)
        published.append(target)
    return published
