"""aw-score timings: the statistics alone on a paper-sized table, and rescoring a whole study.

    .venv/bin/python benchmarks/bench_score.py [--stats-only] [--systems 8] [--draws 10000]
        [--permutations 100000] [--e2e-systems 2] [--e2e-tasks-per-source 1] [--parts 3]
        [--jitter 500] [--jobs 1] --out DIR

1. Statistics: a synthetic study of ``--systems`` systems x 100 tasks (the paper's design: 20
   objects per source, PartNet in two paired conditions) with per-part errors; times the
   bootstrap + randomization tests + reference effects (``uncertainty``) at the given draws, and
   every other analysis (``build_results``) apart.
2. End to end: a box suite (``aw_eval.study.fixtures``; one object per source by default, so
   5 tasks with PartNet's two conditions) and scripted runs whose random-walk nudges make every
   checkpoint a new state, long enough that the study has at least 5,000 checkpoints; times ``score_study`` cold (empty cache: every
   checkpoint in fast mode, every final state in exact mode), then warm (everything cached), and
   the outputs (``write_outputs``, plots included).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _cpu_seconds() -> float:
    """User + system CPU time of this process and its finished children (pool workers)."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def synthetic_study(n_systems: int, seed: int = 0):
    from aw.formats import SuiteEntry
    from aw_eval.study import RunRecord, RunScore, Study
    from aw_eval.study.fixtures import BLOCKS

    rng = np.random.default_rng(seed)
    entries = [
        SuiteEntry(
            task_id=f"{s}-o{o:02d}-{c}",
            source=s,
            condition=c,
            object_id=f"o{o:02d}",
            category="chair",
            n_parts=int(rng.integers(2, 16)),
        )
        for s, conds in BLOCKS
        for o in range(20)
        for c in conds
    ]
    systems = [f"system{i}" for i in range(n_systems)]
    runs = {}
    for i, s in enumerate(systems):
        skill = 1.0 - i / max(1, n_systems)
        for e in entries:
            p = e.n_parts
            errors = np.where(rng.random(p) < skill, rng.uniform(0, 0.01, p), rng.uniform(0.01, 1.0, p))
            n_ck = 40
            calls = np.sort(rng.uniform(0, 1800, 120))
            r = RunScore(
                system=s,
                task_id=e.task_id,
                status="scored",
                final_from="final.json",
                has_trajectory=True,
                end_reason="finished",
                pa=float((errors <= 0.01).mean()),
                sr=float((errors <= 0.01).all()),
                scd=float(errors.mean()),
                part_errors=errors,
                assignment=np.arange(p),
                centred_cd=errors * rng.random(p),
                offset=rng.random(p),
                moved=rng.random(p) < 0.9,
                ck_seq=np.arange(n_ck),
                ck_t=np.concatenate([[0], np.sort(rng.choice(calls, n_ck - 1))]),
                ck_pa=np.sort(rng.random(n_ck)),
                ck_sr=np.zeros(n_ck),
                ck_sra=np.zeros(n_ck),
                ck_scd=rng.random(n_ck),
                ck_part_errors=rng.random((n_ck, p)),
                ck_assignment=np.tile(np.arange(p), (n_ck, 1)),
                call_t=calls,
                call_kind=rng.integers(0, 4, 120).astype(np.int8),
                call_ok=np.ones(120, bool),
                edit_call=np.flatnonzero(rng.random(120) < 0.3),
                end_t=1800.0,
            )
            ne = len(r.edit_call)
            r.edit_translation, r.edit_rotation_deg = rng.random(ne), rng.choice([0.0, 90.0], ne)
            r.edit_revisit = rng.random(ne) < 0.8
            r.sra = float(r.scd < 0.02)
            runs[(s, e.task_id)] = RunRecord(r)
    return Study("bench", entries, systems, runs)


def bench_stats(n_systems: int, draws: int, perms: int) -> dict:
    from aw_eval.analyses import uncertainty
    from aw_eval.report import AnalysisSettings, build_results

    study = synthetic_study(n_systems)
    t0 = time.perf_counter()
    u = uncertainty(study, n_draws=draws, n_permutations=perms, seed=0)
    t_stats = time.perf_counter() - t0
    t0 = time.perf_counter()
    build_results(study, AnalysisSettings(seed=0, n_draws=draws, n_permutations=perms))
    t_all = time.perf_counter() - t0
    return {
        "systems": n_systems,
        "tasks": len(study.original_ids),
        "bootstrap_draws": draws,
        "permutations": perms,
        "tests": u.get("family_size", 0),
        "uncertainty_seconds": round(t_stats, 3),
        "all_analyses_seconds": round(t_all, 3),
    }


