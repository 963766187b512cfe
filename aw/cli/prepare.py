"""aw-prepare: build task suites (manifest.json, tasks/, targets/).

    aw-prepare synthetic --out SUITE [--per-source N] [--seed S]   the embedded procedural benchmark
    aw-prepare folder SRC --out SUITE [--source NAME] [--up-axis auto|z|y]   a folder of one's own objects
    aw-prepare compose --out SUITE --partnet DIR ...                the paper's benchmark from datasets
    aw-prepare official PKG --out SUITE [--episodes DIR --runs RUNS]

Each subcommand is a ``register_*(subparsers)`` function in :data:`REGISTRARS`; it adds its
parser (with :func:`add_suite_options`) and sets ``func`` to a handler that turns its arguments
into :class:`~aw.prepare.ObjectSpec` lists and calls :func:`run_suite`. Adding a subcommand is
writing one such function and appending it to :data:`REGISTRARS`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from aw.cli.common import CliError, UsageError, add_commands, new_parser, plural, run_main
from aw.cli.suite import add_suite_options, check_unique_task_ids, run_suite
from aw.formats import FormatError
from aw.prepare import ObjectError, ObjectSpec, SuiteExistsError
from aw.progress import warnings_in_one_line
from aw.sources.folder import UP_AXES

__all__ = ["REGISTRARS", "add_suite_options", "run_suite", "build_parser", "main"]


# ---------------------------------------------------------------- synthetic
def register_synthetic(sub) -> None:
    p = sub.add_parser(
        "synthetic",
        help="the embedded procedural benchmark (four blocks)",
        description="Generate the procedural benchmark: PartNet-like furniture (none and image), "
        "IKEA-like furniture with manuals, AssemblyBench-like industrial assemblies with step "
        "diagrams, and two-fragment fractures.",
    )
    add_suite_options(p, protocol="native")
    p.add_argument("--per-source", type=int, default=20, metavar="N", help="objects per block (default 20)")
    p.add_argument(
        "--blocks",
        default=None,
        metavar="B1,B2",
        help="comma-separated subset of partnet, ikea_manual, assemblybench, fantastic_breaks (the default: all "
        "four), or of the refiners' benchmark families breaks_planar, breaks_noisy, breaks_eroded, breaks_pieces "
        "(built only when named)",
    )
    p.set_defaults(func=_cmd_synthetic)


def _cmd_synthetic(args: argparse.Namespace) -> int:
    from aw.sources.synthetic import BLOCKS, FAMILIES, plan

    if args.per_source < 1:
        raise UsageError("--per-source must be >= 1")
    known = {**BLOCKS, **FAMILIES}
    blocks = list(BLOCKS) if not args.blocks else [b.strip() for b in args.blocks.split(",") if b.strip()]
    unknown = [b for b in blocks if b not in known]
    if unknown or not blocks:
        raise UsageError(f"unknown block(s) {unknown}; choose from {', '.join(known)}")
    loader = "aw.sources.synthetic:generate_object"
    specs, sources, ids = [], [], []
    n = args.per_source
    for block in blocks:
        conds = known[block].conditions
        for i in range(n):
            donor_index = (i + 1) % n if n > 1 else 1
            donor = ObjectSpec(loader, (block, donor_index, args.seed))
            specs.append(ObjectSpec(loader, (block, i, args.seed), conds, donor))
            sources.append(block)
            ids.append((block, f"{plan(block, i, args.seed)[0]}_{i:03d}", conds))
    check_unique_task_ids(ids)
    return run_suite(
        args, specs, sources, name=f"synthetic-{args.per_source}-seed{args.seed}", generator="aw.sources.synthetic"
    )


# ---------------------------------------------------------------- folder
def register_folder(sub) -> None:
    p = sub.add_parser(
        "folder",
        help="a folder of assembled objects (one subfolder per object)",
        description="Import SRC/<object>/<part>.obj|ply|stl|glb|gltf|off (assembled frame) with an "
        "optional meta.json per object; see aw.sources.folder.",
    )
    p.add_argument("src", metavar="SRC", help="folder with one subfolder per object")
    add_suite_options(p, protocol="native")
    p.add_argument(
        "--source", default="custom", help="benchmark block name for objects whose meta.json has none (default custom)"
    )
    p.add_argument(
        "--up-axis",
        choices=UP_AXES,
        default="auto",
        help="which axis of the meshes points up, for objects whose meta.json has no up_axis: z, y (turned "
        "Z-up), or auto (default: Y where upright parts stand along Y and the object rests on them, else "
        "Z; the choice is printed per object; see docs/datasets.md)",
    )
    p.add_argument(
        "--allow-overlap",
        action="store_true",
        help="keep, with a warning, an object whose parts' bounding boxes mostly overlap (by default refused: "
        "parts saved each at its own origin; see docs/datasets.md)",
    )
    p.set_defaults(func=_cmd_folder)


def _cmd_folder(args: argparse.Namespace) -> int:
    import warnings

    from aw.assembly import piled_parts
    from aw.sources.folder import load_object, read_meta, scan_folder

    if not Path(args.src).is_dir():
        raise UsageError(f"SRC {args.src}: source folder not found")
    try:
        found = scan_folder(args.src)
    except FormatError as exc:  # SRC itself is unusable (no object folders, two objects with one id)
        raise UsageError(str(exc)) from None
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
        donor = ObjectSpec(loader, (found[donor_j].path, args.source, args.up_axis)) if donor_j is not None else None
        specs.append(ObjectSpec(loader, (f.path, args.source, args.up_axis), tuple(f.conditions), donor))
    check_unique_task_ids([(s, f.object_id, f.conditions) for s, f in zip(sources, found, strict=True)])
    # load every object once here: bad meshes and objects that cannot be assessed are reported
    # before any work is done, and the up axis chosen for each is said
    piles: list[str] = []
    for f in found:
        obj = load_object(f.path, args.source, args.up_axis)
        if obj.n_parts < 2:
            raise CliError(
                f"{f.path}: one part ({obj.parts[0].name}) cannot be assessed: the registration aligns "
                "any single part onto its target, so an agent that never moves scores PA 100%, SR 1; "
                "an object needs at least 2 parts"
            )
        up = obj.meta["up_axis"]
        print(f"{f.object_id}: up axis {up['axis'].upper()} ({up['how']})", file=sys.stderr)
        pile = piled_parts(obj)
        if pile is not None:
            piles.append(
                f"{f.path}: {pile.reason()}: each part is likely saved centred at its own origin, not where it "
                "sits in the assembled object, so the target would be a pile on one point"
            )
    if piles and not args.allow_overlap:
        more = f" (and {plural(len(piles) - 1, 'more object')})" if len(piles) > 1 else ""
        raise CliError(
            f"{piles[0]}{more}; export the parts in the assembled frame, or pass --allow-overlap if they truly nest"
        )
    for line in piles:
        warnings.warn(f"{line}; kept (--allow-overlap)", stacklevel=1)
    return run_suite(
        args, specs, sources, name=f"folder-{Path(args.src).resolve().name}", generator="aw.sources.folder"
    )


from aw.cli.compose import register_compose, register_official, register_official_export  # noqa: E402  (dataset sources, official import)

REGISTRARS: list[Callable] = [
    register_synthetic,
    register_folder,
    register_compose,
    register_official,
    register_official_export,
]


def build_parser() -> argparse.ArgumentParser:
    parser = new_parser(
        "aw-prepare",
        "Build AssemblyWorld task suites (SUITE/manifest.json, SUITE/tasks/<id>/, SUITE/targets/<id>.json).",
        epilog="Run 'aw-prepare COMMAND --help' for a command's options.",
    )
    sub = add_commands(parser)
    for register in REGISTRARS:
        register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    import warnings

    typed = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(typed)
    args.typed = typed  # as the user typed them: path errors say what to type instead

    def body() -> int:
        try:
            with warnings.catch_warnings():
                warnings.showwarning = warnings_in_one_line("aw-prepare")
                return args.func(args)
        except SuiteExistsError as exc:
            raise UsageError(str(exc)) from None
        except (FormatError, ObjectError) as exc:
            raise CliError(str(exc)) from None

    return run_main("aw-prepare", body)


if __name__ == "__main__":
    sys.exit(main())
