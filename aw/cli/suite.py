"""What every suite-building subcommand of ``aw-prepare`` shares: its options
(:func:`add_suite_options`), the build and its summary (:func:`run_suite`) and the one-line
error (:class:`aw.cli.common.CliError`, re-exported). Beneath :mod:`aw.cli.prepare` and :mod:`aw.cli.compose`, which both use it."""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence

from aw.cli.common import CliError, UsageError, add_jobs, add_no_progress, add_overwrite, check_out_dir, plural
from aw.prepare import ObjectSpec, VariantPlan, build_suite, format_summary, summarize, task_id_for

__all__ = ["CliError", "add_suite_options", "check_unique_task_ids", "run_suite", "variant_plans"]


def add_suite_options(p: argparse.ArgumentParser, protocol: str = "official") -> None:
    """Options every suite-building subcommand shares; ``protocol`` is its default preparation."""
    p.add_argument("--out", required=True, metavar="SUITE", help="suite directory to write")
    p.add_argument(
        "--protocol",
        choices=("official", "native"),
        default=protocol,
        help="official: the official benchmark's preparation (its layout, part ids and evaluation points "
        "in eval_points/); native: this project's standardization, needed for --variants "
        f"(default {protocol})",
    )
    p.add_argument("--seed", type=int, default=0, help="initialization (and generation) seed (default 0)")
    p.add_argument(
        "--variants",
        type=int,
        default=0,
        metavar="K",
        help="also build the Appendix E robustness variants (two layouts, one removed part, "
        "one distractor) for the first K objects of each source (default 0)",
    )
    add_jobs(p, "objects prepared")
    add_overwrite(p, "a suite already in --out (only its manifest.json, tasks/ and targets/)")
    add_no_progress(p)


def check_unique_task_ids(specs: Sequence[tuple[str, str, Sequence[str]]]) -> None:
    seen: dict[str, str] = {}
    for source, object_id, conditions in specs:
        for c in conditions:
            tid = task_id_for(source, object_id, c)
            if tid in seen and seen[tid] != object_id:
                raise UsageError(f"objects {seen[tid]!r} and {object_id!r} map to the same task id {tid!r}; rename one")
            seen[tid] = object_id


def variant_plans(specs: Sequence[ObjectSpec], sources: Sequence[str], k: int, seed: int) -> list[VariantPlan | None]:
    """The Appendix E plan for the first ``k`` specs of each source, None for the others.

    A spec without a donor gets no distractor."""
    plans: list[VariantPlan | None] = []
    taken: dict[str, int] = {}
    for spec, source in zip(specs, sources, strict=True):
        n = taken.get(source, 0)
        taken[source] = n + 1
        if n >= k:
            plans.append(None)
            continue
        plan = VariantPlan.appendix_e(seed)
        if spec.donor is None:
            plan = VariantPlan(plan.layout_seeds, plan.missing_seed, None)
        plans.append(plan)
    return plans


def run_suite(
    args: argparse.Namespace, specs: list[ObjectSpec], sources: list[str], *, name: str, generator: str
) -> int:
    """Build the suite of ``specs`` (``sources[i]`` is spec i's source) and print its summary."""
    if args.variants < 0:
        raise UsageError("--variants must be >= 0")
    check_out_dir(args.out)
    if args.variants and args.protocol != "native":
        raise UsageError("--variants needs --protocol native (the official preparation has no robustness variants)")
    plans = variant_plans(specs, sources, args.variants, args.seed) if args.variants else None
    start = time.perf_counter()
    manifest, results = build_suite(
        specs,
        args.out,
        name=name,
        generator=generator,
        seed=args.seed,
        variants=plans,
        jobs=args.jobs,
        force=args.overwrite,
        progress=not args.no_progress,
        protocol=args.protocol,
    )
    elapsed = time.perf_counter() - start
    print(format_summary(summarize(manifest, results)))
    print(
        f"wrote {plural(len(manifest.tasks), 'task')} of {plural(len(results), 'object')} to {args.out} "
        f"in {elapsed:.1f} s"
    )
    return 0
