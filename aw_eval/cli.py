"""aw-score: rescore whole studies and write the paper's tables, intervals, tests and plots.

    aw-score SUITE RUNS --out DIR [--final-mode exact|fast] [--checkpoint-mode fast|exact]
             [--final-only] [--backend auto|numba|jax] [--scheduler ADDRESS] [--jobs J] [--seed S]
             [--bootstrap 10000] [--permutations 100000] [--no-plots] [--no-html] [--no-progress]

Runs are RUNS/<system>/<task_id>/ (trajectory.jsonl, final.json, optional run.json). When SUITE
is an official benchmark package (benchmark.json), RUNS is an official run log, a logs/ folder or
a folder of episode archives, and the official metrics.jsonl/summary.json are written
(aw_eval.official_runs). Scores are cached under DIR/cache; a second call recomputes only what
changed. See docs/scoring.md.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
import warnings
from collections.abc import Sequence

from aw.cli.common import (
    CliError,
    UsageError,
    add_hidden_alias,
    add_jobs,
    add_no_progress,
    check_out_dir,
    new_parser,
    plural,
    positive_int,
    run_main,
)
from aw.progress import warnings_in_one_line

__all__ = ["build_parser", "main", "protocol_note"]


def build_parser() -> argparse.ArgumentParser:
    p = new_parser(
        "aw-score",
        "Rescore AssemblyWorld runs of any number of systems: every checkpoint, every final "
        "state, the paper's statistics, analyses and plots.",
        epilog="See docs/scoring.md.",
    )
    p.add_argument(
        "suite_dir",
        metavar="SUITE",
        help="suite directory (manifest.json, tasks/, targets/), or an official benchmark package (benchmark.json)",
    )
    p.add_argument(
        "runs_dir",
        metavar="RUNS",
        help="runs directory: RUNS/<system>/<task_id>/; with a package, "
        "an official run log (run.json), a logs/ folder of runs or a folder of *.episode.zip",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="report directory to write (also holds the cache)")
    modes = ("exact", "fast")
    p.add_argument(
        "--final-mode",
        choices=modes,
        default="exact",
        metavar="MODE",
        help="registration mode for final states, which the tables use: exact (default, the protocol: "
        "every start refined) or fast (not the protocol)",
    )
    p.add_argument(
        "--checkpoint-mode",
        choices=modes,
        default="fast",
        metavar="MODE",
        help="registration mode for trajectory checkpoints, which the curves use: fast (default) or exact",
    )
    add_hidden_alias(p, "--final", dest="final_mode", choices=modes)  # old names
    add_hidden_alias(p, "--mode", dest="checkpoint_mode", choices=modes)
    p.add_argument("--final-only", action="store_true", help="score final states only (no checkpoints, no curves)")
    p.add_argument(
        "--trust-final",
        action="store_true",
        help="score final.json even where it contradicts the trajectory's last recorded state "
        "(default: the trajectory wins; the contradiction is listed either way)",
    )
    p.add_argument(
        "--backend",
        choices=("auto", "numba", "jax"),
        default="auto",
        help="where exact scoring runs: numba (compiled, CPU), jax (batched over checkpoints x starts, "
        "any XLA device), auto (jax when JAX sees a GPU/TPU; default)",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        default=None,
        help="Dask scheduler address (e.g. tcp://host:8786): one job per task on the cluster; "
        "workers must see SUITE and RUNS at the same paths",
    )
    add_jobs(p, "local worker processes (without --scheduler; also for report.html's pictures)")
    p.add_argument("--seed", type=int, default=0, help="seed of the bootstrap and randomization draws (default 0)")
    p.add_argument(
        "--bootstrap",
        type=positive_int("--bootstrap"),
        default=10_000,
        metavar="B",
        help="bootstrap draws (default 10000)",
    )
    p.add_argument(
        "--permutations",
        type=positive_int("--permutations"),
        default=100_000,
        metavar="R",
        help="randomization-test relabellings (default 100000)",
    )
    p.add_argument(
        "--protocol-setting",
        dest="protocol",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="override a number of the evaluation protocol (aw_eval.settings.ProtocolSettings, e.g. "
        "n_fps=200): departs from the paper's protocol; recorded in scores.json (repeatable)",
    )
    add_hidden_alias(p, "--protocol", dest="protocol", action="append")  # old name
    p.add_argument(
        "--geometry-cache",
        metavar="DIR",
        default=None,
        help="where the evaluator caches per-task geometry (default DIR/cache/geometry); may be shared between studies",
    )
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument(
        "--no-html",
        action="store_true",
        help="skip report.html and its folder report_files/ (pictures of every run, 3D views)",
    )
    p.add_argument(
        "--viewer-url",
        metavar="URL",
        help="the URL aw-view printed for these RUNS: report.html links each run to its episode page there "
        "(default: no links, the report stays self-contained)",
    )
    add_no_progress(p)
    return p


def protocol_note(final_mode: str, overrides: Sequence[tuple[str, float]] = ()) -> str:
    """ "" when final states are scored by the paper's protocol, else why the numbers are not its."""
    why = []
    if final_mode != "exact":
        why.append(f"final states in {final_mode} mode")
    if overrides:
        why.append("protocol overridden (" + ", ".join(f"{k}={v:g}" for k, v in overrides) + ")")
    return f" [not the protocol's numbers: {'; '.join(why)}]" if why else ""


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if threading.current_thread() is not threading.main_thread():
        return run_main("aw-score", lambda: _locked(args))
    before = signal.signal(signal.SIGTERM, _interrupt)  # SIGTERM stops as Ctrl-C does: workers ended, exit 130
    try:
        with warnings.catch_warnings():
            warnings.showwarning = warnings_in_one_line("aw-score")
            return run_main("aw-score", lambda: _locked(args))
    finally:
        signal.signal(signal.SIGTERM, before)


