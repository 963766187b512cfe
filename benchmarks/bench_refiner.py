"""A refiner on the generated break families: one table of accuracy and time per family, and
refinement from near starts.

    nice .venv/bin/python benchmarks/bench_refiner.py --out /tmp/bench_refiner [--refiner classical]
        [--families breaks_planar,fantastic_breaks,breaks_noisy,breaks_eroded,breaks_pieces]
        [--objects 20] [--seed 0] [--near-deg 5,15,30] [--near-families fantastic_breaks,breaks_planar]
        [--suites DIR] [--jobs 1]
    .venv/bin/python benchmarks/bench_refiner.py --table benchmarks/results/refiner_classical.json

Each family is a suite that ``aw-prepare synthetic --blocks FAMILY --per-source N --protocol
official`` builds (into ``--suites``, default ``OUT/suites``; an existing suite there is reused).
The refiner runs on every task from its layout (no start: the global search), in worker
processes (``--jobs``), each task's CPU seconds measured in its worker (``time.process_time``)
and its wall seconds around the call. Scores are the fracture protocol's (``aw_eval.fracture``:
the shared samples, the largest part as anchor, the divisor from ``eval_points/``), as
``aw-score`` computes the refinement study's table: RE (degrees), TE (x100), PA (%), CD (x1000),
means over the objects. Beside them: success (objects with RE under 5 degrees), objects with
RE under 2 degrees, and over all parts: parts whose own RE is under 5 degrees.

Near starts (``--near-deg``): on the first ``--near-objects`` tasks of each ``--near-families``
suite, the refiner starts from the target assembly with every part but the anchor turned by the
given angle about a random axis through its centre and moved by ``angle / 30 * 5 %`` of the
object's size (seeded), as an agent's final state would hand it over; the table gives RE at the
start and after, and the objects made worse (RE up by more than 0.5 degrees).

Writes ``refiner_bench.json`` (every object's figures, the command, the machine's load) and
``refiner_bench.md`` (the tables) in ``--out``, never over an existing file.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _output import output_file  # noqa: E402

FAMILIES = ("breaks_planar", "fantastic_breaks", "breaks_noisy", "breaks_eroded", "breaks_pieces")
NEAR_WORSE_DEG = 0.5


def prepare(suites: Path, family: str, objects: int, seed: int, jobs: int) -> Path:
    """The family's suite (built by ``aw-prepare synthetic`` unless it is there already)."""
    out = suites / f"{family}-{objects}-seed{seed}"
    if (out / "manifest.json").is_file():
        return out
    aw_prepare = Path(sys.executable).parent / "aw-prepare"
    cmd = [str(aw_prepare), "synthetic", "--blocks", family, "--per-source", str(objects), "--seed", str(seed)]
    cmd += ["--protocol", "official", "--out", str(out), "--jobs", str(jobs), "--no-progress"]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return out


def _task_data(suite: Path, tid: str) -> tuple:
    """``(task, target poses (P, 7) in task part order, divisor)``."""
    from aw.formats import read_targets, read_task
    from aw.formats.suite import suite_paths

    task_dir, targets_path = suite_paths(suite, tid)
    task = read_task(task_dir)
    targets = read_targets(targets_path)
    with np.load(suite / "eval_points" / f"{tid}.npz", allow_pickle=False) as npz:
        divisor = float(npz["fracture_divisor"])
    return task, np.array([targets.parts[p].pose for p in task.part_ids]), divisor


def near_start(request, target: np.ndarray, degrees: float, rng: np.random.Generator) -> np.ndarray:
    """The target assembly with every non-anchor part turned by ``degrees`` about a random axis
    through its samples' centre and moved by ``degrees / 30 * 5 %`` of the size: ``(P, 7)``."""
    from scipy.spatial.transform import Rotation

    from aw.prepare.official_protocol import pose_of, rotation_of

    size = float(np.ptp(np.vstack([v for v, _ in request.meshes]), axis=0).max())
    start = np.array(target, dtype=np.float64)
    for i in range(len(start)):
        if i == request.anchor:
            continue
        axis = rng.normal(size=3)
        turn = Rotation.from_rotvec(np.radians(degrees) * axis / np.linalg.norm(axis)).as_matrix()
        shift = rng.normal(size=3)
        shift *= degrees / 30 * 0.05 * size / np.linalg.norm(shift)
        rot, t = rotation_of(start[i, 3:]), start[i, :3]
        centre = rot @ request.points[i].mean(0) + t
        new_rot = turn @ rot
        start[i] = pose_of(turn @ (t - centre) + centre + shift, new_rot)
    return start


