"""The official evaluation's outputs: ``metrics.jsonl`` (one row per counted attempt) and
``summary.json`` (block, source and overall means), read, written and computed from rows.

Facts from ``assembly_world_bench/scoring.py`` of AssemblyWorld/assembly-world-bench
(``_score_job``, ``score_episode``, ``summarize``, ``evaluate``) and ``geometry.py``:

* a row starts with ``block, sample_id, run, duration_seconds, usage, cost_usd, tool_calls,
  attempt_finished``; a scored row goes on with ``status: "scored", SCD, PA, SR,
  protocol_version, episode_sha256, state_index, parts, alignment, scale_divisor``; an error
  row with ``status: "error", error: "<ExceptionType>: <message>", SCD: null, PA: 0.0, SR: 0,
  protocol_version``. SCD is 1000 x the aligned squared Chamfer, PA the fraction of parts within
  0.01, SR 1 when all are;
* rows are sorted by (block, sample id), one ``json.dumps`` line each;
* a block's SCD is the mean over its scored rows, its PA and SR the means over all its rows
  (errors count 0); a run is ``complete`` only when its rows are exactly the benchmark's
  (block, sample) pairs and every attempt finished, and only then are source means (each the
  mean of its blocks) and the overall means (the mean over sources) given: a partial run has
  ``official_overall: null`` and no ``sources``;
* resources (duration, cost, tool calls) and token counts (usage keys ending ``_tokens``) are
  means over the rows that report them.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from aw.formats import FormatError
from aw.formats.strict_json import read_json, read_json_lines
from aw.official.runlog import SampleAttempt, write_json

__all__ = [
    "PROTOCOL",
    "EXPECTED_TOTAL",
    "METRICS_FILE",
    "SUMMARY_FILE",
    "RESOURCE_NOTE",
    "row_base",
    "scored_row",
    "error_row",
    "sort_rows",
    "summarize",
    "write_evaluation",
    "read_metrics",
    "read_summary",
    "compare_evaluations",
    "main",
]

PROTOCOL = "assembly-evaluation-v1"
EXPECTED_TOTAL = 100
METRICS_FILE = "metrics.jsonl"
SUMMARY_FILE = "summary.json"
RESOURCE_NOTE = "Selected final attempt only; unknown values remain null"
_METRICS = ("SCD", "PA", "SR")


def row_base(attempt: SampleAttempt) -> dict[str, Any]:
    """The fields every row of an attempt carries, whatever its scoring gives."""
    execution = attempt.execution
    return {
        "block": attempt.block,
        "sample_id": attempt.sample_id,
        "run": str(attempt.run),
        "duration_seconds": attempt.result.get("duration_seconds"),
        "usage": execution.get("usage"),
        "cost_usd": execution.get("cost_usd"),
        "tool_calls": attempt.tool_calls,
        "attempt_finished": attempt.finished,
    }


def scored_row(
    base: Mapping[str, Any],
    *,
    scd: float,
    pa: float,
    sr: bool,
    episode_sha256: str,
    state_index: int,
    parts: list[dict[str, Any]],
    alignment: dict[str, Any],
    scale_divisor: float,
) -> dict[str, Any]:
    """A scored row; ``parts`` are ``{part_id, target_part_id, chamfer, correct}`` sorted by part."""
    return {
        **base,
        "status": "scored",
        "SCD": float(scd),
        "PA": float(pa),
        "SR": int(bool(sr)),
        "protocol_version": PROTOCOL,
        "episode_sha256": episode_sha256,
        "state_index": int(state_index),
        "parts": parts,
        "alignment": alignment,
        "scale_divisor": float(scale_divisor),
    }


def error_row(base: Mapping[str, Any], exc: BaseException) -> dict[str, Any]:
    """An error row: the attempt counts, with PA and SR 0 and no SCD."""
    return {
        **base,
        "status": "error",
        "error": f"{type(exc).__name__}: {exc}",
        "SCD": None,
        "PA": 0.0,
        "SR": 0,
        "protocol_version": PROTOCOL,
    }


def sort_rows(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    return sorted((dict(r) for r in rows), key=lambda r: (r["block"], r["sample_id"]))


def _mean(values: Sequence[float]) -> float:
    return float(np.mean(values))


def _reported(rows: Sequence[Mapping[str, Any]], get) -> dict[str, Any]:
    values = [v for v in map(get, rows) if v is not None]
    return {"reported_samples": len(values), "mean": _mean(values) if values else None}


def summarize(rows: Sequence[Mapping[str, Any]], benchmark: Mapping[str, Any]) -> dict[str, Any]:
    """``summary.json`` of ``rows`` for a ``benchmark.json`` (its ``blocks`` with ``name``,
    ``source`` and ``samples``, and its ``sources``), by the official rules (module doc)."""
    block_list = list(benchmark["blocks"])
    blocks: dict[str, Any] = {}
    for block in block_list:
        mine = [r for r in rows if r["block"] == block["name"]]
        if not mine:
            continue
        scored = [r for r in mine if r["status"] == "scored"]
        blocks[block["name"]] = {
            "attempted": len(mine),
            "expected": len(block["samples"]),
            "scored": len(scored),
            "SCD": _mean([r["SCD"] for r in scored]) if scored else None,
            "PA": _mean([r["PA"] for r in mine]),
            "SR": _mean([r["SR"] for r in mine]),
        }
    expected = {(b["name"], sid) for b in block_list for sid in b["samples"]}
    complete = {(r["block"], r["sample_id"]) for r in rows} == expected and all(
        r.get("attempt_finished", True) for r in rows
    )
    summary: dict[str, Any] = {
        "protocol": PROTOCOL,
        "status": "complete" if complete else "partial",
        "attempted": len(rows),
        "expected": EXPECTED_TOTAL,
        "scored": sum(r["status"] == "scored" for r in rows),
        "blocks": blocks,
        "official_overall": None,
        "resource_accounting": RESOURCE_NOTE,
    }
    if complete:

        def means(parts: list[Mapping[str, Any]]) -> dict[str, float | None]:
            return {m: _mean([p[m] for p in parts]) if all(p[m] is not None for p in parts) else None for m in _METRICS}

        # a source without blocks (a package cut down to some blocks) has no mean, rather than NaN
        sources = {
            s: means([blocks[b["name"]] for b in block_list if b["source"] == s])
            for s in benchmark["sources"]
            if any(b["source"] == s for b in block_list)
        }
        summary["sources"] = sources
        summary["official_overall"] = means(list(sources.values()))
    summary["resources"] = {
        name: _reported(rows, lambda r, n=name: r.get(n)) for name in ("duration_seconds", "cost_usd", "tool_calls")
    }
    usage_keys = sorted({k for r in rows for k in (r.get("usage") or {}) if k.endswith("_tokens")})
    tokens = {k: _reported(rows, lambda r, k=k: (r.get("usage") or {}).get(k)) for k in usage_keys}
    summary["token_usage"] = {k: v for k, v in tokens.items() if v["reported_samples"]}
    return summary


def write_evaluation(out_dir: str | Path, rows: Sequence[Mapping[str, Any]], summary: Mapping[str, Any]) -> Path:
    """Write ``metrics.jsonl`` (rows sorted by block and sample id) and ``summary.json`` into a
    new folder ``out_dir``."""
    out = Path(out_dir)
    if out.exists():
        raise FileExistsError(f"{out}: evaluation folder already exists (use a new one)")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.tmp-"))
    try:  # written beside, then renamed: a failure leaves no folder that looks complete
        text = "".join(json.dumps(r, allow_nan=False) + "\n" for r in sort_rows(rows))  # strict JSON lines
        try:
            (tmp / METRICS_FILE).write_text(text, encoding="utf-8")
        except OSError as exc:  # a full disk: say which file
            raise OSError(exc.errno, exc.strerror, str(out / METRICS_FILE)) from None
        write_json(tmp / SUMMARY_FILE, summary)
        tmp.rename(out)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return out


def read_metrics(path: str | Path) -> list[dict[str, Any]]:
    """The rows of an official ``metrics.jsonl`` (each checked for block, sample id, status and
    the three metrics)."""
    file = Path(path)
    rows = []
    for n, row in read_json_lines(file):
        if not isinstance(row, dict):
            raise FormatError(file, f"line {n}: expected a JSON object")
        missing = [k for k in ("block", "sample_id", "status", *_METRICS) if k not in row]
        if missing:
            raise FormatError(file, f"line {n}: missing {missing}")
        if row["status"] not in ("scored", "error"):
            raise FormatError(file, f"line {n}: status {row['status']!r} is neither 'scored' nor 'error'")
        rows.append(row)
    return rows


def read_summary(path: str | Path) -> dict[str, Any]:
    """An official ``summary.json`` (checked for its protocol, status and blocks)."""
    file = Path(path)
    value = read_json(file)
    if not isinstance(value, dict) or value.get("protocol") != PROTOCOL:
        raise FormatError(file, f"not an official summary (protocol {PROTOCOL!r} expected)")
    if value.get("status") not in ("complete", "partial") or not isinstance(value.get("blocks"), dict):
        raise FormatError(file, "status must be 'complete' or 'partial', blocks an object")
    return value


def _close(a: Any, b: Any, rtol: float) -> bool:
    if a is None or b is None:
        return a is b
    return abs(float(a) - float(b)) <= rtol * max(abs(float(a)), abs(float(b))) + 1e-15


def _compare_rows(key: tuple[str, str], a: Mapping[str, Any], b: Mapping[str, Any], rtol: float) -> list[str]:
    where = f"{key[0]}/{key[1]}"
    if a["status"] != b["status"]:
        return [f"{where}: status {a['status']!r} != {b['status']!r}"]
    out = [f"{where}: {m} {a[m]!r} != {b[m]!r}" for m in ("PA", "SR") if a[m] != b[m]]
    if not _close(a["SCD"], b["SCD"], rtol):
        out.append(f"{where}: SCD {a['SCD']!r} != {b['SCD']!r}")
    if a["status"] == "scored":
        out += [
            f"{where}: {k} {a.get(k)!r} != {b.get(k)!r}"
            for k in ("state_index", "episode_sha256")
            if a.get(k) != b.get(k)
        ]
        pa, pb = a.get("parts") or [], b.get("parts") or []

        def matches(parts):
            return [(p["part_id"], p["target_part_id"], p["correct"]) for p in parts]

        if matches(pa) != matches(pb) or not all(
            _close(p["chamfer"], q["chamfer"], rtol) for p, q in zip(pa, pb, strict=True)
        ):
            out.append(f"{where}: part matches or part Chamfers differ")
    return out


def compare_evaluations(expected_dir: str | Path, actual_dir: str | Path, rtol: float = 1e-9) -> list[str]:
    """What differs between two evaluation folders (e.g. the official ``eval`` output and
    ``aw-score``'s for the same run): rows by (block, sample id), statuses, PA and SR exactly,
    SCD and part Chamfers to ``rtol``, part matches, restored state and archive digest; the
    summaries' status, counts and means. An empty list: they agree."""
    a_dir, b_dir = Path(expected_dir), Path(actual_dir)
    rows_a = {(r["block"], r["sample_id"]): r for r in read_metrics(a_dir / METRICS_FILE)}
    rows_b = {(r["block"], r["sample_id"]): r for r in read_metrics(b_dir / METRICS_FILE)}
    out = [f"{k[0]}/{k[1]}: only in {a_dir}" for k in sorted(set(rows_a) - set(rows_b))]
    out += [f"{k[0]}/{k[1]}: only in {b_dir}" for k in sorted(set(rows_b) - set(rows_a))]
    for key in sorted(set(rows_a) & set(rows_b)):
        out += _compare_rows(key, rows_a[key], rows_b[key], rtol)
    sa, sb = read_summary(a_dir / SUMMARY_FILE), read_summary(b_dir / SUMMARY_FILE)
    out += [
        f"summary: {k} {sa.get(k)!r} != {sb.get(k)!r}"
        for k in ("status", "attempted", "expected", "scored")
        if sa.get(k) != sb.get(k)
    ]
    groups = [("blocks", sa["blocks"], sb["blocks"]), ("sources", sa.get("sources") or {}, sb.get("sources") or {})]
    groups.append(
        (
            "official_overall",
            {"": sa["official_overall"]} if sa["official_overall"] else {},
            {"": sb["official_overall"]} if sb["official_overall"] else {},
        )
    )
    for name, ga, gb in groups:
        if set(ga) != set(gb):
            out.append(f"summary: {name} {sorted(ga)} != {sorted(gb)}")
        for k in sorted(set(ga) & set(gb)):
            out += [
                f"summary: {name}[{k!r}].{m} {ga[k][m]!r} != {gb[k][m]!r}"
                for m in _METRICS
                if not _close(ga[k][m], gb[k][m], rtol)
            ]
    return out


def main(argv: list[str] | None = None) -> int:
    """``python -m aw.official.evaluation_output EXPECTED ACTUAL``: list the differences of two
    evaluation folders; 0 when they agree, 1 when they differ, 2 on unreadable input."""
    import argparse
    import sys

    p = argparse.ArgumentParser(
        prog="python -m aw.official.evaluation_output",
        description="Compare two evaluation folders (metrics.jsonl + summary.json).",
    )
    p.add_argument("expected", help="e.g. the official eval output")
    p.add_argument("actual", help="e.g. aw-score's OUT/official/<system>")
    p.add_argument("--rtol", type=float, default=1e-9, help="relative tolerance of SCD and Chamfers (default 1e-9)")
    args = p.parse_args(argv)
    try:
        diffs = compare_evaluations(args.expected, args.actual, args.rtol)
    except (FormatError, KeyError, TypeError) as exc:
        print(f"evaluation_output: error: {exc}", file=sys.stderr)
        return 2
    for line in diffs:
        print(line)
    print("the evaluations agree" if not diffs else f"{len(diffs)} differences")
    return 1 if diffs else 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
