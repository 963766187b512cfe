"""The official runner's run-log tree: read it, merge resumed chains, and write it.

Layout (``assembly_world_bench/runs.py`` of AssemblyWorld/assembly-world-bench)::

    LOGS/<run id>/run.json
    LOGS/<run id>/blocks/<block>/samples/<slug>/input.json         the sample's frozen inputs
    LOGS/<run id>/blocks/<block>/samples/<slug>/result.json        pending, running, completed, failed
    LOGS/<run id>/blocks/<block>/samples/<slug>/prompt.txt
    LOGS/<run id>/blocks/<block>/samples/<slug>/conversation.jsonl
    LOGS/<run id>/blocks/<block>/samples/<slug>/final.episode.zip  when the episode was exported

A sample is named by the pair (block, sample id): the two PartNet blocks hold the same ids, so a
sample id alone is ambiguous. The slug is the id with every ``/`` written ``--``
(``Chair/reidar`` -> ``Chair--reidar``). ``run.json``'s ``source_run`` links a resumed run to
the run it continues; :func:`select_attempts` merges such chains the way the official
evaluation does (``selected_attempts`` in ``scoring.py``): ancestors first, the latest attempt
of a sample wins even when it failed, pending samples are not attempts, and the same sample in
two unrelated runs or in two sibling resumes is refused.
"""

from __future__ import annotations

import hashlib
import json
import re
import uuid
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from aw.formats import FormatError
from aw.formats.strict_json import read_json_lines, read_json_object
from aw.official.evaluation_cache import write_json
from aw.official.ids import sample_slug

__all__ = [
    "RUN_KIND",
    "RUN_FILE",
    "FINAL_ARCHIVE",
    "RunLog",
    "SampleAttempt",
    "sample_slug",
    "new_run_id",
    "utc_now",
    "read_run",
    "is_run_dir",
    "find_runs",
    "read_attempts",
    "select_attempts",
    "count_tool_calls",
    "chain_root",
    "system_name",
    "systems",
    "archive_system",
    "write_json",
    "create_run",
    "write_result",
]

RUN_KIND = "assembly-world-bench"
RUN_FILE = "run.json"
FINAL_ARCHIVE = "final.episode.zip"


def utc_now() -> str:
    """ISO-8601 UTC time with microseconds, as the runner stamps run and sample files."""
    return datetime.now(UTC).isoformat(timespec="microseconds")


def new_run_id() -> str:
    """A run folder name like the runner's: ``2026-01-02T030405.123456+0000-1a2b3c4d``."""
    return utc_now().replace(":", "") + "-" + uuid.uuid4().hex[:8]


# --- reading -----------------------------------------------------------------------------------


def _json_object(path: Path) -> dict[str, Any]:
    return read_json_object(path)


def _objects(file: Path, meta: dict[str, Any], keys: tuple[str, ...]) -> None:
    for key in keys:
        if meta.get(key) is not None and not isinstance(meta[key], dict):
            raise FormatError(file, f"{key}: expected an object, got {type(meta[key]).__name__}")


def _check_result(file: Path, result: dict[str, Any]) -> None:
    """The parts of ``result.json`` that go into the evaluation rows: objects where objects are
    read, numbers (or null) where means are taken."""
    _objects(file, result, ("archive", "execution"))
    execution = result.get("execution") or {}
    _objects(file, execution, ("usage",))
    numbers = {
        "duration_seconds": result.get("duration_seconds"),
        "tool_calls": result.get("tool_calls"),
        "execution.cost_usd": execution.get("cost_usd"),
        **{f"execution.usage.{k}": v for k, v in (execution.get("usage") or {}).items() if k.endswith("_tokens")},
    }
    for key, value in numbers.items():
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise FormatError(file, f"{key}: expected a number or null, got {type(value).__name__}")


def _inside(run: Path, path: Path) -> Path:
    """``path`` when it (links followed) lies inside the run folder ``run``; links that leave
    the run log are refused, as the package reader refuses links that leave the package."""
    if not path.resolve().is_relative_to(run):
        raise FormatError(path, f"links outside the run log {run}")
    return path