def run_one(job: dict) -> dict:
    """Refine one task (in this worker process) and score it; the figures as a dict."""
    from aw.refine.base import check_poses
    from aw.refine.plugins import load_refiner
    from aw.refine.runs import build_request
    from aw_eval.fracture import fracture_metrics_from_samples

    suite = Path(job["suite"])
    task, target, divisor = _task_data(suite, job["task_id"])
    request = build_request(task, suite, None)
    start = None
    if job.get("near_deg") is not None:
        start = near_start(request, target, job["near_deg"], np.random.default_rng(job["near_seed"]))
        request = build_request(task, suite, {p: list(q) for p, q in zip(task.part_ids, start, strict=True)})
    order = sorted(range(len(task.part_ids)), key=lambda i: task.part_ids[i])  # the protocol's part order
    samples = [request.points[i] for i in order]

    def score(poses: np.ndarray):
        return fracture_metrics_from_samples(samples, poses[order], target[order], divisor)

    refine = load_refiner(job["refiner"])
    t0, c0 = time.perf_counter(), time.process_time()
    error = None
    try:
        poses = check_poses(job["refiner"], request, refine(request))
    except Exception as exc:  # a failing refiner is a result: it keeps the start
        poses, error = np.array(request.initial_poses), f"{type(exc).__name__}: {exc}"
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    m = score(poses)
    row = {
        "family": job["family"],
        "task_id": job["task_id"],
        "parts": len(task.part_ids),
        "re": m.re,
        "te": m.te,
        "pa": m.pa,
        "cd": m.cd,
        "part_re": m.part_re.tolist(),
        "anchor": int(order[m.anchor]),
        "wall_s": wall,
        "cpu_s": cpu,
        "error": error,
    }
    if start is not None:
        row["near_deg"] = job["near_deg"]
        row["start_re"] = score(start).re
        row["kept_start"] = bool(np.allclose(poses, start))
    return row


def _summary(rows: list[dict]) -> dict:
    part_re = np.concatenate([r["part_re"] for r in rows])
    anchors = sum(1 for _ in rows)
    others = np.concatenate([np.delete(r["part_re"], r["anchor"]) for r in rows])
    return {
        "objects": len(rows),
        "re": float(np.mean([r["re"] for r in rows])),
        "te": float(np.mean([r["te"] for r in rows])),
        "pa": float(np.mean([r["pa"] for r in rows])),
        "cd": float(np.mean([r["cd"] for r in rows])),
        "success_5deg": float(np.mean([r["re"] < 5 for r in rows])),
        "objects_re_under_2": int(sum(r["re"] < 2 for r in rows)),
        "parts": int(len(part_re)),
        "parts_re_under_5": float(np.mean(part_re < 5)),
        "moved_parts_re_under_5": float(np.mean(others < 5)) if len(others) else float("nan"),
        "anchors": anchors,
        "wall_s": float(np.mean([r["wall_s"] for r in rows])),
        "cpu_s": float(np.mean([r["cpu_s"] for r in rows])),
        "max_wall_s": float(np.max([r["wall_s"] for r in rows])),
        "errors": [f"{r['task_id']}: {r['error']}" for r in rows if r["error"]],
    }


