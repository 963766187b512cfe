"""Runs recorded here (``aw-run``/``aw-serve``: ``RUNS/<system>/<task_id>/``) written as one
official run log, so the official tools (``eval``, ``status``, ``resume``) can read them.

A task id names its official sample as ``<block>--<slug>`` (:func:`aw.official.ids.task_id_for_sample`,
the ids of a suite converted from the package). For each recorded task the sample folder gets:

* ``input.json``: the package's sample entry, ``initial_path``, ``initial_calls``,
  ``identity`` and ``reference`` (as the runner writes it when it creates a run);
* ``prompt.txt``: the block's task text (the package's), a newline and ``protocol_text``;
* ``conversation.jsonl``: a ``tool_call`` and a ``tool_result`` row per recorded call, stamped
  with the run's start time plus the call's time;
* ``final.episode.zip``: the run as an official archive continuing the sample's initial archive
  (:func:`aw.official.export.export_run`);
* ``result.json``: ``completed`` when the run finished and the archive was written, else
  ``failed``, with the run's wall time, usage and cost.

By default the run selects the recorded tasks alone; with ``all_samples`` it selects every
sample of the package and the unrecorded ones stay ``pending`` (not attempted). ``run.json``
ends ``completed`` when every selected sample is, else ``failed``.
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from aw.formats import FormatError, read_run_info, read_trajectory
from aw.official.ids import task_id_for_sample
from aw.official.package import REVISION, OfficialPackage
from aw.official.runlog import RunLog, create_run, write_json, write_result

__all__ = ["export_runs", "main"]

_EXECUTION = {"finished": "completed", "timeout": "timeout", "error": "failed", "crashed": "failed", "hung": "failed"}


def export_runs(
    system_dir: str | Path,
    package: OfficialPackage,
    logs_dir: str | Path,
    *,
    options: Mapping[str, Any] | None = None,
    protocol_text: str = "",
    run_id: str | None = None,
    all_samples: bool = False,
) -> RunLog:
    """Write ``LOGS/<run id>/`` from ``RUNS/<system>/`` (module doc); returns the run."""
    src = Path(system_dir)
    tasks = sorted(p for p in src.iterdir() if (p / "trajectory.jsonl").is_file()) if src.is_dir() else []
    if not tasks:
        raise FormatError(src, "no recorded run (<task_id>/trajectory.jsonl) in this folder")
    by_task = {task_id_for_sample(b, s): (b, s) for b, s in package.samples()}
    recorded: dict[tuple[str, str], Path] = {}
    for task_dir in tasks:
        if task_dir.name not in by_task:
            raise FormatError(
                task_dir, f"task id {task_dir.name!r} is not <block>--<slug> of a sample of {package.root}"
            )
        recorded[by_task[task_dir.name]] = task_dir
    selection: dict[str, list[str]] = {}
    for block, sid in package.samples():
        if all_samples or (block, sid) in recorded:
            selection.setdefault(block, []).append(sid)
    inputs = {}
    for block, ids in selection.items():
        identity = package.configuration(block)[1]["identity"]
        for sid in ids:
            sample = package.sample(block, sid)
            inputs[(block, sid)] = {
                **sample.expected,
                "initial_path": str(sample.initial_path),
                "initial_calls": len(package.initial_archive(block, sid).calls),
                "identity": identity,
                "reference": sample.reference,
            }
    run = create_run(
        logs_dir,
        selection,
        inputs,
        {b: package.task_text(b) for b in selection},
        {b: package.blocks[b]["reference_mode"] for b in selection},
        options or {"agent": src.name},
        protocol_text=protocol_text,
        run_id=run_id,
        benchmark={"revision": REVISION, "local": str(package.root)},
    )
    statuses = [
        _write_sample(run, package, block, sid, task_dir) for (block, sid), task_dir in sorted(recorded.items())
    ]
    done = len(statuses) == len(inputs) and all(s == "completed" for s in statuses)
    meta = dict(
        run.meta,
        status="completed" if done else "failed",
        finished_at=datetime.now(UTC).isoformat(timespec="microseconds"),
        pause_reason=None,
        errors=[],
    )
    write_json(run.path / "run.json", meta)
    return RunLog(run.path, meta)


def _write_sample(run: RunLog, package: OfficialPackage, block: str, sid: str, task_dir: Path) -> str:
    """Write one recorded task's sample files; returns its result status."""
    from aw.official.export import export_run

    traj = read_trajectory(task_dir / "trajectory.jsonl")
    info = read_run_info(task_dir / "run.json") if (task_dir / "run.json").is_file() else None
    t0 = _parse_time(traj.header.started_at)
    conversation = []
    for call in traj.calls:
        stamp = (t0 + timedelta(seconds=max(call.t or 0.0, 0.0))).isoformat(timespec="microseconds")
        conversation.append(
            {
                "timestamp": stamp,
                "type": "tool_call",
                "id": f"call-{call.seq}",
                "name": call.tool,
                "arguments": call.args,
            }
        )
        conversation.append(
            {
                "timestamp": stamp,
                "type": "tool_result",
                "id": f"call-{call.seq}",
                "result": {"ok": call.ok, **({"error": call.error} if call.error else {})},
            }
        )
    execution: dict[str, Any] = {
        "status": _EXECUTION[info.ended] if info else ("completed" if traj.end else "interrupted")
    }
    if info is not None:
        if info.error:
            execution["error"] = info.error
        if info.tokens is not None:
            execution["usage"] = {f"{k}_tokens": v for k, v in info.tokens.model_dump().items() if v is not None}
        execution["cost_usd"] = info.cost_usd
    with tempfile.TemporaryDirectory() as tmp:
        archive = export_run(task_dir, package.initial_archive(block, sid), Path(tmp) / "final.episode.zip")
        data = archive.path.read_bytes()
    end = t0 + timedelta(seconds=info.wall_seconds) if info and info.wall_seconds is not None else None
    status = "completed" if execution["status"] == "completed" else "failed"
    result = {
        "status": status,
        "started_at": t0.isoformat(timespec="microseconds"),
        **({"finished_at": end.isoformat(timespec="microseconds")} if end else {}),
        "duration_seconds": info.wall_seconds if info else None,
        "execution": execution,
        "agent_outcome": None,
    }
    write_result(
        run, block, sid, result, conversation=conversation, final_archive=data, archive_calls=len(archive.calls)
    )
    return status


