"""``aw-prepare compose`` (the paper's benchmark from the datasets a user holds) and
``aw-prepare official`` (an official package + episode archives -> scoring suite + runs) and
``aw-prepare official-export`` (a recorded run -> an official episode archive).

Registered in :data:`aw.cli.prepare.REGISTRARS`.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from aw.cli.common import add_overwrite, plural

__all__ = ["register_compose", "register_official", "register_official_export", "catalogs_from_args"]


def register_compose(sub) -> None:
    p = sub.add_parser(
        "compose",
        help="sample the benchmark from the published datasets (Section 3.3, Appendix A.1)",
        description="Sample --per-source objects from each given dataset with part-count stratification (2-5, 6-10, "
        "11-20 parts) and category coverage (Fantastic Breaks by category only), seeded, and build their tasks: "
        "PartNet twice (none and image), IKEA-Manual and AssemblyBench with their manuals, Fantastic Breaks without "
        "reference. The selection is written to OUT/composition.json.",
    )
    from aw.cli.suite import add_suite_options

    add_suite_options(p)
    p.add_argument("--partnet", metavar="DIR", help="PartNet assembly data (DGL/Manual-PA prepare_data folder)")
    p.add_argument(
        "--partnet-level", type=int, default=3, help="PartNet hierarchy level of shape_data files (default 3)"
    )
    p.add_argument("--partnet-split", default="test", help="split lists to read, <Category>.<split>.npy (default test)")
    p.add_argument(
        "--partnet-categories", default=None, metavar="C1,C2", help="PartNet categories (default: every split list)"
    )
    p.add_argument(
        "--ikea-manual", metavar="DIR", help="IKEA-Manual dataset folder (main_data.json, parts/, manual pages)"
    )
    p.add_argument("--assemblybench", metavar="DIR", help="AssemblyBench folder (<category>/<object>/)")
    p.add_argument("--fantastic-breaks", metavar="DIR", help="Fantastic Breaks folder (<class>/<object>/model_*.ply)")
    p.add_argument("--breaking-bad", metavar="DIR_OR_H5", help="Breaking Bad folder or HDF5 file (source breaking_bad)")
    p.add_argument(
        "--rehosted",
        metavar="PATH",
        action="append",
        default=[],
        help="official re-hosted download (.parquet/.arrow file or folder); rows join the catalog of their source; repeatable",
    )
    p.add_argument("--per-source", type=int, default=20, metavar="N", help="objects per source (default 20)")
    p.add_argument("--dry-run", action="store_true", help="print the selection and stop")
    p.set_defaults(func=_cmd_compose)


def catalogs_from_args(args: argparse.Namespace) -> dict:
    """Catalogs per source from the dataset options given."""
    from aw.sources import assemblybench, breaking_bad, fantastic_breaks, ikea_manual, partnet, rehosted

    cats: dict[str, list] = {}

    def add(entries):
        for e in entries:
            cats.setdefault(e.source, []).append(e)

    if args.partnet:
        want = [c.strip().lower() for c in args.partnet_categories.split(",")] if args.partnet_categories else None
        add(partnet.catalog(args.partnet, args.partnet_level, args.partnet_split, want))
    if args.ikea_manual:
        add(ikea_manual.catalog(args.ikea_manual))
    if args.assemblybench:
        add(assemblybench.catalog(args.assemblybench))
    if args.fantastic_breaks:
        add(fantastic_breaks.catalog(args.fantastic_breaks))
    if args.breaking_bad:
        bb = Path(args.breaking_bad)
        add(breaking_bad.hdf5_catalog(bb) if bb.is_file() else breaking_bad.catalog(bb))
    for path in args.rehosted:
        add(rehosted.catalog(path))
    return cats


def _cmd_compose(args: argparse.Namespace) -> int:
    from aw.cli.common import CliError, UsageError
    from aw.cli.suite import run_suite
    from aw.formats import FormatError
    from aw.sources.compose import compose, specs_for

    if args.per_source < 1:
        raise UsageError("--per-source must be >= 1")
    given = {
        "--partnet": args.partnet,
        "--ikea-manual": args.ikea_manual,
        "--assemblybench": args.assemblybench,
        "--fantastic-breaks": args.fantastic_breaks,
        "--breaking-bad": args.breaking_bad,
        **{f"--rehosted {p}": p for p in args.rehosted},
    }
    for flag, path in given.items():
        if path and not Path(path).exists():  # a usage error, said before any work
            raise UsageError(f"{flag.split()[0]} {path}: no such file or directory")
    try:
        cats = catalogs_from_args(args)
    except FormatError as exc:  # a dataset whose files cannot be read: a failure naming the file
        raise CliError(str(exc)) from None
    if not cats:
        raise UsageError(
            "no dataset given: pass at least one of --partnet, --ikea-manual, --assemblybench, "
            "--fantastic-breaks, --breaking-bad, --rehosted"
        )
    try:
        comp = compose(cats, args.per_source, args.seed)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    summary = comp.summary()
    for source, s in summary["sources"].items():
        print(
            f"{source}: {len(s['objects'])} of {plural(s['candidates'], 'candidate')}; bands {s['bands']}; "
            f"categories {s['categories']}; conditions {', '.join(s['conditions'])}"
        )
    if args.dry_run:
        print(json.dumps(summary, indent=2))
        return 0
    specs, sources = specs_for(comp)
    if not specs:
        raise CliError("no eligible objects (2 to 20 parts) in the given datasets")
    code = run_suite(
        args, specs, sources, name=f"benchmark-{args.per_source}-seed{args.seed}", generator="aw.sources.compose"
    )
    (Path(args.out) / "composition.json").write_text(json.dumps(summary, indent=2) + "\n")
    return code


def register_official(sub) -> None:
    p = sub.add_parser(
        "official",
        help="convert an official AssemblyWorldBench package and episode archives for aw-score",
        description="Write a scoring suite (manifest, targets, eval_points/ with the official 1000 points per part) "
        "and RUNS/<system>/<task>/ trajectories with every recorded state of each final.episode.zip.",
    )
    p.add_argument(
        "package",
        metavar="PKG",
        help="official benchmark package folder (benchmark.json, <block>/.../config.json, cache/<slug>/evaluation.json)",
    )
    p.add_argument(
        "--episodes",
        metavar="DIR",
        default=None,
        help="folder searched for *.episode.zip archives (a run log, or <block>/<slug>.episode.zip); "
        "the suite then holds only the samples they attempted, so a partly downloaded package will do",
    )
    p.add_argument("--out", required=True, metavar="SUITE", help="scoring suite to write")
    p.add_argument("--runs", metavar="RUNS", default=None, help="runs folder to write (needed with --episodes)")
    p.add_argument(
        "--system", default=None, help="system label for every archive (default: the run folder of each archive)"
    )
    add_overwrite(p, "an existing suite in --out and runs in --runs")
    p.set_defaults(func=_cmd_official)


def _cmd_official(args: argparse.Namespace) -> int:
    from aw.cli.common import UsageError, check_in_dir, check_out_dir
    from aw.official.convert import convert, convert_package

    if not (check_in_dir(args.package, "PKG") / "benchmark.json").is_file():
        raise UsageError(f"PKG {args.package}: benchmark.json not found (is this an official benchmark package?)")
    if args.episodes is not None:
        check_in_dir(args.episodes, "--episodes")
    check_out_dir(args.out)
    if args.episodes is not None and not args.runs:
        raise UsageError("--episodes needs --runs")
    if args.runs:
        check_out_dir(args.runs, "--runs")

    try:
        if args.episodes is None:
            manifest = convert_package(args.package, args.out, force=args.overwrite)
            runs: list[Path] = []
        else:
            skipped: list[str] = []
            manifest, runs = convert(
                args.package,
                args.episodes,
                args.out,
                args.runs,
                system=args.system,
                force=args.overwrite,
                skipped=skipped,
            )
            for line in skipped:
                print(f"aw-prepare: not converted (the official scorer counts it as an error): {line}", file=sys.stderr)
    except FileExistsError as exc:
        raise UsageError(str(exc).replace("pass force=True", "pass --overwrite")) from None
    print(
        f"wrote {plural(len(manifest.tasks), 'task')} to {args.out}"
        + (f" and {plural(len(runs), 'run')} to {args.runs}" if runs else "")
    )
    return 0


def register_official_export(sub) -> None:
    p = sub.add_parser(
        "official-export",
        help="write a recorded run as an official episode archive (final.episode.zip)",
        description="Export RUN_DIR (trajectory.jsonl, final.json) as a 3DWebAgent episode archive continuing the task's "
        "initial archive: SUITE/official/<task>.episode.zip for tasks converted from the official package, else one made "
        "from SUITE/tasks/<task>/ meshes; or the archive given with --initial.",
    )
    p.add_argument("run", metavar="RUN_DIR", help="a run folder written by aw-serve / aw-run")
    p.add_argument("--out", required=True, metavar="FILE", help="archive to write (e.g. final.episode.zip)")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--suite", metavar="SUITE", help="the suite the run was recorded on")
    where.add_argument("--initial", metavar="ARCHIVE", help="the initial (setup) episode archive the run started from")
    add_overwrite(p, "an existing archive at --out")
    p.add_argument(
        "--trust-final",
        action="store_true",
        help="export a run whose closing state (final.json, the end record) contradicts its calls, as recorded "
        "(default: refuse it, as aw-score flags it and scores the calls' state)",
    )
    p.set_defaults(func=_cmd_official_export)


def _cmd_official_export(args: argparse.Namespace) -> int:
    from aw.cli.common import CliError, UsageError
    from aw.cli.paths import check_paths
    from aw.formats import read_trajectory
    from aw.formats.suite import suite_paths
    from aw.official.convert import initial_archive_path
    from aw.official.export import export_run, export_task_run

    check_paths("aw-prepare", args.typed, [(args.run, "run"), (args.suite, "suite")])
    if Path(args.out).exists() and not args.overwrite:
        raise UsageError(f"--out {args.out}: already exists; pass --overwrite to replace it")
    gap = _closing_contradiction(Path(args.run))
    if args.initial:
        ep = export_run(args.run, args.initial, args.out, args.trust_final)
    else:
        task_id = read_trajectory(Path(args.run) / "trajectory.jsonl").header.task_id
        initial = initial_archive_path(args.suite, task_id)
        task_dir = suite_paths(args.suite, task_id)[0]
        if initial.is_file():
            ep = export_run(args.run, initial, args.out, args.trust_final)
        elif task_dir.is_dir():
            ep = export_task_run(args.run, task_dir, args.out, args.trust_final)
        else:
            raise CliError(f"{args.suite}: neither {initial} nor {task_dir} exists for task {task_id!r}")
    print(
        f"wrote {args.out}: {plural(len(ep.calls), 'call')}, {plural(len(ep.states), 'state')}, final state {ep.final_state().index}"
    )
    if gap:  # exported with --trust-final (export refuses it otherwise)
        print(
            f"aw-prepare: warning: {args.run}: the closing state contradicts the calls (parts {gap}); exported as "
            "recorded (--trust-final): the official scorer scores a state that aw-score does not",
            file=sys.stderr,
        )
    return 0


def _closing_contradiction(run_dir: Path) -> list[str]:
    """The parts whose closing pose contradicts the run's calls ([] if unreadable: export says why)."""
    from aw.formats import FormatError, read_final, read_trajectory
    from aw.formats.agreement import closing_contradiction

    try:
        traj = read_trajectory(run_dir / "trajectory.jsonl")
        final = read_final(run_dir / "final.json").poses if (run_dir / "final.json").is_file() else None
        return closing_contradiction(traj, final)
    except (FormatError, KeyError, OSError):
        return []