def tables(doc: dict) -> str:
    """The markdown tables of a results document."""
    lines = [
        f"Refiner `{doc['refiner']}`, {doc['objects']} objects a family, seed {doc['seed']}; "
        f"load average {doc['load_before'][0]:.1f} before, {doc['load_after'][0]:.1f} after; {doc['cpus']} CPUs.",
        "",
        "| Family | Objects | RE (deg) | TE (x100) | PA (%) | CD (x1000) | Success (RE < 5) | RE < 2 | Parts RE < 5 "
        "| s / object | CPU s / object |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for fam, s in doc["families"].items():
        lines.append(
            f"| {fam} | {s['objects']} | {s['re']:.2f} | {100 * s['te']:.2f} | {100 * s['pa']:.1f} | "
            f"{1000 * s['cd']:.3f} | {100 * s['success_5deg']:.0f} % | {s['objects_re_under_2']}/{s['objects']} | "
            f"{100 * s['parts_re_under_5']:.0f} % of {s['parts']} | {s['wall_s']:.1f} | {s['cpu_s']:.1f} |"
        )
    if doc.get("near"):
        lines += [
            "",
            "| Start | Family | Objects | RE at start | RE after | Worse (> 0.5 deg) | Start kept |",
            "|---|---|---:|---:|---:|---:|---:|",
        ]
        for key, s in doc["near"].items():
            deg, fam = key.split(" ", 1)
            lines.append(
                f"| {deg} deg | {fam} | {s['objects']} | {s['start_re']:.2f} | {s['re']:.2f} | "
                f"{s['worse']} | {s['kept_start']} |"
            )
    errors = [e for s in doc["families"].values() for e in s["errors"]]
    if errors:
        lines += ["", "Errors:", *[f"- {e}" for e in errors]]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", help="folder for refiner_bench.json and refiner_bench.md")
    p.add_argument("--table", help="print the tables of a results JSON and stop")
    p.add_argument("--refiner", default="classical")
    p.add_argument("--families", default=",".join(FAMILIES))
    p.add_argument("--objects", type=int, default=20)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--near-deg", default="5,15,30", help="start angles for the near-start runs ('' for none)")
    p.add_argument("--near-families", default="fantastic_breaks,breaks_planar")
    p.add_argument("--near-objects", type=int, default=10)
    p.add_argument("--suites", help="where the suites are built (default OUT/suites)")
    p.add_argument("--jobs", type=int, default=1)
    args = p.parse_args(argv)
    if args.table:
        print(tables(json.loads(Path(args.table).read_text())), end="")
        return 0
    if not args.out:
        p.error("--out is required")
    json_path, md_path = output_file(args.out, "refiner_bench.json"), output_file(args.out, "refiner_bench.md")
    suites = Path(args.suites or Path(args.out) / "suites")
    families = [f for f in args.families.split(",") if f]
    jobs = []
    suite_of = {fam: prepare(suites, fam, args.objects, args.seed, args.jobs) for fam in families}
    from aw.formats import read_manifest

    for fam, suite in suite_of.items():
        for tid in read_manifest(suite).select(None):
            jobs.append({"family": fam, "suite": str(suite), "task_id": tid, "refiner": args.refiner})
    near_degs = [float(d) for d in args.near_deg.split(",") if d]
    for k, deg in enumerate(near_degs):
        for fam in [f for f in args.near_families.split(",") if f in suite_of]:
            for i, tid in enumerate(read_manifest(suite_of[fam]).select(None)[: args.near_objects]):
                job = {"family": fam, "suite": str(suite_of[fam]), "task_id": tid, "refiner": args.refiner}
                jobs.append({**job, "near_deg": deg, "near_seed": 1000 * k + i})
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        rows = list(pool.map(run_one, jobs))
    doc = {
        "command": " ".join([Path(sys.argv[0]).name, *(sys.argv[1:] if argv is None else argv)]),
        "refiner": args.refiner,
        "objects": args.objects,
        "seed": args.seed,
        "jobs": args.jobs,
        "cpus": os.cpu_count(),
        "load_before": list(load_before),
        "load_after": list(os.getloadavg()),
        "wall_s": time.perf_counter() - t0,
        "families": {},
        "near": {},
        "rows": rows,
    }
    for fam in families:
        doc["families"][fam] = _summary([r for r in rows if r["family"] == fam and "near_deg" not in r])
    for deg in near_degs:
        for fam in families:
            sel = [r for r in rows if r["family"] == fam and r.get("near_deg") == deg]
            if sel:
                doc["near"][f"{deg:g} {fam}"] = {
                    "objects": len(sel),
                    "start_re": float(np.mean([r["start_re"] for r in sel])),
                    "re": float(np.mean([r["re"] for r in sel])),
                    "worse": int(sum(r["re"] > r["start_re"] + NEAR_WORSE_DEG for r in sel)),
                    "kept_start": int(sum(r["kept_start"] for r in sel)),
                }
    json_path.write_text(json.dumps(doc, indent=1) + "\n")
    md_path.write_text(tables(doc))
    print(tables(doc), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
