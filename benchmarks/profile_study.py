"""Where a study's time goes on box assemblies, and what round 6's two changes save there.

Builds ``bench_score.py``'s box suite (8 parts) with one scripted run per task whose last part
is misplaced (so its checkpoints sit near the part-error threshold), then, in one process:

1. ``fast`` on ``--checkpoints`` consecutive checkpoints of one run, as a trajectory
   (``score_batch``: the refinement near a threshold starts from the previous checkpoint's) and
   one at a time (``score``: every refinement starts cold): seconds, refinements and their
   ICP iterations, and whether PA/SR agree;
2. ``exact`` on each run's final state, with and without the switch to the prediction's own
   Delaunay graph where parts touch (``aw_eval.registration.CONTACT_WALKS``), alternating, best of
   ``--repeat``: seconds, the first start's part walks per backward search, and the largest
   relative SCD difference.

    .venv/bin/python benchmarks/profile_study.py [--tasks 2] [--checkpoints 100] [--repeat 2]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import aw_eval  # noqa: E402
from aw_eval import registration  # noqa: E402
from aw_eval.kernels import ICPProblem  # noqa: E402


class _CountRefinements:
    """Counts the refinements (full-budget ICP runs) and their iterations while active."""

    def __enter__(self):
        self.runs, self.iterations = 0, 0
        self._run = ICPProblem.run
        counter = self

        def run(prob, r0, t0, max_iters, tol, stop_at=None):
            res = counter._run(prob, r0, t0, max_iters, tol, stop_at)
            if max_iters >= 100:
                counter.runs += 1
                counter.iterations += res.iterations
            return res

        ICPProblem.run = run
        return self

    def __exit__(self, *exc):
        ICPProblem.run = self._run


def profile_fast(geom, poses: np.ndarray) -> dict:
    aw_eval.score_batch(geom, poses[:2], mode="fast")  # per-task structures, not timed
    out = {}
    with _CountRefinements() as c:
        t = time.perf_counter()
        traj = aw_eval.score_batch(geom, poses, mode="fast")
        out["trajectory"] = {"seconds": time.perf_counter() - t, "refinements": c.runs, "iterations": c.iterations}
    with _CountRefinements() as c:
        t = time.perf_counter()
        cold = [aw_eval.score(geom, p, mode="fast") for p in poses]
        out["one_at_a_time"] = {"seconds": time.perf_counter() - t, "refinements": c.runs, "iterations": c.iterations}
    out["pa_sr_identical"] = int(
        sum(a.pa == pa and a.sr == sr for a, pa, sr in zip(cold, traj.pa, traj.sr, strict=True))
    )
    out["scd_max_rel_diff"] = float(max(abs(a.scd - b) / b for a, b in zip(cold, traj.scd, strict=True)))
    return out


def profile_exact(geom, poses: np.ndarray, repeat: int) -> dict:
    index = geom.index()
    ck = geom.checkpoint(poses)
    r0, t0 = registration.checkpoint_starts(geom, ck)
    st = geom.settings

    def prediction_problem():
        return index.assembly_problem(ck.poses, ck.rotations, ck.parts, geom.divisor)

    first = prediction_problem().run(r0[0], t0[0], st.max_iters, st.tol)
    best = {"parts' walks": np.inf, "own graph where parts touch": np.inf}
    regs = {}
    for _ in range(repeat):
        for name in best:
            t = time.perf_counter()
            prob = prediction_problem()
            hook = registration._own_graph_where_parts_touch(index, ck.parts) if name.startswith("own") else None
            regs[name] = registration.register_points(prob, r0, t0, st.max_iters, st.tol, hook)
            best[name] = min(best[name], time.perf_counter() - t)
    a, b = regs.values()
    return {
        "seconds": best,
        "first_start_walks_per_search": first.part_walks / max(first.part_searches, 1),
        "scd_max_rel_diff": abs(a.scd - b.scd) / a.scd,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tasks", type=int, default=2, help="box tasks (of the suite's 5)")
    ap.add_argument("--checkpoints", type=int, default=100, help="consecutive checkpoints for the fast part")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="DIR",
        help="folder to write profile_study.json to (a new file; never overwritten)",
    )
    args = ap.parse_args()
    from _output import output_file

    out = output_file(args.out, "profile_study.json")  # refused before the run, not after it
    from aw.formats import read_manifest, suite_paths
    from aw_eval.study.fixtures import box_suite, write_scripted_run

    result = {"command": " ".join(sys.argv), "tasks": []}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        suite = box_suite(tmp / "suite", objects_per_source=1, n_parts=8)
        for k, e in enumerate(read_manifest(suite).tasks[: args.tasks]):
            ids = [f"p{i + 1:02d}" for i in range(e.n_parts)]
            run = tmp / "runs" / e.task_id
            write_scripted_run(run, suite, e.task_id, system="sys", correct=ids[:-1], jitter_edits=500, seed=k)
            task_dir, targets = suite_paths(suite, e.task_id)
            geom = aw_eval.load_task_geometry(task_dir, targets, cache_dir=tmp / "cache")
            states = [
                geom.poses_from_dict(r["poses"])
                for r in map(json.loads, (run / "trajectory.jsonl").read_text().splitlines())
                if r.get("poses")
            ]
            fin = json.loads((run / "final.json").read_text())
            row = {
                "task": e.task_id,
                "fast": profile_fast(geom, np.stack(states[100 : 100 + args.checkpoints])),
                "exact_final": profile_exact(geom, geom.poses_from_dict(fin.get("poses", fin)), args.repeat),
            }
            result["tasks"].append(row)
            f, x = row["fast"], row["exact_final"]
            n = args.checkpoints
            print(
                f"{e.task_id}: fast on {n} checkpoints, as a trajectory {f['trajectory']['seconds']:.1f} s "
                f"({f['trajectory']['refinements']} refinements, {f['trajectory']['iterations']} ICP iterations), "
                f"one at a time {f['one_at_a_time']['seconds']:.1f} s ({f['one_at_a_time']['refinements']}, "
                f"{f['one_at_a_time']['iterations']}); PA/SR identical {f['pa_sr_identical']}/{n}, "
                f"SCD within {f['scd_max_rel_diff']:.1e}"
            )
            s = x["seconds"]
            print(
                f"  exact final state: first start {x['first_start_walks_per_search']:.2f} part walks per search; "
                + ", ".join(f"{k} {v:.2f} s" for k, v in s.items())
                + f"; SCD within {x['scd_max_rel_diff']:.1e}",
                flush=True,
            )
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
