"""``aw-score``: rescore whole studies and write the paper's tables, intervals, tests and plots.

    aw-score SUITE_DIR RUNS_DIR --out OUT_DIR [--final-only] [--final exact|fast]
             [--mode fast|exact] [--backend auto|numba|jax] [--scheduler ADDRESS] [--jobs J] [--seed S]
             [--bootstrap 10000] [--permutations 100000] [--no-plots] [--no-html] [--no-progress]

Runs are ``RUNS_DIR/<system>/<task_id>/`` (``trajectory.jsonl``, ``final.json``, optional
``run.json``). When SUITE_DIR is an official benchmark package (``benchmark.json``), RUNS_DIR is
an official run log, a ``logs/`` folder or a folder of episode archives, and the official
``metrics.jsonl``/``summary.json`` are written (:mod:`aw_eval.official_runs`). Scores are
cached under ``OUT_DIR/cache``; a second call recomputes only what changed. See ``docs/scoring.md``.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

__all__ = ["build_parser", "main"]


def _positive(name: str):
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be an integer, got {text!r}") from None
        if v < 1:
            raise argparse.ArgumentTypeError(f"{name} must be >= 1, got {v}")
        return v

    return parse


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="aw-score", description="Rescore AssemblyWorld runs of any number of systems: "
                                "every checkpoint, every final state, the paper's statistics, analyses and plots.")
    p.add_argument("suite_dir", metavar="SUITE_DIR", help="suite directory (manifest.json, tasks/, targets/), "
                   "or an official benchmark package (benchmark.json)")
    p.add_argument("runs_dir", metavar="RUNS_DIR", help="runs directory: RUNS_DIR/<system>/<task_id>/; with a package, "
                   "an official run log (run.json), a logs/ folder of runs or a folder of *.episode.zip")
    p.add_argument("--out", required=True, metavar="OUT_DIR", help="output directory (also holds the cache)")
    p.add_argument("--final-only", action="store_true", help="score final states only (no checkpoints)")
    p.add_argument("--trust-final", action="store_true",
                   help="score final.json even where it contradicts the trajectory's last recorded state "
                   "(default: the trajectory wins; the contradiction is listed either way)")
    p.add_argument("--final", choices=("exact", "fast"), default="exact",
                   help="registration mode for final states (default exact: the protocol, every start refined)")
    p.add_argument("--mode", choices=("fast", "exact"), default="fast",
                   help="registration mode for trajectory checkpoints (default fast)")
    p.add_argument("--backend", choices=("auto", "numba", "jax"), default="auto",
                   help="where exact scoring runs: numba (compiled, CPU), jax (batched over checkpoints x starts, "
                   "any XLA device), auto (jax when JAX sees a GPU/TPU; default)")
    p.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="Dask scheduler address (e.g. tcp://host:8786): one job per task on the cluster; "
                   "workers must see SUITE_DIR and RUNS_DIR at the same paths")
    p.add_argument("--jobs", type=_positive("--jobs"), default=None, metavar="J",
                   help="local worker processes without --scheduler (default: the number of cores)")
    p.add_argument("--seed", type=int, default=0, help="seed of the bootstrap and randomization draws (default 0)")
    p.add_argument("--bootstrap", type=_positive("--bootstrap"), default=10_000, metavar="B",
                   help="bootstrap draws (default 10000)")
    p.add_argument("--permutations", type=_positive("--permutations"), default=100_000, metavar="R",
                   help="randomization-test relabellings (default 100000)")
    p.add_argument("--protocol", action="append", default=[], metavar="NAME=VALUE",
                   help="override a number of the evaluation protocol (aw_eval.settings.ProtocolSettings, e.g. "
                   "n_fps=200): departs from the paper's protocol; recorded in scores.json (repeatable)")
    p.add_argument("--geometry-cache", metavar="DIR", default=None,
                   help="where the evaluator caches per-task geometry (default OUT_DIR/cache/geometry); "
                   "may be shared between studies")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--no-html", action="store_true", help="skip report.html and its folder report_files/ "
                   "(pictures of every run, 3D views)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from pathlib import Path

    from aw_eval import official_runs

    if official_runs.is_official_package(args.suite_dir):  # an official package and its run logs
        return official_runs.main(args.suite_dir, args.runs_dir, args.out, args.jobs)

    from aw_eval.report import AnalysisSettings, write_outputs
    from aw_eval.study import ScoreSettings, ScoringFailed, StudyError, score_study

    def log(msg: str) -> None:
        print(f"aw-score: {msg}", file=sys.stderr)

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        print(f"aw-score: error: {out} exists and is not a directory", file=sys.stderr)
        return 2
    overrides = []
    for item in args.protocol:
        name, sep, value = item.partition("=")
        try:
            if not sep:
                raise ValueError("expected NAME=VALUE")
            overrides.append((name.strip(), float(value)))
        except ValueError as exc:
            print(f"aw-score: error: --protocol {item!r}: {exc}", file=sys.stderr)
            return 2
    try:
        settings = ScoreSettings(checkpoint_mode=args.mode, final_mode=args.final, final_only=args.final_only,
                                 trust_final=args.trust_final, protocol=tuple(overrides), backend=args.backend)
    except (ValueError, TypeError) as exc:
        print(f"aw-score: error: --protocol: {exc}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    try:
        study, stats = score_study(args.suite_dir, args.runs_dir, out, settings, scheduler=args.scheduler,
                                   n_jobs=args.jobs, progress=not args.no_progress and sys.stderr.isatty(), log=log,
                                   geometry_cache=args.geometry_cache)
    except ScoringFailed as exc:  # the tool failed, not the runs: no report of zeros
        print(f"aw-score: error: {exc}", file=sys.stderr)
        return 1
    except StudyError as exc:
        print(f"aw-score: error: {exc}", file=sys.stderr)
        return 2
    t_score = time.perf_counter() - t0
    res = write_outputs(study, out, AnalysisSettings(seed=args.seed, n_draws=args.bootstrap, n_permutations=args.permutations),
                        suite_dir=str(args.suite_dir), runs_dir=str(args.runs_dir),
                        score_stats={"cached_runs": stats.cached, "scored_runs": stats.scored, "missing_runs": stats.missing,
                                     "errors": stats.errors, "tasks_dispatched": stats.tasks_dispatched,
                                     "executor": stats.executor, "scoring_seconds": round(t_score, 3),
                                     "worker_seconds": {"geometry": round(stats.seconds_geometry, 3),
                                                        "checkpoints": round(stats.seconds_checkpoints, 3),
                                                        "final_states": round(stats.seconds_final, 3)}},
                        plots=not args.no_plots, html=not args.no_html, log=log)
    doc = res["doc"]
    unscored = {k: len(v) for k, v in doc["unscored_runs"].items()}
    log(f"{len(study.systems)} systems x {len(study.entries)} tasks: {stats.cached} runs from the cache, "
        f"{stats.scored} scored now" + (f", unscored {unscored}" if unscored else "") +
        (f", {len(study.unknown_runs)} runs for unknown tasks ignored" if study.unknown_runs else "") +
        f" ({time.perf_counter() - t0:.1f} s)")
    q = doc["quality"]["systems"]
    for s in doc["uncertainty"].get("order", study.systems):
        o = q[s]["overall"]
        print(f"{s}: Overall SR {o['sr']:.2f}%  PA {o['pa']:.2f}%")
    print(f"wrote {res['files']['report']}")
    if "html" in res["files"]:
        print(f"wrote {res['files']['html']}")
    if doc.get("partial"):
        failed = {k: len(doc["unscored_runs"][k]) for k in ("error", "task_error") if k in doc["unscored_runs"]}
        log(f"error: the study is partial: runs not scored {failed} (marked in scores.json and the report)")
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