@dataclass(frozen=True)
class RunLog:
    """One run folder: its resolved ``path`` and parsed ``run.json`` (``meta``)."""

    path: Path
    meta: dict[str, Any]

    @property
    def run_id(self) -> str:
        return self.path.name

    @property
    def status(self) -> str:
        return str(self.meta.get("status"))

    @property
    def source_run(self) -> Path | None:
        """The run this one resumes (absolute path in ``run.json``), or None."""
        src = self.meta.get("source_run")
        return Path(src).resolve() if src else None

    @property
    def selection(self) -> dict[str, list[str]]:
        """Block -> sample ids, in the run's block order."""
        return self.meta["selection"]

    @property
    def options(self) -> dict[str, Any]:
        return self.meta.get("options") or {}

    def sample_dir(self, block: str, sample_id: str) -> Path:
        return self.path / "blocks" / block / "samples" / sample_slug(sample_id)


def read_run(path: str | Path) -> RunLog:
    """Read and check ``<path>/run.json`` (kind ``assembly-world-bench``, version 1, a selection
    of block -> sample ids)."""
    root = Path(path).resolve()
    file = root / RUN_FILE
    meta = _json_object(file)
    if meta.get("kind") != RUN_KIND or meta.get("version") != 1:
        raise FormatError(
            file,
            f"not an official run log (kind {meta.get('kind')!r}, version {meta.get('version')!r}; "
            f"expected {RUN_KIND!r}, 1)",
        )
    selection = meta.get("selection")
    if not isinstance(selection, dict) or not all(
        isinstance(ids, list) and all(isinstance(s, str) for s in ids) for ids in selection.values()
    ):
        raise FormatError(file, "selection: expected an object of block -> list of sample ids")
    for ids in selection.values():
        for sid in ids:
            sample_slug(sid, f"{file}: selection")
    src = meta.get("source_run")
    if src is not None and not isinstance(src, str):
        raise FormatError(file, "source_run: expected a path or null")
    _objects(file, meta, ("options", "tasks", "reference_modes", "benchmark", "versions"))
    return RunLog(root, meta)


def is_run_dir(path: str | Path) -> bool:
    return (Path(path) / RUN_FILE).is_file()


def find_runs(path: str | Path) -> list[Path]:
    """``path`` itself when it is a run folder, else the run folders directly inside it
    (a ``logs/`` directory), sorted by name."""
    root = Path(path)
    if is_run_dir(root):
        return [root.resolve()]
    if not root.is_dir():
        raise FormatError(root, "run-log directory not found")
    runs = sorted(p.resolve() for p in root.iterdir() if is_run_dir(p))
    if not runs:
        raise FormatError(root, f"no run folder (with {RUN_FILE}) in this directory")
    return runs


@dataclass(frozen=True)
class SampleAttempt:
    """One sample of one run: where it lives and what its ``input.json`` and ``result.json`` say.
    ``root`` is the first run of the chain the run belongs to."""

    block: str
    sample_id: str
    run: Path
    root: Path
    directory: Path
    inputs: dict[str, Any]
    result: dict[str, Any]

    @property
    def slug(self) -> str:
        return self.directory.name

    @property
    def status(self) -> str:
        return str(self.result.get("status"))

    @property
    def finished(self) -> bool:
        """False while the attempt is ``running`` (its export may be missing or stale)."""
        return self.status != "running"

    @property
    def final_archive(self) -> Path:
        return self.directory / FINAL_ARCHIVE

    @property
    def archive_saved(self) -> bool:
        return (self.result.get("archive") or {}).get("status") == "saved" and self.final_archive.is_file()

    @property
    def saved_sha256(self) -> str | None:
        return (self.result.get("archive") or {}).get("sha256")

    @property
    def execution(self) -> dict[str, Any]:
        return self.result.get("execution") or {}

    @property
    def tool_calls(self) -> int | None:
        """``result.json``'s count when it has the key, else the ``tool_call`` rows of
        ``conversation.jsonl`` (None when that file is missing or unreadable)."""
        if "tool_calls" in self.result:
            return self.result["tool_calls"]
        return count_tool_calls(self.directory / "conversation.jsonl")


def count_tool_calls(path: str | Path) -> int | None:
    """The ``{"type": "tool_call"}`` rows of a ``conversation.jsonl`` (every MCP call, read-only
    and failed ones included), or None when the file is missing; a row that is not a JSON object
    (by the rule of :mod:`aw.formats.strict_json`) is a :class:`FormatError` naming the line."""
    file = Path(path)
    if not file.is_file():
        return None
    count = 0
    for n, row in read_json_lines(file):
        if not isinstance(row, dict):
            raise FormatError(file, f"line {n}: expected a JSON object")
        count += row.get("type") == "tool_call"
    return count


