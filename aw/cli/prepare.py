"""``aw-prepare``: build task suites (``manifest.json``, ``tasks/``, ``targets/``).

Subcommands::

    aw-prepare synthetic --out DIR [--per-source N] [--seed S]   the embedded procedural benchmark
    aw-prepare folder SRC --out DIR [--source NAME]              a folder of one's own objects

Each subcommand is a ``register_*(subparsers)`` function in :data:`REGISTRARS`; it adds its
parser (with :func:`add_suite_options`) and sets ``func`` to a handler that turns its arguments
into :class:`~aw.prepare.ObjectSpec` lists and calls :func:`run_suite`. Adding a subcommand is
writing one such function and appending it to :data:`REGISTRARS`.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from aw.formats import FormatError
from aw.prepare import ObjectError, ObjectSpec, SuiteExistsError, VariantPlan, build_suite, format_summary, summarize, task_id_for

__all__ = ["REGISTRARS", "add_suite_options", "run_suite", "build_parser", "main"]


class CliError(Exception):
    """A problem to report in one line (exit status 1)."""


def add_suite_options(p: argparse.ArgumentParser, protocol: str = "official") -> None:
    """Options every suite-building subcommand shares; ``protocol`` is its default preparation."""
    p.add_argument("--out", required=True, metavar="DIR", help="suite directory to write")
    p.add_argument("--protocol", choices=("official", "native"), default=protocol,
                   help="official: the official benchmark's preparation (its layout, part ids and evaluation points "
                   "in eval_points/); native: this project's standardization, needed for --variants "
                   f"(default {protocol})")
    p.add_argument("--seed", type=int, default=0, help="initialization (and generation) seed (default 0)")
    p.add_argument("--variants", type=int, default=0, metavar="K",
                   help="also build the Appendix E robustness variants (two layouts, one removed part, "
                   "one distractor) for the first K objects of each source (default 0)")
    p.add_argument("--jobs", type=int, default=None, metavar="J", help="worker processes (default: CPUs, at most 4)")
    p.add_argument("--force", action="store_true", help="replace a suite already in --out")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _check_unique_task_ids(specs: Sequence[tuple[str, str, Sequence[str]]]) -> None:
    seen: dict[str, str] = {}
    for source, object_id, conditions in specs:
        for c in conditions:
            tid = task_id_for(source, object_id, c)
            if tid in seen and seen[tid] != object_id:
                raise CliError(f"objects {seen[tid]!r} and {object_id!r} map to the same task id {tid!r}; rename one")
            seen[tid] = object_id


def variant_plans(specs: Sequence[ObjectSpec], sources: Sequence[str], k: int, seed: int) -> list[VariantPlan | None]:
    """The Appendix E plan for the first ``k`` specs of each source, None for the others.

    A spec without a donor gets no distractor."""
    plans: list[VariantPlan | None] = []
    taken: dict[str, int] = {}
    for spec, source in zip(specs, sources):
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


def run_suite(args: argparse.Namespace, specs: list[ObjectSpec], sources: list[str], *, name: str, generator: str) -> int:
    """Build the suite of ``specs`` (``sources[i]`` is spec i's source) and print its summary."""
    if args.variants < 0:
        raise CliError("--variants must be >= 0")
    if args.jobs is not None and args.jobs < 1:
        raise CliError("--jobs must be >= 1")
    if args.variants and args.protocol != "native":
        raise CliError("--variants needs --protocol native (the official preparation has no robustness variants)")
    plans = variant_plans(specs, sources, args.variants, args.seed) if args.variants else None
    start = time.perf_counter()
    manifest, results = build_suite(
        specs, args.out, name=name, generator=generator, seed=args.seed, variants=plans, jobs=args.jobs,
        force=args.force, progress=not args.no_progress, protocol=args.protocol,
    )
    elapsed = time.perf_counter() - start
    print(format_summary(summarize(manifest, results)))
    print(f"wrote {len(manifest.tasks)} tasks of {len(results)} objects to {args.out} in {elapsed:.1f} s")
    return 0


# ---------------------------------------------------------------- synthetic
def register_synthetic(sub) -> None:
    p = sub.add_parser("synthetic", help="the embedded procedural benchmark (four blocks)",
                       description="Generate the procedural benchmark: PartNet-like furniture (none and image), "
                       "IKEA-like furniture with manuals, AssemblyBench-like industrial assemblies with step "
                       "diagrams, and two-fragment fractures.")
    add_suite_options(p, protocol="native")
    p.add_argument("--per-source", type=int, default=20, metavar="N", help="objects per block (default 20)")
    p.add_argument("--blocks", default=None, metavar="B1,B2",
                   help="comma-separated subset of partnet, ikea_manual, assemblybench, fantastic_breaks")
    p.set_defaults(func=_cmd_synthetic)


def _cmd_synthetic(args: argparse.Namespace) -> int:
    from aw.sources.synthetic import BLOCKS, plan

    if args.per_source < 1:
        raise CliError("--per-source must be >= 1")
    blocks = list(BLOCKS) if not args.blocks else [b.strip() for b in args.blocks.split(",") if b.strip()]
    unknown = [b for b in blocks if b not in BLOCKS]
    if unknown or not blocks:
        raise CliError(f"unknown block(s) {unknown}; choose from {', '.join(BLOCKS)}")
    loader = "aw.sources.synthetic:generate_object"
    specs, sources, ids = [], [], []
    n = args.per_source
    for block in blocks:
        conds = BLOCKS[block].conditions
        for i in range(n):
            donor_index = (i + 1) % n if n > 1 else 1
            donor = ObjectSpec(loader, (block, donor_index, args.seed))
            specs.append(ObjectSpec(loader, (block, i, args.seed), conds, donor))
            sources.append(block)
            ids.append((block, f"{plan(block, i, args.seed)[0]}_{i:03d}", conds))
    _check_unique_task_ids(ids)
    return run_suite(args, specs, sources, name=f"synthetic-{args.per_source}-seed{args.seed}", generator="aw.sources.synthetic")


# ---------------------------------------------------------------- folder
def register_folder(sub) -> None:
    p = sub.add_parser("folder", help="a folder of assembled objects (one subfolder per object)",
                       description="Import SRC/<object>/<part>.obj|ply|stl|glb|gltf|off (assembled frame) with an "
                       "optional meta.json per object; see aw.sources.folder.")
    p.add_argument("src", metavar="SRC", help="folder with one subfolder per object")
    add_suite_options(p, protocol="native")
    p.add_argument("--source", default="custom", help="benchmark block name for objects whose meta.json has none (default custom)")
    p.set_defaults(func=_cmd_folder)


def _cmd_folder(args: argparse.Namespace) -> int:
    from aw.sources.folder import load_object, read_meta, scan_folder

    found = scan_folder(args.src)
    loader = "aw.sources.folder:load_object"
    sources = []
    for f in found:
        meta = read_meta(Path(f.path))
        sources.append(meta.source or args.source)
    specs = []
    for i, f in enumerate(found):
        # the distractor comes from the next object of the same source, if there is one
        same = [j for j in range(len(found)) if sources[j] == sources[i] and j != i]
        donor_j = next((j for j in same if j > i), same[0] if same else None)
        donor = ObjectSpec(loader, (found[donor_j].path, args.source)) if donor_j is not None else None
        specs.append(ObjectSpec(loader, (f.path, args.source), tuple(f.conditions), donor))
    _check_unique_task_ids([(s, f.object_id, f.conditions) for s, f in zip(sources, found)])
    # load every object once here: bad meshes are reported before any work is done
    for f in found:
        load_object(f.path, args.source)
    return run_suite(args, specs, sources, name=f"folder-{Path(args.src).resolve().name}", generator="aw.sources.folder")


from aw.cli.compose import register_compose, register_official, register_official_export  # noqa: E402  (dataset sources, official import)

REGISTRARS: list[Callable] = [register_synthetic, register_folder, register_compose, register_official,
                               register_official_export]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="aw-prepare", description="Build AssemblyWorld task suites "
                                     "(SUITE/manifest.json, SUITE/tasks/<id>/, SUITE/targets/<id>.json).")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for register in REGISTRARS:
        register(sub)
    return parser


def _warn_in_one_line(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"aw-prepare: warning: {message}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    import warnings

    args = build_parser().parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _warn_in_one_line
            return args.func(args)
    except (CliError, FormatError, SuiteExistsError, NotADirectoryError, ObjectError) as exc:
        print(f"aw-prepare: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("aw-prepare: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
