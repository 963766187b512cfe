"""``aw-score --checkpoint-mode exact`` on a Dask LocalCluster: every checkpoint of a small study scored by the
protocol (every start at full resolution), then extrapolated to a paper-scale study.

    .venv/bin/python benchmarks/bench_dask_exact.py [--workers 2] [--parts 8] [--systems 1]
        [--jitter 0] --out DIR [--name NAME]

Builds a box suite (``aw_eval.study.fixtures``: one object per source, 5 tasks of ``--parts``
parts), writes scripted runs (one placement per part, ``--jitter`` extra nudges), starts a
``distributed.LocalCluster`` of ``--workers`` single-threaded worker processes and runs the
``aw-score`` command line against it (``--scheduler``), checkpoints and final states in
``exact``. The extrapolation divides the measured worker seconds per checkpoint into
60,000 checkpoints (8 systems x 100 tasks x 75) and 800 exact final states on 16 workers,
assuming perfect balance over 100 tasks: a projection, not a measurement.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

STUDY_CHECKPOINTS, STUDY_FINALS, STUDY_TASKS, CLUSTER_WORKERS = 60_000, 800, 100, 16


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--parts", type=int, default=8)
    ap.add_argument("--systems", type=int, default=1)
    ap.add_argument("--jitter", type=int, default=0, help="extra nudges per run (one new checkpoint each)")
    ap.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder to write the JSON to (a new file)")
    ap.add_argument("--name", default="bench_dask_exact", help="the JSON file's name in --out, without .json")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from _output import output_file

    path = output_file(args.out, f"{args.name}.json")  # refused before the run, not after it

    from distributed import LocalCluster

    from aw.formats import read_manifest
    from aw_eval.cli import main as aw_score
    from aw_eval.study.fixtures import box_suite, write_scripted_run

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        suite = box_suite(tmp / "suite", objects_per_source=1, n_parts=args.parts)
        tasks = read_manifest(suite).tasks
        n_tasks, n_ck = len(tasks), 0
        for si in range(args.systems):
            for k, e in enumerate(tasks):
                ids = [f"p{i + 1:02d}" for i in range(e.n_parts)]
                r = write_scripted_run(
                    tmp / "runs" / f"sys{si}" / e.task_id,
                    suite,
                    e.task_id,
                    system=f"sys{si}",
                    correct=ids if (k + si) % 3 else ids[:-1],
                    jitter_edits=args.jitter,
                    seed=k,
                    inspect_moves=False,
                )
                n_ck += r.n_checkpoints
        with LocalCluster(
            n_workers=args.workers, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster:
            argv = [
                str(suite),
                str(tmp / "runs"),
                "--out",
                str(tmp / "out"),
                "--checkpoint-mode",
                "exact",
                "--final-mode",
                "exact",
                "--scheduler",
                cluster.scheduler_address,
                "--no-plots",
                "--no-html",
                "--no-progress",
                "--bootstrap",
                "100",
                "--permutations",
                "100",
            ]
            t0 = time.perf_counter()
            rc = aw_score(argv)
            wall = time.perf_counter() - t0
        if rc != 0:
            raise SystemExit(f"aw-score exited with {rc}")
        scoring = json.loads((tmp / "out" / "scores.json").read_text())["scoring"]
    ws = scoring["worker_seconds"]
    per_ck = ws["checkpoints"] / n_ck
    per_final = ws["final_states"] / (args.systems * n_tasks)
    per_task_geometry = ws["geometry"] / n_tasks
    worker_hours = (STUDY_CHECKPOINTS * per_ck + STUDY_FINALS * per_final + STUDY_TASKS * per_task_geometry) / 3600
    out = {
        "command": " ".join(["benchmarks/bench_dask_exact.py"] + sys.argv[1:]),
        "measured": {
            "workers": args.workers,
            "systems": args.systems,
            "tasks": n_tasks,
            "parts_per_task": args.parts,
            "checkpoints": n_ck,
            "wall_seconds": round(wall, 1),
            "scoring": scoring,
            "worker_seconds_per_checkpoint": round(per_ck, 3),
            "worker_seconds_per_final_state": round(per_final, 3),
            "load_average_after": os.getloadavg(),
            "cpus": os.cpu_count(),
        },
        "extrapolated (not measured)": {
            "checkpoints": STUDY_CHECKPOINTS,
            "final_states": STUDY_FINALS,
            "tasks": STUDY_TASKS,
            "workers": CLUSTER_WORKERS,
            "worker_hours": round(worker_hours, 2),
            "wall_hours_on_16_workers": round(worker_hours / CLUSTER_WORKERS, 2),
        },
    }
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
