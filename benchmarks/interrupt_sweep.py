"""A seeded sweep of interrupts over a real ``aw-score``: SIGINT, SIGTERM and SIGHUP at random
moments of a study (starting up, loading geometry, inside the compiled ICP, in the analyses,
writing the report), under ``--jobs 1``, ``--jobs 2`` and a Dask local cluster::

    .venv/bin/python benchmarks/interrupt_sweep.py --out OUT [--trials 24] [--seed 0] [--html] [--dask]

Each trial starts from a finished report of the same study (its cache removed in every other
trial, so that the call scores again) and signals aw-score after a seeded delay, the way a user
would: SIGINT and SIGHUP to the whole process group (a terminal's Ctrl-C, a closed terminal),
SIGTERM to aw-score alone (``kill PID``). A trial passes when aw-score

- exits ``128 + signal`` with every output (report.md, report.html and report_files/, scores.json,
  the CSVs, plots/) byte-identical to before, or with complete outputs (the signal came while they
  were being moved into place, after they were all written), or exits 0 (it had finished);
- prints no traceback and no "leaked semaphore" warning, leaves no temporary file or staging
  folder, and leaves no worker process behind.

``tests/aw_eval/test_score_interrupts.py`` runs a few trials of the same sweep.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

OUTPUTS = ("scores.json", "tasks.csv", "checkpoints.csv", "report.md", "report.html", "plots", "report_files")
FAST = [
    "--checkpoint-mode",  # every checkpoint registered exactly: scoring is mostly the compiled ICP
    "exact",
    "--protocol-setting",
    "n_surface=256",
    "--protocol-setting",
    "n_fps=64",
    "--bootstrap",
    "200",
    "--permutations",
    "500",
    "--no-progress",
]
SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
_TIMELESS = ("tasks.csv", "checkpoints.csv")  # outputs that hold no time of their own
SCORING_LINE = "aw-score: scoring "  # said when the scoring of runs starts
SCORED_LINE = " system x "  # said when it ended ("1 system x 5 tasks: ...")


def make_study(root: Path, n_parts: tuple[int, ...] = (4, 5)) -> tuple[Path, Path]:
    """A small box suite and one system's scripted runs of every task."""
    from aw.formats import read_manifest
    from aw_eval.study.fixtures import box_suite, write_scripted_run

    suite = box_suite(root / "suite", objects_per_source=1, n_parts=list(n_parts))
    for t in [e.task_id for e in read_manifest(suite).tasks]:
        write_scripted_run(root / "runs" / "alpha" / t, suite, t, system="alpha", jitter_edits=20)
    return suite, root / "runs"


def _alive(pid: int, started: float) -> bool:
    """Whether the process ``pid`` that started at ``started`` still runs (not a zombie)."""
    try:
        p = psutil.Process(pid)
        return p.create_time() == started and p.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def snapshot(out: Path) -> dict[str, str]:
    """``relative path -> sha256`` of every output file (the cache and the lock file are not outputs)."""
    files = {}
    for name in OUTPUTS:
        p = out / name
        for f in [p] if p.is_file() else sorted(p.rglob("*")) if p.is_dir() else []:
            if f.is_file():
                files[str(f.relative_to(out))] = hashlib.sha256(f.read_bytes()).hexdigest()
    return files


def leftovers(out: Path) -> list[str]:
    """Temporary files and staging folders anywhere under ``out``."""
    return sorted(
        str(p.relative_to(out))
        for p in out.rglob("*")
        if ".tmp" in p.name or p.name.startswith((".report-", ".published-"))
    )


def numbers(out: Path) -> list[tuple] | None:
    """Each run's status and scores from scores.json (None when it cannot be read)."""
    try:
        doc = json.loads((out / "scores.json").read_text())
    except (OSError, ValueError):
        return None
    return [(r["system"], r["task_id"], r["status"], r["pa"], r["sr"], r["scd"]) for r in doc["runs"]] + [
        ("partial", doc["partial"])
    ]