def read_attempts(run: RunLog, root: Path | None = None) -> list[SampleAttempt]:
    """Every selected sample of ``run`` (pending ones included), in selection order."""
    out = []
    for block, ids in run.selection.items():
        for sid in ids:
            directory = _inside(run.path, run.sample_dir(block, sid))
            for name in ("input.json", "result.json", "conversation.jsonl", FINAL_ARCHIVE):
                if (directory / name).is_symlink() or (directory / name).exists():
                    _inside(run.path, directory / name)
            inputs = _json_object(directory / "input.json")
            if inputs.get("sample_id") != sid or inputs.get("block") != block:
                raise FormatError(
                    directory / "input.json",
                    f"names {inputs.get('block')!r}/{inputs.get('sample_id')!r}, "
                    f"but the run selects it as {block!r}/{sid!r}",
                )
            result = _json_object(directory / "result.json")
            if not isinstance(result.get("status"), str):
                raise FormatError(directory / "result.json", "status: missing")
            _check_result(directory / "result.json", result)
            out.append(SampleAttempt(block, sid, run.path, root or run.path, directory, inputs, result))
    return out


def _chain(run: RunLog, cache: dict[Path, RunLog]) -> list[RunLog]:
    """``run`` and its ancestors, nearest first; a cycle in ``source_run`` is refused."""
    chain, seen = [run], {run.path}
    while chain[-1].source_run is not None:
        src = chain[-1].source_run
        if src in seen:
            raise FormatError(chain[-1].path / RUN_FILE, f"source_run: cycle through {src}")
        if src not in cache:
            cache[src] = read_run(src)
        chain.append(cache[src])
        seen.add(src)
    return chain


def chain_root(run: RunLog) -> RunLog:
    """The first run of ``run``'s resume chain (``run`` itself when it resumes nothing)."""
    return _chain(run, {})[-1]


def system_name(run: RunLog) -> str:
    """The system a chain of runs stands for: ``<agent>-<model>[-<effort>]`` from the options of
    the chain's first run (a resume keeps them), made file-safe, else that run's id."""
    opts = chain_root(run).options
    name = "-".join(str(opts[k]) for k in ("agent", "model", "effort") if opts.get(k))
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or chain_root(run).run_id


def archive_system(folder: str | Path) -> str:
    """The system of a plain folder of episode archives (no run log): the folder's name."""
    return Path(folder).resolve().name


def systems(runs: Iterable[str | Path | RunLog]) -> dict[str, list[RunLog]]:
    """Runs grouped by :func:`system_name`, in name order."""
    out: dict[str, list[RunLog]] = {}
    for r in runs:
        log = r if isinstance(r, RunLog) else read_run(r)
        out.setdefault(system_name(log), []).append(log)
    return dict(sorted(out.items()))


def select_attempts(runs: Iterable[str | Path | RunLog]) -> dict[tuple[str, str], SampleAttempt]:
    """The attempt that counts for every (block, sample id) of the given runs and their
    ancestors: a chain is read root first and a later run's attempt replaces an earlier one's
    (never the other way, even when the later one failed); pending samples are skipped. The same
    sample in runs of two different chains, or in two runs of which neither resumes the
    other, raises ValueError (``Duplicate sample in unrelated runs`` / ``Ambiguous sibling
    attempts``)."""
    cache: dict[Path, RunLog] = {}
    chains = []
    for r in runs:
        log = r if isinstance(r, RunLog) else read_run(r)
        cache.setdefault(log.path, log)
        chains.append(_chain(cache[log.path], cache))
    ancestors = {c[0].path: {x.path for x in c} for c in chains}
    for c in chains:
        for k, run in enumerate(c):
            ancestors.setdefault(run.path, {x.path for x in c[k:]})
    roots = {run.path: c[-1].path for c in chains for run in c}
    depth = {run.path: len(c) - 1 - k for c in chains for k, run in enumerate(c)}
    chosen: dict[tuple[str, str], SampleAttempt] = {}
    for path in sorted(depth, key=lambda p: (depth[p], str(p))):
        for attempt in read_attempts(cache[path], roots[path]):
            if attempt.status == "pending":
                continue
            key = (attempt.block, attempt.sample_id)
            previous = chosen.get(key)
            if previous is not None:
                if previous.root != attempt.root:
                    raise ValueError(f"Duplicate sample in unrelated runs: {key} in {previous.run} and {attempt.run}")
                if previous.run not in ancestors[path]:
                    raise ValueError(
                        f"Ambiguous sibling attempts: {key} in {previous.run} and {attempt.run} "
                        "(neither run resumes the other)"
                    )
            chosen[key] = attempt
    return chosen