def _interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def _locked(args: argparse.Namespace) -> int:
    """``_score`` holding ``--out``'s lock (aw.runlock): a second aw-score on the same --out is refused."""
    from aw.runlock import RunDirBusy, RunDirLock, holder_of

    out = check_out_dir(args.out)
    try:
        lock = RunDirLock(out).acquire()
    except RunDirBusy:
        raise UsageError(
            f"--out {out}: in use by {holder_of(out) or 'another process'}; wait for it to end or choose another --out"
        ) from None
    try:
        return _score(args)
    finally:
        lock.release()


def _parse_overrides(items: Sequence[str]) -> list[tuple[str, float]]:
    overrides = []
    for item in items:
        name, sep, value = item.partition("=")
        try:
            if not sep:
                raise ValueError("expected NAME=VALUE")
            overrides.append((name.strip(), float(value)))
        except ValueError as exc:
            raise UsageError(f"--protocol-setting {item!r}: {exc}") from None
    return overrides


def _score(args: argparse.Namespace) -> int:
    from aw_eval import official_runs

    out = check_out_dir(args.out)
    if args.viewer_url is not None and not args.viewer_url.startswith(("http://", "https://")):
        raise UsageError(f"--viewer-url must be the http:// URL that aw-view printed, got {args.viewer_url!r}")
    if official_runs.is_official_package(args.suite_dir):  # an official package and its run logs
        return official_runs.main(args.suite_dir, args.runs_dir, args.out, args.jobs)

    from aw_eval.report import AnalysisSettings, write_outputs
    from aw_eval.report.markdown import system_label
    from aw_eval.study import ScoreSettings, ScoringFailed, StudyError, score_study

    def log(msg: str) -> None:
        print(f"aw-score: {msg}", file=sys.stderr)

    overrides = _parse_overrides(args.protocol)
    try:
        settings = ScoreSettings(
            checkpoint_mode=args.checkpoint_mode,
            final_mode=args.final_mode,
            final_only=args.final_only,
            trust_final=args.trust_final,
            protocol=tuple(overrides),
            backend=args.backend,
        )
    except (ValueError, TypeError) as exc:
        raise UsageError(f"--protocol-setting: {exc}") from None
    t0 = time.perf_counter()
    try:
        study, stats = score_study(
            args.suite_dir,
            args.runs_dir,
            out,
            settings,
            scheduler=args.scheduler,
            n_jobs=args.jobs,
            progress=not args.no_progress,
            log=log,
            geometry_cache=args.geometry_cache,
        )
    except ScoringFailed as exc:  # the tool failed, not the runs: no report of zeros
        raise CliError(str(exc)) from None
    except StudyError as exc:
        raise UsageError(str(exc)) from None
    t_score = time.perf_counter() - t0
    res = write_outputs(
        study,
        out,
        AnalysisSettings(seed=args.seed, n_draws=args.bootstrap, n_permutations=args.permutations),
        suite_dir=str(args.suite_dir),
        runs_dir=str(args.runs_dir),
        score_stats={
            "cached_runs": stats.cached,
            "scored_runs": stats.scored,
            "missing_runs": stats.missing,
            "errors": stats.errors,
            "tasks_dispatched": stats.tasks_dispatched,
            "executor": stats.executor,
            "scoring_seconds": round(t_score, 3),
            "worker_seconds": {
                "geometry": round(stats.seconds_geometry, 3),
                "checkpoints": round(stats.seconds_checkpoints, 3),
                "final_states": round(stats.seconds_final, 3),
            },
        },
        plots=not args.no_plots,
        html=not args.no_html,
        log=log,
        jobs=args.jobs,
        viewer_url=args.viewer_url,
    )
    doc = res["doc"]
    unscored = ", ".join(f"{len(v)} {k}" for k, v in sorted(doc["unscored_runs"].items()))
    log(
        f"{plural(len(study.systems), 'system')} x {plural(len(study.entries), 'task')}: "
        f"{plural(stats.cached, 'run')} from the cache, {stats.scored} scored now"
        + (f", unscored: {unscored}" if unscored else "")
        + (
            f", {plural(len(study.unknown_runs), 'run')} for tasks not in the suite ignored"
            if study.unknown_runs
            else ""
        )
        + f" ({time.perf_counter() - t0:.1f} s)"
    )
    q = doc["quality"]["systems"]
    note = protocol_note(args.final_mode, overrides)
    cov = stats.coverage
    for s in doc["uncertainty"].get("order", study.systems):
        o = q[s]["overall"]
        have = cov.runs.get(s, cov.n_tasks) if cov else None
        short = (
            f"  [WARNING: runs for only {have} of {plural(cov.n_tasks, 'task')}; the rest count 0]"
            if cov and have < cov.n_tasks
            else ""
        )
        print(f"{system_label(doc, s)}: Overall SR {o['sr']:.2f}%  PA {o['pa']:.2f}%{note}{short}")
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
