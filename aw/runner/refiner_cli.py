"""The refiner options of ``aw-run``: a refiner as a system on its own, and the four-arm
bidirectional refinement study (``--refinement-study``). See docs/agents.md, "Refiners"."""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

from aw.cli.common import CliError, UsageError, plural, positive_float, positive_int

__all__ = ["add_refiner_arguments", "run_refiner_command"]


def _option(text: str) -> tuple[str, object]:
    """``KEY=VALUE``, the value an int or a finite float where it reads as one, else text (so
    ``mode=nan`` stays the word, not a NaN)."""
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    key, value = text.split("=", 1)
    for conv in (int, float):
        try:
            number = conv(value)
        except ValueError:
            continue
        if math.isfinite(number):
            return key, number
    return key, value


def add_refiner_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("refiners (see docs/agents.md, Refiners)")
    g.add_argument(
        "--refiner",
        metavar="NAME",
        help="run a geometric refiner: classical (built in) or an installed "
        "assemblyworld.refiners entry point; with --agent only together with --refinement-study",
    )
    g.add_argument(
        "--refiner-command",
        metavar="CMD",
        help="an external refiner: a command line that reads "
        "{request} and writes {result} (JSON, docs/formats.md; appended when absent)",
    )
    g.add_argument(
        "--refiner-option",
        type=_option,
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="refiner-specific setting, passed in the request's options (repeatable)",
    )
    g.add_argument(
        "--refiner-timeout",
        type=positive_float("--refiner-timeout"),
        default=300.0,
        metavar="S",
        help="seconds a refiner may take per task before it is killed (default 300)",
    )
    g.add_argument(
        "--refiner-seed",
        type=int,
        default=42,
        metavar="S",
        help="seed of the shared point samples and the refiner (default 42, the fracture protocol's)",
    )
    g.add_argument(
        "--refiner-steps",
        type=positive_int("--refiner-steps"),
        default=20,
        metavar="N",
        help="refinement steps asked of a learned refiner (default 20, the paper's GARF setting)",
    )
    g.add_argument(
        "--refinement-study",
        action="store_true",
        help="run the four arms (agent, refiner, agent then refiner, refiner then agent) as four systems "
        "and write RUNS/refinement_study.json; needs --agent and a refiner",
    )


def wants_refiner(args: argparse.Namespace) -> bool:
    return bool(args.refiner or args.refiner_command or args.refinement_study)


def run_refiner_command(args: argparse.Namespace, agent_config) -> int:
    """``aw-run`` with a refiner: one refiner system, or the study (``agent_config()`` builds the
    agent's BatchConfig, checked)."""
    from aw.formats import FormatError, read_manifest
    from aw.refine.base import RefinerError
    from aw.refine.plugins import resolve
    from aw.refine.runs import RefineConfig, refine_suite

    if args.out is None:
        raise UsageError("--out RUNS is required")
    try:
        spec = resolve(args.refiner, args.refiner_command)
    except RefinerError as exc:
        raise UsageError(str(exc)) from None
    try:
        ids = read_manifest(args.suite).select(args.tasks)
    except FormatError as exc:
        raise UsageError(str(exc)) from None
    except ValueError as exc:
        raise UsageError(f"--tasks: {exc}") from None
    cfg = RefineConfig(
        suite_dir=args.suite,
        out_dir=args.out,
        system=spec.name,
        spec=spec,
        tasks=ids,
        timeout_s=args.refiner_timeout,
        seed=args.refiner_seed,
        steps=args.refiner_steps,
        options=dict(args.refiner_option),
        overwrite=args.overwrite,
        jobs=args.jobs,
        progress=not args.no_progress,
    )
    if args.refinement_study:
        if not (args.agent or args.harness):
            raise UsageError("--refinement-study needs --agent NAME (or --harness) and --refiner/--refiner-command")
        if args.initial_poses is not None:
            raise UsageError("--refinement-study starts from the tasks' layouts; drop --initial-poses")
        from aw.runner.refinement_study import run_study

        agent_cfg = agent_config()  # --system labels the agent's arm; the refiner's is its name
        cfg.system = spec.name
        arms = run_study(agent_cfg, cfg, ids, log=lambda m: print(f"aw-run: {m}", file=sys.stderr, flush=True))
        for a in arms:
            note = (
                f" ({len(a.failed)} of {a.tasks} tasks failed, first: {next(iter(a.failed.values()))})"
                if a.failed
                else ""
            )
            print(f"{a.arm}: {a.system} {a.status}{note}")
        print(f"runs: {args.out}; study: {os.path.join(str(args.out), 'refinement_study.json')}")
        bad = [a.arm for a in arms if a.status != "ok"]
        if bad:
            raise CliError(f"arms not complete: {', '.join(bad)} (the others are written; see refinement_study.json)")
        return 0
    if args.agent or args.harness:
        raise UsageError(
            "--refiner runs a refiner on its own; to compose it with an agent use --refinement-study "
            "(or run the agent with --initial-poses RUNS/<refiner>)"
        )
    cfg.system = args.system or spec.name
    cfg.start_from = Path(args.initial_poses) if args.initial_poses is not None else None
    try:
        infos, skipped = refine_suite(cfg)
    except RefinerError as exc:
        raise UsageError(str(exc)) from None
    failed = [i for i in infos if i.ended != "finished"]
    print(
        f"{cfg.system}: {plural(len(infos), 'task')} refined, {len(failed)} failed"
        + (f"; skipped {len(skipped)} with an existing run.json" if skipped else "")
    )
    print(f"runs: {os.path.join(str(args.out), cfg.system)}")
    for i in failed:
        print(f"  {i.task_id}: {(i.error or '').splitlines()[0] if i.error else i.ended}")
    if infos and len(failed) == len(infos):
        raise CliError(f"the refiner failed on every task (first: {failed[0].error})")
    return 0