@dataclass
class Sweep:
    """The study, the options of every call, and the finished report trials start from."""

    suite: Path
    runs: Path
    work: Path
    options: tuple[str, ...]
    code: Path = ROOT  # the checkout whose aw-score runs
    baseline: Path | None = None
    reference: list[tuple] | None = None
    seconds: float = 0.0  # how long a full call took (cache removed)
    scoring_seconds: float = 0.0  # of which the scoring of runs, from SCORING_LINE to SCORED_LINE

    def popen(self, out: Path, extra: list[str]) -> subprocess.Popen:
        env = {**os.environ, "PYTHONPATH": str(self.code)}
        return subprocess.Popen(
            [sys.executable, "-m", "aw_eval.cli", str(self.suite), str(self.runs), "--out", str(out), *self.options]
            + extra,
            env=env,
            cwd=self.code,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,  # its own process group, as a terminal's foreground job
            # SIGINT as in a terminal: a background job would start with it ignored
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )

    def prepare(self) -> None:
        """The finished report every trial starts from, and how long a full call and its scoring take."""
        self.baseline = self.work / "baseline"
        t0 = time.perf_counter()
        proc = self.popen(self.baseline, ["--jobs", "1"])
        assert proc.stderr is not None
        said = [(time.perf_counter(), line) for line in proc.stderr]
        if proc.wait() != 0:
            raise RuntimeError(f"the baseline call failed ({proc.returncode}): {''.join(x for _, x in said)[-2000:]}")
        self.seconds = time.perf_counter() - t0
        start = next(t for t, line in said if SCORING_LINE in line)
        self.scoring_seconds = next(t for t, line in said if SCORED_LINE in line) - start
        self.reference = numbers(self.baseline)

    def trial(self, index: int, point: Point) -> dict:
        """One interrupted call on a copy of the baseline report; what it did, and whether that passes."""
        assert self.baseline is not None
        sig, delay, extra, fresh, anchor = (
            point.signal,
            point.delay * (self.scoring_seconds if point.anchor else self.seconds),
            list(point.options),
            point.fresh_cache,
            point.anchor,
        )
        out = self.work / f"trial-{index}"
        shutil.copytree(self.baseline, out)
        if fresh:
            shutil.rmtree(out / "cache" / "runs", ignore_errors=True)
        before = snapshot(out)
        proc = self.popen(out, extra)
        lines: list[str] = []
        seen = threading.Event()

        def read() -> None:
            assert proc.stderr is not None
            for line in proc.stderr:
                lines.append(line)
                if anchor is None or anchor in line:
                    seen.set()
            seen.set()

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        family: dict[int, float] = {}  # pid -> start time: a pid the system reuses is not a survivor
        while not seen.is_set() and proc.poll() is None:  # the anchor line, or the start
            seen.wait(0.02)
        deadline = time.monotonic() + delay
        while time.monotonic() < deadline and proc.poll() is None:
            try:  # every process of the call, to check that none outlives it
                family |= {c.pid: c.create_time() for c in psutil.Process(proc.pid).children(recursive=True)}
            except psutil.Error:
                pass
            time.sleep(0.02)
        sent = proc.poll() is None
        t_sig = time.perf_counter()
        if sent:
            if sig == signal.SIGTERM:
                proc.send_signal(sig)  # kill PID: aw-score alone
            else:
                os.killpg(proc.pid, sig)  # Ctrl-C, a closed terminal: the whole foreground group
        try:
            proc.wait(timeout=600)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        seconds = time.perf_counter() - t_sig
        reader.join(10)
        err = "".join(lines)
        time.sleep(0.5)
        survivors = [pid for pid, started in family.items() if _alive(pid, started)]
        after = snapshot(out)
        # complete outputs of the same study: the same numbers, and the same bytes where no time is recorded
        complete = numbers(out) == self.reference and all(after.get(f) == before.get(f) for f in _TIMELESS)
        if proc.returncode == 0:
            outcome = "finished before the signal" if not sent else "finished (the signal came after the outputs)"
            ok = complete
        elif proc.returncode in (128 + sig, -sig):  # -sig: ended by the signal itself (the shell's 128 + sig)
            if after == before:
                outcome, ok = "stopped, outputs byte-identical", True
            else:
                outcome, ok = "stopped after the outputs were moved into place", complete
        else:
            outcome, ok = f"exit {proc.returncode}", False
        problems = []
        if "Traceback" in err:
            problems.append("traceback")
        if "leaked" in err:
            problems.append("leaked semaphore warning")
        if leftovers(out):
            problems.append(f"left {leftovers(out)}")
        if survivors:
            problems.append(f"{len(survivors)} processes survived")
        shutil.rmtree(out, ignore_errors=True)
        return {
            "trial": index,
            "signal": sig.name,
            "options": " ".join(extra),
            "cache": "removed" if fresh else "kept",
            "delay_s": round(delay, 2),
            "after": f"the line {anchor!r}" if anchor else "the start",
            "exit": proc.returncode,
            "seconds_to_exit": round(seconds, 2) if sent else None,
            "outcome": outcome,
            "problems": problems,
            "ok": ok and not problems,
            **({"stderr_tail": err[-1500:]} if not (ok and not problems) else {}),
        }


