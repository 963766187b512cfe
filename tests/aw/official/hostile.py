"""Hostile official files: a good run log of one sample, made by this project's writers
(:mod:`tests.aw.official.builders`), then damaged in one targeted way per variant. Used by
``tests/aw/official/test_hostile_files.py`` and ``benchmarks/hostile_official.py``.

Each :class:`Variant` names what ``aw-score PKG RUNS`` and ``aw-prepare official`` must both
say about it (a piece of the one-line error, or of the sample's error row in ``metrics.jsonl``).
An archive damaged on purpose gets its new SHA-256 in ``result.json``, so the damage reaches the
archive reader rather than the checksum comparison.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from aw.official.archive import archive_bytes, read_archive
from tests.aw.official.builders import FINAL, write_run_log

SAMPLE = ("partnet-none", "743")
RUN_ID = "run-1"


@dataclass(frozen=True)
class Variant:
    name: str
    damage: Callable[[Path, Path], None]  # (run folder, scratch folder outside the run log)
    message: str  # what both commands must say
    archive: bool  # True: the sample's archive is bad (aw-score: an error row), else the run log (a refusal)


def good_run(pkg, logs: Path) -> Path:
    return write_run_log(logs, pkg, {SAMPLE: FINAL}, RUN_ID)


def sample_dir(run: Path) -> Path:
    return run / "blocks" / SAMPLE[0] / "samples" / SAMPLE[1]


def _final(run: Path) -> Path:
    return sample_dir(run) / "final.episode.zip"


def _edit_json(path: Path, edit: Callable[[dict], None], raw: dict[str, str] | None = None) -> None:
    """Edit a JSON file; ``raw`` maps placeholder strings to JSON text written in their place
    (values no JSON writer makes: NaN, 100,000-deep arrays)."""
    value = json.loads(path.read_text())
    edit(value)
    text = json.dumps(value)
    for placeholder, replacement in (raw or {}).items():
        text = text.replace(json.dumps(placeholder), replacement)
    path.write_text(text)


def _rehash_result(run: Path) -> None:
    result = sample_dir(run) / "result.json"
    digest = hashlib.sha256(_final(run).read_bytes()).hexdigest()
    _edit_json(result, lambda r: r["archive"].update(sha256=digest))


def _members(path: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(path) as zf:
        return {i.filename: zf.read(i) for i in zf.infolist()}


def _rezip(path: Path, files: dict[str, bytes]) -> None:
    """Write ``files`` back with manifest hashes that match, so the damage reaches the records."""
    manifest = json.loads(files["manifest.json"])
    manifest["hashes"] = {n: hashlib.sha256(d).hexdigest() for n, d in files.items() if n != "manifest.json"}
    files = {**files, "manifest.json": json.dumps(manifest).encode()}
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, data in files.items():
            zf.writestr(name, data)


def _edit_member_rows(run: Path, member: str, edit: Callable[[list[str]], None]) -> None:
    path = _final(run)
    files = _members(path)
    rows = files[member].decode().split("\n")
    edit(rows)
    files[member] = "\n".join(rows).encode()
    _rezip(path, files)
    _rehash_result(run)


def _edit_row(member: str, line: int, edit: Callable[[dict], None], raw: dict[str, str] | None = None):
    def damage(run: Path, scratch: Path) -> None:
        def change(rows: list[str]) -> None:
            row = json.loads(rows[line])
            edit(row)
            text = json.dumps(row)
            for placeholder, replacement in (raw or {}).items():
                text = text.replace(json.dumps(placeholder), replacement)
            rows[line] = text

        _edit_member_rows(run, member, change)

    return damage


def _state_value(offset: int, value: float):
    """Set one number of the final state's vector (mjSTATE_INTEGRATION: time, then each free
    body's position and quaternion), written by the project's archive writer."""

    def damage(run: Path, scratch: Path) -> None:
        ep = read_archive(_final(run))
        ep.states[-1].integration[offset] = value
        _final(run).write_bytes(archive_bytes(ep))
        _rehash_result(run)

    return damage


def _zero_quaternion(run: Path, scratch: Path) -> None:
    ep = read_archive(_final(run))
    ep.states[-1].integration[4:8] = 0.0  # part-0001's quaternion
    _final(run).write_bytes(archive_bytes(ep))
    _rehash_result(run)


def _corrupt_deflate(run: Path, scratch: Path) -> None:
    """Overwrite frames.jsonl's compressed bytes with 0xFF (an invalid DEFLATE block type)."""
    path = _final(run)
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo("frames.jsonl")
    name_len = int.from_bytes(data[info.header_offset + 26 : info.header_offset + 28], "little")
    extra_len = int.from_bytes(data[info.header_offset + 28 : info.header_offset + 30], "little")
    start = info.header_offset + 30 + name_len + extra_len
    data[start : start + info.compress_size] = b"\xff" * info.compress_size
    path.write_bytes(bytes(data))
    _rehash_result(run)


def _link_outside(run: Path, scratch: Path) -> None:
    """final.episode.zip becomes a link to a (good) copy outside the run log."""
    outside = scratch / "elsewhere.episode.zip"
    shutil.copyfile(_final(run), outside)
    _final(run).unlink()
    _final(run).symlink_to(outside)


def _sample_dir_outside(run: Path, scratch: Path) -> None:
    outside = scratch / "elsewhere-sample"
    shutil.copytree(sample_dir(run), outside)
    shutil.rmtree(sample_dir(run))
    sample_dir(run).symlink_to(outside, target_is_directory=True)


