"""JSON reading and writing shared by the format modules (orjson, validated with pydantic)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TypeVar

import orjson
from pydantic import BaseModel, ValidationError

from aw.formats.errors import FormatError

M = TypeVar("M", bound=BaseModel)

JSON_OPTIONS = orjson.OPT_INDENT_2 | orjson.OPT_SORT_KEYS | orjson.OPT_SERIALIZE_NUMPY


def describe_validation_error(exc: ValidationError) -> str:
    """One line per problem: ``field.path: message``."""
    lines = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"]) or "<root>"
        lines.append(f"{loc}: {err['msg']}")
    return "; ".join(lines)


def load_json(path: str | Path) -> object:
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise FormatError(path, "file not found") from None
    except OSError as exc:
        raise FormatError(path, f"cannot be read ({exc.strerror})") from None
    try:
        return orjson.loads(raw)
    except orjson.JSONDecodeError as exc:
        raise FormatError(path, f"not valid JSON ({exc})") from None


def parse_model(model: type[M], data: object, path: str | Path) -> M:
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise FormatError(path, describe_validation_error(exc)) from None


def read_model(model: type[M], path: str | Path) -> M:
    return parse_model(model, load_json(path), path)


def dump_json(obj: object) -> bytes:
    if isinstance(obj, BaseModel):
        obj = obj.model_dump(mode="json")
    return orjson.dumps(obj, option=JSON_OPTIONS) + b"\n"


def write_json_atomic(path: str | Path, obj: object) -> None:
    """Write JSON through a temporary file and rename, so readers never see half a file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    with open(tmp, "wb") as fh:
        fh.write(dump_json(obj))
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