def bench_e2e(n_systems: int, per_source: int, n_parts: int, jitter: int, jobs: int, min_checkpoints: int) -> dict:
    from aw.formats import read_manifest
    from aw_eval.report import AnalysisSettings, write_outputs
    from aw_eval.study import ScoreSettings, score_study
    from aw_eval.study.fixtures import box_suite, write_scripted_run

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        suite = box_suite(tmp / "suite", objects_per_source=per_source, n_parts=n_parts)
        entries = read_manifest(suite).tasks
        n_ck = 0
        for si in range(n_systems):
            for k, e in enumerate(entries):
                ids = [f"p{i + 1:02d}" for i in range(e.n_parts)]
                correct = ids if (k + si) % 3 else ids[:-1]
                r = write_scripted_run(
                    tmp / "runs" / f"sys{si}" / e.task_id,
                    suite,
                    e.task_id,
                    system=f"sys{si}",
                    correct=correct,
                    jitter_edits=jitter,
                    seed=k,
                    run_info={"wall_seconds": 600.0, "mcp_calls": 100},
                )
                n_ck += r.n_checkpoints
        if n_ck < min_checkpoints:
            raise SystemExit(f"only {n_ck} checkpoints; raise --jitter or --e2e-tasks-per-source")
        settings = ScoreSettings(checkpoint_mode="fast", final_mode="exact")
        cpu0 = _cpu_seconds()
        t0 = time.perf_counter()
        study, st = score_study(suite, tmp / "runs", tmp / "out", settings, n_jobs=jobs, progress=True)
        cold = time.perf_counter() - t0
        cold_cpu = _cpu_seconds() - cpu0
        t0 = time.perf_counter()
        study, st2 = score_study(suite, tmp / "runs", tmp / "out", settings, n_jobs=jobs, progress=False)
        warm = time.perf_counter() - t0
        t0 = time.perf_counter()
        write_outputs(study, tmp / "out", AnalysisSettings(), suite_dir=str(suite), runs_dir=str(tmp / "runs"))
        outputs = time.perf_counter() - t0
        return {
            "systems": n_systems,
            "tasks": len(entries),
            "parts_per_task": n_parts,
            "runs": n_systems * len(entries),
            "checkpoints": n_ck,
            "jobs": jobs,
            "executor": st.executor,
            "cold_seconds": round(cold, 2),
            "cold_cpu_seconds": round(cold_cpu, 1),
            "load_average_after": os.getloadavg(),
            "worker_seconds": {
                "geometry": round(st.seconds_geometry, 1),
                "checkpoints": round(st.seconds_checkpoints, 1),
                "final_states_exact": round(st.seconds_final, 1),
            },
            "checkpoints_per_second_cold": round(n_ck / cold, 1),
            "warm_seconds": round(warm, 3),
            "warm_cached_runs": st2.cached,
            "warm_scored_runs": st2.scored,
            "outputs_seconds_incl_stats_and_plots": round(outputs, 2),
        }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stats-only", action="store_true")
    ap.add_argument("--systems", type=int, default=8)
    ap.add_argument("--draws", type=int, default=10_000)
    ap.add_argument("--permutations", type=int, default=100_000)
    ap.add_argument("--e2e-systems", type=int, default=2)
    ap.add_argument("--e2e-tasks-per-source", type=int, default=1)
    ap.add_argument("--parts", type=int, default=3)
    ap.add_argument("--jitter", type=int, default=500, help="small nudges per run (one new checkpoint each)")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--min-checkpoints", type=int, default=5000)
    ap.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="DIR",
        help="folder to write bench_score.json to (a new file; never overwritten)",
    )
    args = ap.parse_args()
    from _output import output_file

    out = output_file(args.out, "bench_score.json")  # refused before the run, not after it
    result = {
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "platform": platform.platform()},
        "command": " ".join(sys.argv),
    }
    result["statistics"] = bench_stats(args.systems, args.draws, args.permutations)
    s = result["statistics"]
    print(
        f"statistics: {s['systems']} systems x {s['tasks']} tasks, {s['bootstrap_draws']:,} bootstrap draws, "
        f"{s['permutations']:,} relabellings x {s['tests']} tests: {s['uncertainty_seconds']:.2f} s; "
        f"all analyses: {s['all_analyses_seconds']:.2f} s"
    )
    if not args.stats_only:
        result["end_to_end"] = bench_e2e(
            args.e2e_systems, args.e2e_tasks_per_source, args.parts, args.jitter, args.jobs, args.min_checkpoints
        )
        e = result["end_to_end"]
        print(
            f"end to end: {e['runs']} runs, {e['checkpoints']:,} checkpoints ({e['parts_per_task']} parts): cold "
            f"{e['cold_seconds']:.1f} s wall, {e['cold_cpu_seconds']:.0f} s CPU; worker time geometry "
            f"{e['worker_seconds']['geometry']:.0f} s, checkpoints {e['worker_seconds']['checkpoints']:.0f} s, "
            f"exact finals {e['worker_seconds']['final_states_exact']:.0f} s "
            f"({e['checkpoints_per_second_cold']:.1f} checkpoints/s, {e['executor']}), "
            f"warm {e['warm_seconds']:.2f} s ({e['warm_cached_runs']} cached, {e['warm_scored_runs']} rescored), "
            f"outputs {e['outputs_seconds_incl_stats_and_plots']:.1f} s"
        )
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
