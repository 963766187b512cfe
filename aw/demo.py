"""aw-demo: the whole loop of the paper on the embedded synthetic benchmark, in one command.

    1. build the synthetic suite (aw-prepare synthetic): two objects per source by default,
       every source and condition; --full builds five per source (25 tasks);
    2. run idle, heuristic and the oracle at two noise levels on every task, each episode
       through its own aw-serve over MCP (--jobs at a time);
    3. rescore every trajectory (aw-score: final states by the protocol, exact registration);
    4. print the Table-1-style summary with 95% intervals and where the report and plots are.

The oracle systems read the hidden targets: they are calibration upper bounds that give the
analyses a controlled spread, never results.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

from aw.cli.common import (
    add_jobs,
    add_overwrite,
    check_out_dir,
    new_parser,
    nonnegative_float,
    plural,
    positive_int,
    run_main,
)
from aw.runner.batch import system_label

DEFAULT_PER_SOURCE = 1  # 5 tasks: every source and condition once (--per-source 2: intervals with a spread)
FULL_PER_SOURCE = 5  # --full: 25 tasks
DEFAULT_NOISE = (0.5, 1.5)
QUICK_DRAWS = ("--bootstrap", "1000", "--permutations", "10000")  # the paper: 10,000 and 100,000
# The whole demo (suite, episodes, scoring, report) on idle cores: a fixed part plus core-seconds
# per episode (its aw-serve with the renderer, and its share of scoring and of the report), fitted
# to `time aw-demo` on an idle 2-core machine: 1.5 minutes for the defaults (20 episodes), 3.4 for
# --per-source 2 (40), 6.7 for --full (100) (docs/agents.md).
FIXED_SECONDS = 13.0
SECONDS_PER_EPISODE_CORE = 7.8


def _bin(name: str) -> list[str]:
    beside = Path(sys.executable).with_name(name)
    if beside.is_file():
        return [str(beside)]
    found = shutil.which(name)
    if found:
        return [found]
    raise SystemExit(f"aw-demo: {name} not found beside {sys.executable} or on PATH; run scripts/install.sh")


def _stage(n: int, total: int, text: str) -> None:
    print(f"\n[{n}/{total}] {text}", flush=True)


def _run(cmd: list[str]) -> None:
    proc = subprocess.run(cmd)
    if proc.returncode != 0:
        raise SystemExit(f"aw-demo: {' '.join(cmd[:2])} ... failed with exit code {proc.returncode}")


def systems(noise_levels: tuple[float, ...]) -> list[tuple[str, str, float | None]]:
    """(label, agent, noise) of every demo system, in table order."""
    out: list[tuple[str, str, float | None]] = [("idle", "idle", None), ("heuristic", "heuristic", None)]
    out += [(system_label("oracle", None, {"noise": n}), "oracle", n) for n in noise_levels]
    return out


def summary_from_report(report_md: Path, wanted: tuple[str, ...] = ("Table 1:", "Table A-3:")) -> str:
    """The report's Table-1-style summary and its bootstrap-interval companion (sections whose
    heading starts with one of ``wanted``); else the first section that holds a table."""
    text = report_md.read_text()
    sections = [sec.strip() for sec in re.split(r"(?m)^(?=#{1,3} )", text)]
    picked = [sec for sec in sections if sec.lstrip("#").strip().startswith(wanted)]
    if picked:
        return "\n\n".join(picked)
    for sec in sections:
        if re.search(r"(?m)^\|.*\|\s*$", sec):
            return sec
    return text.strip()[:4000]


def expected_minutes(episodes: int, jobs: int) -> float:
    """About how long the demo takes on an idle machine with ``jobs`` cores."""
    return (FIXED_SECONDS + SECONDS_PER_EPISODE_CORE * episodes / jobs) / 60.0


def plan_line(per_source: int, blocks: str | None, noise_levels: tuple[float, ...], jobs: int) -> str:
    """What the demo is about to do and about how long it takes, said before it starts."""
    from aw.sources.synthetic import BLOCKS

    names = [b.strip() for b in blocks.split(",") if b.strip() in BLOCKS] if blocks else list(BLOCKS)
    n_tasks = per_source * sum(len(BLOCKS[b].conditions) for b in names)
    n_systems = len(systems(noise_levels))
    episodes = n_tasks * n_systems
    minutes = expected_minutes(episodes, jobs)
    took = "about a minute" if minutes < 1.5 else f"about {round(minutes)} minutes"
    return (
        f"aw-demo: builds a synthetic suite of {plural(n_tasks, 'task')}, runs {plural(n_systems, 'system')} on "
        f"every task ({plural(episodes, 'episode')} through aw-serve, {jobs} at a time), rescores every "
        f"trajectory with aw-score and writes the report; expect {took} on {plural(jobs, 'idle core')}, "
        "longer when other work shares the cores"
    )


def build_parser() -> argparse.ArgumentParser:
    p = new_parser(
        "aw-demo",
        "The whole loop of the paper on the embedded synthetic benchmark, in one command.",
        epilog=__doc__.split("\n\n")[1] + "\n\nThe oracle systems read the hidden targets: calibration "
        "upper bounds, never results. A second call reuses the suite and every finished episode.",
    )
    p.add_argument(
        "--out", type=Path, default=Path("aw-demo"), metavar="DIR", help="working directory (default ./aw-demo)"
    )
    size = p.add_mutually_exclusive_group()
    size.add_argument(
        "--per-source",
        type=positive_int("--per-source"),
        metavar="N",
        help=f"objects per benchmark source (default {DEFAULT_PER_SOURCE}; --full: {FULL_PER_SOURCE}; the paper's "
        "suite has 20)",
    )
    size.add_argument(
        "--full",
        action="store_true",
        help=f"the larger demo: {FULL_PER_SOURCE} objects per source (25 tasks, 100 episodes)",
    )
    add_jobs(p, "objects prepared, episodes and scoring workers")
    p.add_argument(
        "--noise",
        type=nonnegative_float("--noise"),
        nargs="+",
        default=list(DEFAULT_NOISE),
        metavar="LEVEL",
        help="oracle noise levels, one oracle system each (default " + " ".join(f"{n:g}" for n in DEFAULT_NOISE) + ")",
    )
    p.add_argument(
        "--blocks", metavar="B1,B2", help="comma-separated subset of the benchmark sources (default: all four)"
    )
    p.add_argument("--seed", type=int, default=0, metavar="S", help="suite generation and agent seed (default 0)")
    add_overwrite(p, "the suite, runs and report in --out (default: reuse the suite and the finished episodes)")
    p.add_argument(
        "--paper-draws",
        action="store_true",
        help="intervals and tests from the paper's 10,000 bootstrap draws and 100,000 relabellings "
        "(default: 1,000 and 10,000, to fit the demo's time; the scores themselves are the protocol's either way)",
    )
    return p


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line, with ``per_source`` resolved (``--per-source``, else ``--full``'s or the default)."""
    args = build_parser().parse_args(argv)
    if args.per_source is None:
        args.per_source = FULL_PER_SOURCE if args.full else DEFAULT_PER_SOURCE
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    return run_main("aw-demo", lambda: _demo(args))


