"""``aw-demo``: the whole loop of the paper on the embedded synthetic benchmark, in one command.

1. build the synthetic suite (``aw-prepare synthetic``);
2. run ``idle``, ``heuristic`` and the ``oracle`` at two noise levels on every task, each
   episode through its own ``aw-serve`` over MCP (parallel jobs = cores);
3. rescore every trajectory (``aw-score``);
4. print the Table-1-style summary with 95% intervals and where the report and plots are.

The oracle systems read the hidden targets: they are calibration upper bounds that give the
analyses a controlled spread, never results.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

DEFAULT_PER_SOURCE = 5
DEFAULT_NOISE = (0.5, 1.5)
QUICK_SCORE_ARGS = ("--final", "fast", "--bootstrap", "1000", "--permutations", "10000")


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
    out = [("idle", "idle", None), ("heuristic", "heuristic", None)]
    out += [(f"oracle-noise{n:g}", "oracle", n) for n in noise_levels]
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


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="aw-demo", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=Path("aw-demo"), help="working directory (default ./aw-demo)")
    p.add_argument("--per-source", type=int, default=DEFAULT_PER_SOURCE,
                   help=f"objects per benchmark source (default {DEFAULT_PER_SOURCE}; the paper's suite has 20)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="episodes in parallel (default: cores)")
    p.add_argument("--noise", type=float, nargs="+", default=list(DEFAULT_NOISE), help="oracle noise levels")
    p.add_argument("--blocks", help="comma-separated subset of the benchmark sources (default: all four)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--fresh", action="store_true", help="delete --out first (default: reuse what is there)")
    p.add_argument("--protocol", action="store_true",
                   help="score final states with the exact protocol and the paper's resample counts (aw-score's "
                        f"defaults); without it the demo passes aw-score {' '.join(QUICK_SCORE_ARGS)} to fit its time")
    args = p.parse_args(argv)
    if args.per_source < 1 or args.jobs < 1:
        p.error("--per-source and --jobs must be at least 1")
    if any(not (n >= 0) for n in args.noise):
        p.error("--noise levels must be >= 0")

    from aw.runner.batch import BatchConfig, run_batch

    t_all = time.monotonic()
    out = args.out.resolve()
    if args.fresh and out.exists():
        shutil.rmtree(out)
    suite, runs, report = out / "suite", out / "runs", out / "report"
    out.mkdir(parents=True, exist_ok=True)
    total = 4
    timings: dict[str, float] = {}

    _stage(1, total, f"building the synthetic suite ({args.per_source} objects per source) in {suite}")
    t0 = time.monotonic()
    recipe = out / ".suite-recipe"
    want = f"per_source={args.per_source} seed={args.seed} blocks={args.blocks or 'all'}"
    if (suite / "manifest.json").is_file() and recipe.is_file() and recipe.read_text() == want:
        print("  reusing the suite already there")
    else:
        cmd = _bin("aw-prepare") + ["synthetic", "--out", str(suite), "--per-source", str(args.per_source),
                                    "--seed", str(args.seed), "--jobs", str(args.jobs), "--force"]
        if args.blocks:
            cmd += ["--blocks", args.blocks]
        if runs.exists():  # runs of another suite must not be mixed in
            shutil.rmtree(runs)
        _run(cmd)
        recipe.write_text(want)
    timings["suite"] = time.monotonic() - t0

    sys_list = systems(tuple(args.noise))
    _stage(2, total, f"running {len(sys_list)} systems on every task through aw-serve (MCP over stdio), {args.jobs} at a time")
    t0 = time.monotonic()
    problems = []
    for label, agent, noise in sys_list:
        res = run_batch(BatchConfig(suite_dir=suite, system=label, out_dir=runs, agent=agent, noise=noise,
                                    jobs=args.jobs, seed=args.seed))
        bad = {k: v for k, v in res.endings().items() if k != "finished"}
        if bad:
            problems.append(f"{label}: {bad}")
    timings["episodes"] = time.monotonic() - t0
    if problems:
        print("  episodes that did not finish (recorded in their run.json):", "; ".join(problems))

    how = "the exact protocol for final states" if args.protocol else (
        "fast registration for checkpoints and final states, 1,000 bootstrap draws, 10,000 relabellings; "
        "--protocol for the paper's exact protocol")
    _stage(3, total, f"rescoring every checkpoint of every trajectory (aw-score: {how}) into {report}")
    t0 = time.monotonic()
    score_cmd = _bin("aw-score") + [str(suite), str(runs), "--out", str(report), "--jobs", str(args.jobs)]
    if not args.protocol:
        score_cmd += list(QUICK_SCORE_ARGS)
    _run(score_cmd)
    timings["scoring"] = time.monotonic() - t0

    _stage(4, total, "summary")
    report_md = report / "report.md"
    if report_md.is_file():
        print(summary_from_report(report_md))
    print("\noracle-* systems read the hidden targets: calibration upper bounds, never results.")
    print(f"\nreport: {report_md}")
    if (report / "report.html").is_file():
        print(f"report with pictures and 3D views (open in a browser): {report / 'report.html'}")
    plots = sorted(report.rglob("*.png"))
    if plots:
        print("plots:")
        for pl in plots:
            print(f"  {pl}")
    wall = time.monotonic() - t_all
    print(f"\ndone in {wall / 60:.1f} min (" + ", ".join(f"{k} {v:.0f} s" for k, v in timings.items()) + ")")
    return 0


if __name__ == "__main__":
    sys.exit(main())