@dataclass(frozen=True)
class Point:
    """One interrupt point: ``signal`` after the ``anchor`` line (that scoring starts) or the start,
    ``delay`` of the way (0 to 1) through the scoring or the whole call as the baseline took."""

    signal: signal.Signals
    delay: float
    options: tuple[str, ...]
    fresh_cache: bool
    anchor: str | None


def plan(n: int, seed: int, variants: list[list[str]]) -> list[Point]:
    """``n`` interrupt points: signals and option sets in turn (each pair in every nine, with three
    option sets); in every four calls, three score
    again (their cache removed) and two of them are signalled during the scoring of runs (in the
    compiled ICP, most likely); the others at any moment of a whole call."""
    rng = random.Random(seed)
    out = []
    for i in range(n):
        fresh = i % 4 != 2
        anchor = SCORING_LINE if i % 4 in (0, 3) else None
        delay = rng.uniform(0.0, 1.0)
        variant = variants[(i + i // len(SIGNALS)) % len(variants)]  # every signal meets every option set
        out.append(Point(SIGNALS[i % len(SIGNALS)], delay, tuple(variant), fresh, anchor))
    return out


def main() -> None:
    from benchmarks._output import output_file

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="folder for interrupt_sweep.json")
    ap.add_argument("--trials", type=int, default=24, help="interrupt points (default 24)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the delays (default 0)")
    ap.add_argument("--html", action="store_true", help="also write report.html (slower calls)")
    ap.add_argument("--dask", action="store_true", help="add a Dask local cluster to the option sets")
    ap.add_argument(
        "--code", default=str(ROOT), help="the checkout whose aw-score runs (default this one; e.g. a git archive)"
    )
    args = ap.parse_args()
    target = output_file(args.out, "interrupt_sweep.json")
    work = Path(tempfile.mkdtemp(prefix="aw-interrupts-"))
    cluster = None
    try:
        suite, runs = make_study(work / "study")
        opts = tuple(FAST + ([] if args.html else ["--no-html"]))
        sweep = Sweep(suite, runs, work, opts, Path(args.code).resolve())
        sweep.prepare()
        variants = [["--jobs", "1"], ["--jobs", "2"]]
        if args.dask:
            from distributed import LocalCluster

            cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None)
            variants.append(["--scheduler", cluster.scheduler_address])
        rows = []
        for i, pt in enumerate(plan(args.trials, args.seed, variants)):
            row = sweep.trial(i, pt)
            rows.append(row)
            print(json.dumps({k: v for k, v in row.items() if k != "stderr_tail"}), flush=True)
        outcomes: dict[str, int] = {}
        for r in rows:
            outcomes[r["outcome"]] = outcomes.get(r["outcome"], 0) + 1
        exits = [r["seconds_to_exit"] for r in rows if r["seconds_to_exit"] is not None]
        doc = {
            "command": " ".join(["benchmarks/interrupt_sweep.py", *sys.argv[1:]]),
            "code": str(Path(args.code).resolve()),
            "study": "5 box tasks of 4 and 5 parts, 1 system, 20 jitter edits each, exact final states and "
            "checkpoints, protocol overrides n_surface=256 n_fps=64",
            "load": os.getloadavg(),
            "full_call_seconds": round(sweep.seconds, 2),
            "scoring_seconds": round(sweep.scoring_seconds, 2),
            "trials": len(rows),
            "passed": sum(r["ok"] for r in rows),
            "outcomes": outcomes,
            "seconds_to_exit_max": max(exits) if exits else None,
            "seconds_to_exit_median": sorted(exits)[len(exits) // 2] if exits else None,
            "rows": rows,
        }
        target.write_text(json.dumps(doc, indent=1) + "\n")
        print(f"wrote {target}: {doc['passed']} of {doc['trials']} trials passed; {outcomes}")
    finally:
        if cluster is not None:
            cluster.close()
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