def _demo(args: argparse.Namespace) -> int:
    from aw.runner.batch import BatchConfig, run_batch

    check_out_dir(args.out)
    print(plan_line(args.per_source, args.blocks, tuple(args.noise), args.jobs), flush=True)
    t_all = time.monotonic()
    out = args.out.resolve()
    suite, runs, report = out / "suite", out / "runs", out / "report"
    if args.overwrite:  # the demo's own outputs only: --out may be a folder with other things in it
        for own in (suite, runs, report):
            shutil.rmtree(own, ignore_errors=True)
        (out / ".suite-recipe").unlink(missing_ok=True)
    out.mkdir(parents=True, exist_ok=True)
    total = 4
    timings: dict[str, float] = {}

    _stage(1, total, f"building the synthetic suite ({plural(args.per_source, 'object')} per source) in {suite}")
    t0 = time.monotonic()
    recipe = out / ".suite-recipe"
    want = f"per_source={args.per_source} seed={args.seed} blocks={args.blocks or 'all'}"
    if (suite / "manifest.json").is_file() and recipe.is_file() and recipe.read_text() == want:
        print("  reusing the suite already there")
    else:
        cmd = _bin("aw-prepare") + [
            "synthetic",
            "--out",
            str(suite),
            "--per-source",
            str(args.per_source),
            "--seed",
            str(args.seed),
            "--jobs",
            str(args.jobs),
            "--overwrite",
        ]
        if args.blocks:
            cmd += ["--blocks", args.blocks]
        if runs.exists():  # runs of another suite must not be mixed in
            shutil.rmtree(runs)
        _run(cmd)
        recipe.write_text(want)
    timings["suite"] = time.monotonic() - t0
    print(f"  suite ready ({timings['suite']:.0f} s)", flush=True)

    sys_list = systems(tuple(args.noise))
    _stage(
        2,
        total,
        f"running {len(sys_list)} systems on every task through aw-serve (MCP over stdio), {args.jobs} at a time",
    )
    t0 = time.monotonic()
    problems = []
    for label, agent, noise in sys_list:
        t_system = time.monotonic()
        res = run_batch(
            BatchConfig(
                suite_dir=suite, system=label, out_dir=runs, agent=agent, noise=noise, jobs=args.jobs, seed=args.seed
            )
        )
        endings = ", ".join(f"{k} {v}" for k, v in sorted(res.endings().items())) or "nothing to run"
        reused = f", {len(res.skipped)} reused" if res.skipped else ""
        print(f"  {label}: {endings}{reused} ({time.monotonic() - t_system:.0f} s)", flush=True)
        bad = {k: v for k, v in res.endings().items() if k != "finished"}
        if bad:
            problems.append(f"{label}: {bad}")
    timings["episodes"] = time.monotonic() - t0
    if problems:
        print("  episodes that did not finish (recorded in their run.json):", "; ".join(problems))

    draws = (
        "the paper's 10,000 bootstrap draws" if args.paper_draws else "1,000 bootstrap draws (--paper-draws: 10,000)"
    )
    _stage(
        3,
        total,
        f"rescoring every checkpoint of every trajectory (aw-score: final states by the protocol, exact "
        f"registration; intervals from {draws}) into {report}",
    )
    t0 = time.monotonic()
    score_cmd = _bin("aw-score") + [
        str(suite),
        str(runs),
        "--out",
        str(report),
        "--jobs",
        str(args.jobs),
        "--final-mode",
        "exact",
    ]
    if not args.paper_draws:
        score_cmd += list(QUICK_DRAWS)
    _run(score_cmd)
    timings["scoring"] = time.monotonic() - t0
    print(f"  scored and reported in {timings['scoring']:.0f} s", flush=True)

    _stage(4, total, "summary")
    report_md = report / "report.md"
    if report_md.is_file():
        print(summary_from_report(report_md))
    print(f"\nscores: final states by the paper's protocol (exact registration); intervals from {draws}.")
    if args.per_source == 1:
        print(
            "one object per source: the bootstrap resamples objects within a source, so the intervals "
            "have no width here; --per-source 2 (about 3.5 minutes) or --full gives intervals worth reading."
        )
    print("\noracle-* systems read the hidden targets: calibration upper bounds, never results.")
    print(f"\nreport: {report_md}")
    if (report / "report.html").is_file():
        print(f"report with pictures and 3D views (open in a browser): {report / 'report.html'}")
    plots = sorted(report.rglob("*.png"))
    if plots:
        print("plots:")
        for pl in plots:
            print(f"  {pl}")
    print(f"\nwatch the episodes in a browser (live while a batch runs; --suite adds scores): aw-view {runs}")
    wall = time.monotonic() - t_all
    print(f"\ndone in {wall / 60:.1f} min (" + ", ".join(f"{k} {v:.0f} s" for k, v in timings.items()) + ")")
    return 0


if __name__ == "__main__":
    sys.exit(main())
