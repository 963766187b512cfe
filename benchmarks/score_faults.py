"""aw-score under faults, as real processes: SIGKILL / SIGTERM / SIGINT while two workers score
(how long until aw-score and its workers are gone), two aw-score on one --out, and a full disk
(a small tmpfs as --out; needs root, else skipped)::

    .venv/bin/python benchmarks/score_faults.py --out OUT [--baseline DIR]

``--baseline DIR`` runs the same trials with the code of another checkout (e.g. ``git archive
<commit> | tar -x -C DIR``) in the same call, so the two sets of figures share inputs and machine.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aw.formats import read_manifest  # noqa: E402
from aw_eval.study.fixtures import box_suite, write_scripted_run  # noqa: E402
from benchmarks._output import output_file  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
WAIT = 180  # seconds a signalled aw-score is given to exit
OPTS = ["--no-progress", "--no-plots", "--no-html", "--bootstrap", "200", "--permutations", "500"]


def _study(root: Path) -> tuple[Path, Path]:
    suite = box_suite(root / "suite", objects_per_source=2, n_parts=[6, 8])
    for t in [e.task_id for e in read_manifest(suite).tasks]:
        write_scripted_run(root / "runs" / "alpha" / t, suite, t, system="alpha", jitter_edits=30)
    return suite, root / "runs"


def _popen(code: Path, study, out: Path, *extra: str, **kw) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(code)}
    # SIGINT as in a terminal: a shell starts background jobs with SIGINT ignored, and Python keeps that
    return subprocess.Popen(
        [sys.executable, "-m", "aw_eval.cli", str(study[0]), str(study[1]), "--out", str(out), *OPTS, *extra],
        env=env,
        cwd=code,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        **kw,
    )


def kill_trial(code: Path, study, out: Path, sig: signal.Signals) -> dict:
    """Signal aw-score once both workers run; seconds until it exits and until its workers are gone."""
    proc = _popen(code, study, out, "--jobs", "2", "--checkpoint-mode", "exact")
    parent = psutil.Process(proc.pid)
    workers: list[psutil.Process] = []
    while len(workers) < 2 and proc.poll() is None:
        time.sleep(0.1)
        workers = [c for c in parent.children(recursive=True) if "spawn_main" in " ".join(c.cmdline())]
    time.sleep(5)  # let them start scoring
    t0 = time.perf_counter()
    proc.send_signal(sig)
    try:
        code_ = proc.wait(timeout=WAIT)
    except subprocess.TimeoutExpired:  # before the fixes, Ctrl-C waited for the running tasks
        proc.kill()
        code_ = f"still running {WAIT} s later (killed)"
    exited = time.perf_counter() - t0
    gone, alive = psutil.wait_procs(workers, timeout=90 if isinstance(code_, int) else 1)
    workers_gone = time.perf_counter() - t0 if not alive else None
    for w in alive:
        w.kill()
    err = proc.stderr.read()
    proc.stderr.close()
    return {
        "signal": sig.name,
        "exit": code_,
        "seconds_to_exit": round(exited, 2),
        "seconds_until_workers_gone": None if workers_gone is None else round(workers_gone, 2),
        "workers_alive_90_s_later": len(alive),
        "traceback": "Traceback" in err,
        **({"stderr_tail": err[-2000:]} if "Traceback" in err else {}),
    }


def lock_trial(code: Path, study, out: Path) -> dict:
    first = _popen(code, study, out, "--jobs", "1", "--final-only")
    time.sleep(8)
    second = _popen(code, study, out, "--jobs", "1", "--final-only")
    err2 = second.communicate()[1]
    first.wait()
    first.stderr.close()
    return {"second_exit": second.returncode, "second_said": err2.strip().splitlines()[-1] if err2.strip() else ""}


def disk_full_trial(code: Path, study, mount: Path, size: str) -> dict:
    mount.mkdir(parents=True, exist_ok=True)
    if subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mount)], capture_output=True
    ).returncode:
        return {"skipped": "cannot mount a tmpfs (needs root)"}
    try:
        proc = _popen(code, study, mount / "out", "--jobs", "1", "--final-only")
        err = proc.communicate()[1]
        lines = [x for x in err.splitlines() if "error" in x.lower()]
        temps = [str(p.relative_to(mount)) for p in mount.rglob("*") if ".tmp" in p.name]
        return {
            "tmpfs": size,
            "exit": proc.returncode,
            "traceback": "Traceback" in err,
            "said": lines[-1] if lines else "",
            "temporary_files_left": temps,
        }
    finally:
        subprocess.run(["umount", str(mount)], check=False)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="folder for score_faults.json")
    ap.add_argument("--baseline", default=None, help="another checkout to run the same trials with")
    ap.add_argument("--tmpfs", default="512k", help="size of the full disk (default 512k)")
    ap.add_argument("--trials", default="kill,lock,disk", help="which trials (default kill,lock,disk)")
    args = ap.parse_args()
    target = output_file(args.out, "score_faults.json")
    work = Path(tempfile.mkdtemp(prefix="aw-faults-"))
    try:
        study = _study(work / "study")
        doc = {
            "command": " ".join(["benchmarks/score_faults.py", *sys.argv[1:]]),
            "study": "10 box tasks of 6 and 8 parts, 1 system, 30 jitter edits each; --jobs 2, exact checkpoints",
        }
        codes = {"this": ROOT, **({"baseline": Path(args.baseline).resolve()} if args.baseline else {})}
        for label, code in codes.items():
            res = {}
            if "kill" in args.trials:
                res["kill"] = [
                    kill_trial(code, study, work / f"{label}-{s.name}", s)
                    for s in (signal.SIGKILL, signal.SIGTERM, signal.SIGINT)
                ]
            if "lock" in args.trials:
                res["second_aw_score_on_one_out"] = lock_trial(code, study, work / f"{label}-lock")
            if "disk" in args.trials:
                res["disk_full"] = disk_full_trial(code, study, work / f"{label}-tmpfs", args.tmpfs)
            doc[label] = res
            print(label, json.dumps(res, indent=1), flush=True)
        target.write_text(json.dumps(doc, indent=1) + "\n")
        print(f"wrote {target}")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
