"""Rescore official benchmark runs with this project's evaluator (``exact`` mode) and write the
official evaluation outputs.

``aw-score PACKAGE RUNS --out OUT`` with ``PACKAGE`` an official benchmark package (it has
``benchmark.json``) lands here. ``RUNS`` is a run folder (``run.json``), a ``logs/`` folder of
runs, or a folder of ``*.episode.zip`` archives. Runs are grouped into systems by the agent,
model and effort in their ``run.json`` options; each system's chains are merged as the
official evaluation merges them (:func:`aw.official.runlog.select_attempts`) and every counted
attempt's final state is scored against the package's evaluation inputs. For each system
``OUT/official/<system>/`` gets ``metrics.jsonl`` and ``summary.json`` in the official form
(:mod:`aw.official.evaluation_output`), so they can be set beside the official ``summary.json``
of the same run.
"""

from __future__ import annotations

import multiprocessing
import os
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from aw import interrupts
from aw.cli.common import plural
from aw.formats import FormatError
from aw.official.evaluation_cache import EvaluationInputs
from aw.official.evaluation_output import error_row, row_base, scored_row, sort_rows, summarize, write_evaluation
from aw.official.package import OfficialPackage, file_sha256
from aw.official.runlog import (
    RunLog,
    SampleAttempt,
    archive_system,
    is_run_dir,
    read_attempts,
    read_run,
    select_attempts,
    systems,
)
from aw_eval.study.runner import ScoringFailed
from aw_eval.workers import stop_pool, worker_init

__all__ = [
    "is_official_package",
    "archive_attempts",
    "score_state",
    "score_attempt",
    "evaluate_system",
    "evaluate",
    "main",
]

SCD_SCALE = 1000.0  # the official SCD is 1000 x the aligned squared Chamfer (geometry.py)


def is_official_package(path: str | Path) -> bool:
    return (Path(path) / "benchmark.json").is_file()


# --- systems -----------------------------------------------------------------------------------


def archive_attempts(folder: str | Path, package: OfficialPackage) -> dict[tuple[str, str], SampleAttempt]:
    """Attempts for a folder of episode archives, each named by the block folder above it and
    its sample slug (``<block>/<slug>.episode.zip``, or ``.../<block>/.../<slug>/final.episode.zip``
    as in a run log; :func:`aw.official.convert.archive_sample`)."""
    from aw.official.convert import archive_sample, find_archives

    root = Path(folder).resolve()
    out: dict[tuple[str, str], SampleAttempt] = {}
    for arc in find_archives(root):
        key = archive_sample(arc, package)
        if key in out:
            raise FormatError(arc, f"a second archive for {key[0]}/{key[1]} (first: {out[key].final_archive})")
        result = {"status": "completed", "archive": {"status": "saved", "sha256": file_sha256(arc)}}
        out[key] = _ArchiveAttempt(key[0], key[1], root, root, arc.parent, {}, result, arc)
    if not out:
        raise FormatError(root, "no *.episode.zip archive in this folder")
    return out


@dataclass(frozen=True)
class _ArchiveAttempt(SampleAttempt):
    archive: Path = Path()

    @property
    def final_archive(self) -> Path:
        return self.archive

    @property
    def tool_calls(self) -> int | None:
        return None


# --- scoring -----------------------------------------------------------------------------------


def score_state(inputs: EvaluationInputs, poses: np.ndarray) -> dict[str, Any]:
    """Official metrics of one state ``poses (P, 7)`` by this project's ``exact`` evaluator:
    ``SCD`` (x1000), ``PA``, ``SR``, ``parts`` ({part_id, target_part_id, chamfer, correct})
    and ``alignment`` (rotation, translation, chamfer, seed)."""
    from aw_eval import TaskGeometry, score
    from aw_eval.results import start_label

    geom = TaskGeometry.from_points(
        inputs.part_ids,
        np.asarray(inputs.points, dtype=np.float64),
        np.asarray(inputs.target_poses, dtype=np.float64),
        float(inputs.divisor),
        inputs.groups,
    )
    res = score(geom, np.asarray(poses, dtype=np.float64), mode="exact")
    ids = list(geom.part_ids)
    threshold = geom.settings.threshold
    parts = sorted(
        (
            {
                "part_id": p,
                "target_part_id": ids[int(res.assignment[k])],
                "chamfer": float(res.part_errors[k]),
                "correct": bool(res.part_errors[k] <= threshold),
            }
            for k, p in enumerate(ids)
        ),
        key=lambda r: str(r["part_id"]),
    )
    kind, index = start_label(res.start_index)
    alignment = {
        "rotation": res.reg_rotation.tolist(),
        "translation": res.reg_translation.tolist(),
        "chamfer": float(res.scd),
        "seed": f"{kind}-{index}",
    }
    return {
        "SCD": SCD_SCALE * float(res.scd),
        "PA": float(res.pa),
        "SR": bool(res.sr),
        "parts": parts,
        "alignment": alignment,
    }