# --- writing -----------------------------------------------------------------------------------


def create_run(
    logs_dir: str | Path,
    selection: Mapping[str, Sequence[str]],
    inputs: Mapping[tuple[str, str], Mapping[str, Any]],
    prompts: Mapping[str, str],
    reference_modes: Mapping[str, str],
    options: Mapping[str, Any] | None = None,
    *,
    protocol_text: str = "",
    source_run: str | Path | None = None,
    benchmark: Mapping[str, Any] | None = None,
    run_id: str | None = None,
    started_at: str | None = None,
    versions: Mapping[str, Any] | None = None,
) -> RunLog:
    """Create ``LOGS/<run id>/`` with ``run.json`` (status ``running``) and every selected
    sample's ``input.json``, ``result.json`` (``pending``), ``prompt.txt`` and an empty
    ``conversation.jsonl``, as the runner does before it executes anything.

    ``inputs[(block, sid)]`` is the sample's input record (the package's sample entry plus
    ``initial_path``, ``initial_calls``, ``identity``, ``reference``); ``block`` and
    ``sample_id`` are set here. ``prompts[block]`` is the block's task text; each sample's
    ``prompt.txt`` is that text, a newline and ``protocol_text``."""
    directory = Path(logs_dir).resolve() / (run_id or new_run_id())
    if directory.exists():
        raise FileExistsError(f"{directory}: run folder already exists")
    unknown = sorted(set(selection) - set(prompts))
    if unknown:
        raise ValueError(f"no task text for blocks {unknown}")
    directory.mkdir(parents=True)
    meta = {
        "version": 1,
        "kind": RUN_KIND,
        "status": "running",
        "started_at": started_at or utc_now(),
        "source_run": str(Path(source_run).resolve()) if source_run else None,
        "options": dict(options or {}),
        "selection": {b: list(ids) for b, ids in selection.items()},
        "benchmark": dict(benchmark or {"revision": None, "local": None}),
        "tasks": {b: prompts[b] for b in selection},
        "reference_modes": {b: reference_modes[b] for b in selection},
        "code_commit": None,
        "versions": dict(versions or {}),
    }
    write_json(directory / RUN_FILE, meta)
    log = RunLog(directory, meta)
    for block, ids in selection.items():
        for sid in ids:
            sample = log.sample_dir(block, sid)
            record = {k: v for k, v in inputs[(block, sid)].items() if k not in ("block", "sample_id")}
            write_json(sample / "input.json", {**record, "block": block, "sample_id": sid})
            write_json(sample / "result.json", {"status": "pending"})
            (sample / "prompt.txt").write_text(prompts[block] + "\n" + protocol_text, encoding="utf-8")
            (sample / "conversation.jsonl").touch()
    return log


def write_result(
    run: RunLog,
    block: str,
    sample_id: str,
    result: Mapping[str, Any],
    *,
    conversation: Iterable[Mapping[str, Any]] = (),
    final_archive: bytes | None = None,
    archive_calls: int | None = None,
) -> Path:
    """Record one sample's attempt: ``conversation.jsonl`` rows, ``final.episode.zip`` (then
    ``result.archive`` is ``{"status": "saved", "sha256", "calls"}``) and ``result.json``
    (``tool_calls`` counted from the conversation unless given). Returns the sample folder."""
    sample = run.sample_dir(block, sample_id)
    if not (sample / "input.json").is_file():
        raise FormatError(sample / "input.json", f"{block}/{sample_id} is not selected by this run")
    rows = [dict(r) for r in conversation]
    (sample / "conversation.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows), encoding="utf-8")
    record = dict(result)
    if final_archive is not None:
        (sample / FINAL_ARCHIVE).write_bytes(final_archive)
        record["archive"] = {
            "status": "saved",
            "sha256": hashlib.sha256(final_archive).hexdigest(),
            **({"calls": archive_calls} if archive_calls is not None else {}),
        }
    record.setdefault("archive", {"status": "not_saved"})
    record.setdefault("tool_calls", sum(r.get("type") == "tool_call" for r in rows))
    write_json(sample / "result.json", record)
    return sample