def _deep(depth: int) -> str:
    return "[" * depth + "]" * depth


def _json_file(name: str, edit: Callable[[dict], None], raw: dict[str, str] | None = None, in_sample: bool = True):
    def damage(run: Path, scratch: Path) -> None:
        _edit_json((sample_dir(run) if in_sample else run) / name, edit, raw)

    return damage


def _conversation(text: str):
    def damage(run: Path, scratch: Path) -> None:
        _edit_json(sample_dir(run) / "result.json", lambda r: r.pop("tool_calls"))  # counted from the conversation
        (sample_dir(run) / "conversation.jsonl").write_text(text + "\n")

    return damage


def _set(**values):
    def edit(obj: dict) -> None:
        obj.update(values)

    return edit


def _set_in(key: str, **values):
    def edit(obj: dict) -> None:
        obj[key].update(values)

    return edit


VARIANTS = [
    # the sample's final archive
    Variant("corrupt-deflate", _corrupt_deflate, "member 'frames.jsonl' cannot be inflated", True),
    Variant("frame-kind-list", _edit_row("frames.jsonl", -1, _set(kind=["state"])), "kind ['state']", True),
    Variant("event-call-id-list", _edit_row("events.jsonl", 0, _set(call_id=["call-0"])), "events.jsonl: line 1", True),
    Variant("zero-quaternion", _zero_quaternion, "quaternion has zero length", True),
    Variant("position-1e300", _state_value(1, 1e300), "holds a value beyond +-1e+09", True),
    Variant("position-1e8", _state_value(1, 1e8), "position beyond +-1e+06", True),
    Variant(
        "arguments-1000-deep",
        _edit_row("calls.jsonl", 0, _set(arguments={"x": "@DEEP@"}), {"@DEEP@": _deep(1000)}),
        "nested deeper than 64 levels",
        True,
    ),
    Variant(
        "arguments-duplicate-key",
        _edit_row("calls.jsonl", 0, _set(arguments="@DUP@"), {"@DUP@": '{"x": 1, "x": 2}'}),
        "calls.jsonl: line 1: duplicate key 'x'",
        True,
    ),
    Variant(
        "arguments-5MB-array",
        _edit_row("calls.jsonl", 0, _set(arguments={"x": "@BIG@"}), {"@BIG@": "[" + "0.0," * 1_300_000 + "0.0]"}),
        "over the limit of 4194304 per row",
        True,
    ),
    # the run log
    Variant("final-archive-links-outside", _link_outside, "links outside the run log", False),
    Variant("sample-folder-links-outside", _sample_dir_outside, "links outside the run log", False),
    Variant(
        "run-json-100000-deep",
        _json_file("run.json", _set(versions="@DEEP@"), {"@DEEP@": _deep(100_000)}, False),
        "run.json: JSON nested deeper than 64 levels",
        False,
    ),
    Variant(
        "result-json-100000-deep",
        _json_file("result.json", _set(extra="@DEEP@"), {"@DEEP@": _deep(100_000)}),
        "result.json: JSON nested deeper than 64 levels",
        False,
    ),
    Variant(
        "input-json-100000-deep",
        _json_file("input.json", _set(extra="@DEEP@"), {"@DEEP@": _deep(100_000)}),
        "input.json: JSON nested deeper than 64 levels",
        False,
    ),
    Variant(
        "conversation-100000-deep",
        _conversation(_deep(100_000)),
        "conversation.jsonl: line 1: JSON nested deeper than 64 levels",
        False,
    ),
    Variant(
        "conversation-not-objects", _conversation("[1, 2]"), "conversation.jsonl: line 1: expected a JSON object", False
    ),
    Variant(
        "result-nan",
        _json_file("result.json", _set(duration_seconds="@NAN@"), {"@NAN@": "NaN"}),
        "NaN and Infinity are not JSON numbers",
        False,
    ),
    Variant(
        "result-infinity",
        _json_file("result.json", _set_in("execution", cost_usd="@INF@"), {"@INF@": "Infinity"}),
        "NaN and Infinity are not JSON numbers",
        False,
    ),
    Variant(
        "run-json-duplicate-key",
        _json_file("run.json", _set(versions="@DUP@"), {"@DUP@": '{"k": 1, "k": 2}'}, False),
        "run.json: duplicate key 'k'",
        False,
    ),
    Variant(
        "result-integer-401-digits",
        _json_file("result.json", _set(duration_seconds="@BIG@"), {"@BIG@": "1" + "0" * 400}),
        "result.json: not valid JSON: a number beyond the range of a double (+-1.8e308)",
        False,
    ),
    Variant(
        "result-status-list",
        _json_file("result.json", _set(status=["completed"])),
        "result.json: status: missing",
        False,
    ),
    Variant(
        "result-archive-list", _json_file("result.json", _set(archive=["saved"])), "archive: expected an object", False
    ),
    Variant(
        "result-execution-string",
        _json_file("result.json", _set(execution="completed")),
        "execution: expected an object",
        False,
    ),
    Variant(
        "result-tool-calls-string",
        _json_file("result.json", _set(tool_calls="many")),
        "tool_calls: expected a number or null",
        False,
    ),
    Variant(
        "run-options-list",
        _json_file("run.json", _set(options=["codex"]), in_sample=False),
        "options: expected an object",
        False,
    ),
    Variant(
        "run-tasks-list",
        _json_file("run.json", _set(tasks=["Assemble."]), in_sample=False),
        "tasks: expected an object",
        False,
    ),
]