def score_attempt(attempt: SampleAttempt, sources: OfficialPackage) -> dict[str, Any]:
    """The ``metrics.jsonl`` row of one counted attempt. As in the official evaluation, a
    running attempt, a missing export or an archive that differs from ``result.json``'s
    checksum is an error row (PA 0, SR 0), never a fallback to an earlier export."""
    base = row_base(attempt)
    try:
        if not attempt.finished:
            raise RuntimeError("Latest attempt is unfinished; an earlier export is not used instead")
        if not attempt.archive_saved:
            raise FileNotFoundError("Latest attempted execution has no saved final episode")
        checksum = file_sha256(attempt.final_archive)
        if attempt.saved_sha256 and attempt.saved_sha256 != checksum:
            raise ValueError("Final episode checksum differs from execution record")
        inputs = sources.evaluation_inputs(attempt.block, attempt.sample_id)
        poses, state_index = sources.final_state(attempt.block, attempt.sample_id, attempt.final_archive)
        m = score_state(inputs, poses)
        return scored_row(
            base,
            scd=m["SCD"],
            pa=m["PA"],
            sr=m["SR"],
            episode_sha256=checksum,
            state_index=state_index,
            parts=m["parts"],
            alignment=m["alignment"],
            scale_divisor=float(inputs.divisor),
        )
    except Exception as exc:  # every failure of one sample is that sample's error row
        interrupts.reraise_if_interrupted(exc)  # but an interrupt inside a kernel is no sample's failure
        return error_row(base, exc)


def _score_job(job: tuple[SampleAttempt, OfficialPackage]) -> dict[str, Any]:
    return score_attempt(*job)


def evaluate_system(
    attempts: Mapping[tuple[str, str], SampleAttempt], sources: OfficialPackage, out_dir: str | Path, jobs: int = 1
) -> dict[str, Any]:
    """Score every attempt, write ``metrics.jsonl`` and ``summary.json`` into the new folder
    ``out_dir``; returns the summary."""
    if not attempts:
        raise ValueError("No final execution attempts to evaluate")
    items = [attempts[k] for k in sorted(attempts)]
    if jobs > 1 and len(items) > 1:
        # spawn, as the study's pool: forking a process that has started JAX's threads can deadlock
        pool = ProcessPoolExecutor(
            max_workers=jobs,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=worker_init,
            initargs=(os.getpid(),),
        )  # a killed aw-score takes its workers with it
        try:
            with interrupts.blocked_for_children():  # the workers are started by the submissions
                scored = pool.map(_score_job, [(a, sources) for a in items])
            rows = list(scored)
        except BrokenProcessPool as exc:  # a worker died: the tool failed, not the runs
            stop_pool(pool)
            raise ScoringFailed(
                f"scoring failed: a scoring worker process died ({exc}); no evaluation was written"
            ) from None
        except BaseException:  # Ctrl-C, SIGTERM: end the workers now, not after their tasks
            stop_pool(pool)
            raise
        pool.shutdown()
    else:
        rows = [score_attempt(a, sources) for a in items]
    rows = sort_rows(rows)
    summary = summarize(rows, sources.benchmark)
    write_evaluation(out_dir, rows, summary)
    return summary