def _parse_time(text: str) -> datetime:
    try:
        t = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise ValueError(f"started_at {text!r} is not an ISO-8601 time") from None
    return t if t.tzinfo else t.replace(tzinfo=UTC)


def main(argv: list[str] | None = None) -> int:
    """``python -m aw.official.runlog_export PKG RUNS/<system> --logs LOGS``: print the run folder."""
    import argparse
    import sys

    p = argparse.ArgumentParser(
        prog="python -m aw.official.runlog_export",
        description="Write one system's recorded runs as an official run log.",
    )
    p.add_argument("package", metavar="PKG", help="official benchmark package (benchmark.json)")
    p.add_argument("system_dir", metavar="RUNS/SYSTEM", help="recorded runs: SYSTEM/<block>--<slug>/trajectory.jsonl")
    p.add_argument("--logs", default="logs", help="folder that receives the run (default logs)")
    p.add_argument("--model", default=None, help="model name recorded in run.json's options")
    p.add_argument(
        "--all-samples", action="store_true", help="select every package sample (unrecorded ones stay pending)"
    )
    args = p.parse_args(argv)
    options = {"agent": Path(args.system_dir).name, **({"model": args.model} if args.model else {})}
    try:
        run = export_runs(
            args.system_dir,
            OfficialPackage(args.package, strict=False),
            args.logs,
            options=options,
            all_samples=args.all_samples,
        )
    except (FormatError, ValueError, OSError) as exc:
        print(f"runlog_export: error: {exc}", file=sys.stderr)
        return 2
    print(run.path)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
