"""``aw-run``: run a baseline agent or an agent harness on the tasks of a suite.

    aw-run SUITE_DIR --agent NAME --system LABEL --out RUNS_DIR [--jobs J] [--tasks ID ...]
           [--noise LEVEL] [--timeout-minutes M] [--seed S]
    aw-run SUITE_DIR --harness claude-code|codex --system LABEL --out RUNS_DIR [--harness-bin PATH]
           [--harness-model MODEL] [--harness-arg ARG ...]

Each task gets its own ``aw-serve`` (stdio) and a clean ``RUNS_DIR/LABEL/<task_id>/``; see
``docs/agents.md``.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from aw.runner.batch import BatchConfig, RunnerError, run_batch


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
    p = argparse.ArgumentParser(prog="aw-run", description=__doc__.split("\n\n")[0])
    p.add_argument("suite", type=Path, help="suite directory (manifest.json, tasks/, targets/)")
    who = p.add_mutually_exclusive_group(required=True)
    who.add_argument("--agent", help="baseline agent: idle, random, heuristic, oracle (calibration only)")
    who.add_argument("--harness", choices=["claude-code", "codex"], help="run a real agent harness CLI")
    p.add_argument("--system", help="system label: the runs go to OUT/LABEL/ (default: the agent or harness name)")
    p.add_argument("--out", type=Path, required=True, help="runs directory")
    p.add_argument("--jobs", type=int, default=1, help="episodes in parallel (default 1)")
    p.add_argument("--tasks", nargs="+", metavar="ID", help="only these task ids")
    p.add_argument("--seed", type=int, default=0, help="agent seed (default 0)")
    p.add_argument("--noise", type=float, help="oracle only: residual error level >= 0 (see docs/agents.md)")
    p.add_argument("--timeout-minutes", type=float, help="wall-clock limit per episode (default 10, harnesses 65)")
    p.add_argument("--budget-minutes", type=float, help="the server's execution budget (default: the task's, 60)")
    p.add_argument("--think-seconds", type=float, default=0.0, help="baseline agents pause this long before each edit")
    p.add_argument("--call-timeout", type=float, default=120.0, help="seconds a tool call may wait for the server before the episode counts as hung")
    p.add_argument("--agent-option", type=_agent_option, action="append", default=[], metavar="KEY=VALUE", help="agent-specific setting (repeatable)")
    p.add_argument("--overwrite", action="store_true", help="rerun tasks that already have a run.json (default: skip them)")
    p.add_argument("--harness-bin", help="harness executable (default: claude / codex on PATH)")
    p.add_argument("--harness-model", help="model passed to the harness (--model / -m)")
    p.add_argument("--harness-arg", action="append", default=[], metavar="ARG", help="extra harness argument (repeatable; use --harness-arg=--flag)")
    p.add_argument("--price-table", type=Path, help="Codex cost estimate: JSON {model: [input, cached_input, output]} USD per million tokens")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    system = args.system or args.agent or args.harness
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
        harness_bin=args.harness_bin,
        harness_model=args.harness_model,
        harness_args=args.harness_arg,
        price_table=args.price_table,
        progress=not args.no_progress,
    )
    if args.harness and args.harness_bin is None:
        default = "claude" if args.harness == "claude-code" else "codex"
        import shutil

        if shutil.which(default) is None:
            print(f"aw-run: error: {default!r} is not on PATH; install it or pass --harness-bin", file=sys.stderr)
            return 2
    try:
        result = run_batch(cfg)
    except RunnerError as exc:
        print(f"aw-run: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\naw-run: interrupted; finished episodes are kept, run the same command again to resume", file=sys.stderr)
        return 130
    ends = result.endings()
    summary = ", ".join(f"{k} {v}" for k, v in sorted(ends.items())) or "nothing to run"
    print(f"{system}: {len(result.runs)} episodes in {result.wall_seconds:.1f} s ({summary})", end="")
    print(f"; skipped {len(result.skipped)} with an existing run.json" if result.skipped else "")
    print(f"runs: {os.path.join(str(args.out), system)}")
    for r in result.runs:
        if r.ended != "finished":
            first = (r.error or "").splitlines()[0] if r.error else ""
            print(f"  {r.task_id}: {r.ended}{': ' + first if first else ''}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