def evaluate(
    sources: OfficialPackage,
    runs_dir: str | Path,
    out_dir: str | Path,
    jobs: int = 1,
    log: Callable[[str], None] = lambda m: None,
) -> dict[str, dict[str, Any]]:
    """Every system found in ``runs_dir`` (module doc) -> its summary, written under
    ``OUT/official/<system>/``."""
    root = Path(runs_dir)
    out = Path(out_dir) / "official"
    if out.exists():
        raise FileExistsError(f"{out}: already holds an official evaluation (use a new --out)")
    for stale in Path(out_dir).glob(f".{out.name}.tmp-*"):  # left by a killed run (the caller holds --out's lock)
        shutil.rmtree(stale, ignore_errors=True)
    for inside in (root, sources.root):
        if out.resolve().is_relative_to(inside.resolve()):
            raise ValueError(f"--out {out_dir}: the evaluation must be written outside {inside}")
    runs = _runs_or_none(root)
    if runs is None:
        by_system = {archive_system(root): archive_attempts(root, sources)}
    else:
        by_system = {}
        for name, logs in systems(runs).items():
            chosen = select_attempts(logs)
            for run in _chain_runs(logs):  # every run and sample of the chains, pending ones included
                sources.check_run(run)
                for attempt in read_attempts(run):
                    sources.check_attempt(attempt)
                    attempt.tool_calls  # noqa: B018 - a conversation.jsonl that cannot be read is refused here
            by_system[name] = chosen
    summaries = {}
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out_dir, prefix=f".{out.name}.tmp-"))
    try:  # every system is written beside, then the folder is renamed: a failure leaves no evaluation
        for name, attempts in by_system.items():
            log(f"{name}: scoring {plural(len(attempts), 'attempt')}")
            summaries[name] = evaluate_system(attempts, sources, tmp / name, jobs)
        interrupts.check()  # an interrupt that a library swallowed: no evaluation of a part
        tmp.rename(out)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return summaries


def _chain_runs(logs: Iterable[RunLog]) -> list[RunLog]:
    """The given runs and every run they resume, each once."""
    seen: dict[Path, RunLog] = {}
    for run in logs:
        while run.path not in seen:
            seen[run.path] = run
            if run.source_run is None:
                break
            run = read_run(run.source_run)
    return list(seen.values())


def _runs_or_none(root: Path) -> list[Path] | None:
    if is_run_dir(root):
        return [root.resolve()]
    if root.is_dir():
        runs = sorted(p.resolve() for p in root.iterdir() if is_run_dir(p))
        if runs:
            return runs
        return None
    raise FormatError(root, "runs directory not found")


def _overall_text(summary: Mapping[str, Any]) -> str:
    overall = summary.get("official_overall")
    if overall is None:
        return f"partial run ({summary['attempted']}/{summary['expected']} attempted): no Overall"

    def fmt(v: float | None) -> str:
        return "n/a" if v is None else f"{v:.4f}"

    return f"Overall SCD {fmt(overall['SCD'])}  PA {fmt(overall['PA'])}  SR {fmt(overall['SR'])}"


def main(package_dir: str, runs_dir: str, out_dir: str, jobs: int | None = None) -> int:
    """``aw-score PACKAGE RUNS --out OUT [--jobs J]`` (J worker processes, default the number of
    cores): print each system's result; 0 when every attempt was scored (as the official
    ``eval`` exits), 1 when some are error rows, 2 on bad input."""

    def log(msg: str) -> None:
        print(f"aw-score: {msg}", file=sys.stderr)

    try:
        sources = OfficialPackage(package_dir, strict=False)
        summaries = evaluate(sources, runs_dir, out_dir, jobs or os.cpu_count() or 1, log)
    except ScoringFailed as exc:
        print(f"aw-score: error: {exc}", file=sys.stderr)
        return 1
    except (FormatError, ValueError, FileExistsError, FileNotFoundError, NotADirectoryError, PermissionError) as exc:
        print(f"aw-score: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # a failure while writing (a full disk): nothing of the evaluation is left
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"aw-score: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1
    for name, s in summaries.items():
        print(f"{name}: {s['scored']}/{s['attempted']} scored; {_overall_text(s)}")
    print(f"wrote {Path(out_dir) / 'official'}")
    return 0 if all(s["scored"] == s["attempted"] for s in summaries.values()) else 1
