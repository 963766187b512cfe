"""aw-run: run a baseline agent or an agent harness on the tasks of a suite.

    aw-run SUITE --agent NAME --out RUNS [--system LABEL] [--jobs J] [--tasks ID ...]
           [--noise LEVEL] [--timeout-minutes M] [--seed S] [--initial-poses DIR]
    aw-run SUITE --harness claude-code|codex --out RUNS [--system LABEL] [--harness-bin PATH]
           [--harness-model MODEL] [--harness-arg ARG ...]
    aw-run SUITE --harness claude-code|codex --check     the harness check alone
    aw-run SUITE --refiner NAME --out RUNS [--initial-poses DIR]   a geometric refiner as a system
    aw-run SUITE --refinement-study --agent NAME --refiner NAME --out RUNS   the four arms

Each task gets its own aw-serve (stdio) and a clean RUNS/LABEL/<task_id>/; see docs/agents.md.
A harness batch starts with the harness check (binary, version, login, one short session that
lists aw-serve's tools) and stops with one line if it fails. Exit status: 0 when at least one
episode finished, 1 when none did (a refiner: when it failed on every task; a study: when an arm
is incomplete), 2 for a usage error.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from aw.cli.common import (
    CliError,
    UsageError,
    add_jobs,
    add_no_progress,
    add_overwrite,
    check_out_dir,
    new_parser,
    nonnegative_float,
    plural,
    positive_float,
    run_main,
)
from aw.runner.batch import BatchConfig, RunnerError, check_config, run_batch, system_label


def _agent_option(text: str) -> tuple[str, object]:
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    key, value = text.split("=", 1)
    for conv in (int, float):
        try:
            return key, conv(value)
        except ValueError:
            pass
    return key, value


def build_parser() -> argparse.ArgumentParser:
    p = new_parser(
        "aw-run",
        "Run a baseline agent or an agent harness on the tasks of a suite.",
        epilog=__doc__.partition("\n\n")[2],
    )
    p.add_argument("suite", type=Path, metavar="SUITE", help="suite directory (manifest.json, tasks/, targets/)")
    who = p.add_mutually_exclusive_group()  # one of them, or a refiner (checked in _run)
    who.add_argument(
        "--agent", metavar="NAME", help="baseline agent: idle, random, heuristic, oracle (calibration only)"
    )
    who.add_argument(
        "--harness",
        choices=["claude-code", "codex"],
        metavar="NAME",
        help="run a real agent harness CLI: claude-code or codex",
    )
    p.add_argument("--out", type=Path, metavar="RUNS", help="runs directory to write (required unless --check)")
    p.add_argument(
        "--system",
        metavar="LABEL",
        help="system label: the runs go to RUNS/LABEL/ (default: the agent or harness name, with the "
        "oracle's noise level, e.g. oracle-noise0.5)",
    )
    add_jobs(p, "episodes")
    p.add_argument("--tasks", nargs="+", metavar="ID", help="only these task ids")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="agent seed (default 0)")
    p.add_argument(
        "--noise", type=float, metavar="LEVEL", help="oracle only: residual error level >= 0 (see docs/agents.md)"
    )
    p.add_argument(
        "--timeout-minutes",
        type=positive_float("--timeout-minutes"),
        metavar="M",
        help="wall-clock limit per episode (default 10, harnesses 65)",
    )
    p.add_argument(
        "--budget-minutes",
        type=positive_float("--budget-minutes"),
        metavar="M",
        help="the server's execution budget (default: the task's, 60)",
    )
    p.add_argument(
        "--think-seconds",
        type=nonnegative_float("--think-seconds"),
        default=0.0,
        metavar="S",
        help="baseline agents pause this long before each edit (default 0)",
    )
    p.add_argument(
        "--call-timeout",
        type=positive_float("--call-timeout"),
        default=120.0,
        metavar="S",
        help="seconds a tool call may wait for the server before the episode counts as hung (default 120)",
    )
    p.add_argument(
        "--agent-option",
        type=_agent_option,
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="agent-specific setting (repeatable)",
    )
    p.add_argument(
        "--initial-poses",
        type=Path,
        metavar="DIR",
        help="start each episode from given poses instead of the task's layout: DIR/<task_id>/final.json "
        "(another system's runs, e.g. a refiner's) or DIR/<task_id>.json (assemblyworld.poses files)",
    )
    add_overwrite(p, "runs that already have a run.json (default: skip them)")
    p.add_argument("--harness-bin", metavar="PATH", help="harness executable (default: claude / codex on PATH)")
    p.add_argument("--harness-model", metavar="MODEL", help="model passed to the harness (--model / -m)")
    p.add_argument(
        "--harness-arg",
        action="append",
        default=[],
        metavar="ARG",
        help="extra harness argument (repeatable; use --harness-arg=--flag)",
    )
    p.add_argument(
        "--price-table",
        type=Path,
        metavar="FILE",
        help="Codex cost estimate: JSON {model: [input, cached_input, output]} USD per million tokens",
    )
    p.add_argument(
        "--check",
        action="store_true",
        help="with --harness: run the harness check alone and exit (0: ready, 1: not ready)",
    )
    p.add_argument(
        "--skip-check", action="store_true", help="with --harness: start the batch without the harness check"
    )
    add_no_progress(p)
    from aw.runner.refiner_cli import add_refiner_arguments

    add_refiner_arguments(p)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return run_main("aw-run", lambda: _run(args))


def _first_task_dir(args: argparse.Namespace) -> Path:
    from aw.formats import FormatError, read_manifest
    from aw.formats.suite import suite_paths

    try:
        manifest = read_manifest(args.suite)
    except FormatError as exc:
        raise UsageError(str(exc)) from None
    ids = [t.task_id for t in manifest.tasks if not args.tasks or t.task_id in args.tasks]
    if not ids:
        raise UsageError(f"{args.suite}: no task to run")
    return suite_paths(args.suite, ids[0])[0].resolve()


def _check(args: argparse.Namespace) -> bool:
    """Run the harness check, print its steps, and say whether the harness is ready."""
    from aw.runner.check import check_harness

    print(
        f"aw-run: checking {args.harness} (binary, version, login, one short session listing aw-serve's tools)",
        file=sys.stderr,
        flush=True,
    )
    steps = check_harness(
        args.harness, args.harness_bin, _first_task_dir(args), model=args.harness_model, extra_args=args.harness_arg
    )
    for step in steps:
        print(f"  {step.line()}", file=sys.stderr)
    failed = [s for s in steps if not s.ok]
    if failed:
        s = failed[0]
        print(
            f"aw-run: error: {args.harness} is not ready ({s.name}: {s.detail})" + (f"; {s.fix}" if s.fix else ""),
            file=sys.stderr,
        )
        return False
    return True


def _batch_config(args: argparse.Namespace) -> BatchConfig:
    """The checked batch of an --agent or --harness run (UsageError for a bad choice)."""
    if args.out is None:
        raise UsageError("--out RUNS is required (unless --check)")
    check_out_dir(args.out)
    harness_bin = args.harness_bin
    if args.harness:
        from aw.runner.check import find_binary

        try:
            harness_bin = str(find_binary(args.harness, args.harness_bin))
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    system = args.system or system_label(
        args.agent,
        args.harness,
        {**dict(args.agent_option), **({"noise": args.noise} if args.noise is not None else {})},
    )
    cfg = BatchConfig(
        suite_dir=args.suite,
        system=system,
        out_dir=args.out,
        agent=args.agent,
        harness=args.harness,
        jobs=args.jobs,
        tasks=args.tasks,
        seed=args.seed,
        noise=args.noise,
        timeout_minutes=args.timeout_minutes,
        budget_minutes=args.budget_minutes,
        think_seconds=args.think_seconds,
        call_timeout=args.call_timeout,
        overwrite=args.overwrite,
        agent_options=dict(args.agent_option),
        harness_bin=harness_bin,
        harness_model=args.harness_model,
        harness_args=args.harness_arg,
        price_table=args.price_table,
        progress=not args.no_progress,
        initial_poses=args.initial_poses,
    )
    try:
        check_config(cfg)
    except RunnerError as exc:
        raise UsageError(str(exc)) from None
    return cfg


def _run(args: argparse.Namespace) -> int:
    from aw.runner.refiner_cli import run_refiner_command, wants_refiner

    if not (args.agent or args.harness or wants_refiner(args)):
        raise UsageError("give --agent NAME, --harness NAME or --refiner NAME")
    if wants_refiner(args) and not args.check:
        return run_refiner_command(args, lambda: _batch_config(args))
    if args.check or args.skip_check:
        if not args.harness:
            raise UsageError("--check and --skip-check apply to --harness runs")
    if args.check:
        return 0 if _check(args) else 1
    cfg = _batch_config(args)
    system = cfg.system
    if args.harness and not args.skip_check and not _check(args):
        return 1
    try:
        result = run_batch(cfg)
    except RunnerError as exc:
        raise UsageError(str(exc)) from None
    except KeyboardInterrupt:
        print(
            "\naw-run: interrupted; finished episodes are kept, run the same command again to resume", file=sys.stderr
        )
        return 130
    ends = result.endings()
    summary = ", ".join(f"{k} {v}" for k, v in sorted(ends.items())) or "nothing to run"
    print(f"{system}: {plural(len(result.runs), 'episode')} in {result.wall_seconds:.1f} s ({summary})", end="")
    print(f"; skipped {len(result.skipped)} with an existing run.json (same options)" if result.skipped else "")
    print(f"runs: {os.path.join(str(args.out), system)}")
    for r in result.runs:
        if r.ended != "finished":
            first = (r.error or "").splitlines()[0] if r.error else ""
            print(f"  {r.task_id}: {r.ended}{': ' + first if first else ''}")
    if result.runs and not ends.get("finished"):
        raise CliError(f"no episode finished ({summary}); see run.json and the logs under {args.out / system}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
