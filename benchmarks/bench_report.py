"""Size and write time of ``report.html`` over a study of ``--systems`` systems on a box suite of
``--objects`` objects per source (5 tasks per object: PartNet's two conditions and one each for the
other sources), each run ``--checkpoints`` recorded states long.

The paper's scale is 20 objects (100 tasks) x 6 systems x 100 checkpoints = 60,000 checkpoints.
Scores are synthetic (PA rising along each trajectory, identity registrations): what is timed is
the report, not the evaluator (``bench_score.py`` times that). The page is written twice: cold
(every picture rendered) and warm (every picture reused from ``report_files/renders``)::

    .venv/bin/python benchmarks/bench_report.py --objects 20 --out /tmp/bench-report   # paper scale
    .venv/bin/python benchmarks/bench_report.py --objects 4 --out /tmp/bench-report    # 1/5 of it
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

import numpy as np


def _synthetic_score(system: str, task_id: str, run_dir: Path, part_ids: list[str], all_ids: list[str], rng):
    from aw_eval.study.episode import read_episode
    from aw_eval.study.model import RunScore

    ep = read_episode(run_dir, task_id, all_ids, part_ids, np.zeros((len(all_ids), 3)), 1.0)
    n, p = len(ep.ck_seq), len(part_ids)
    frac = np.linspace(0.0, 1.0, n)
    errors = np.clip(0.05 * (1 - frac)[:, None] + 0.004 * rng.random((n, p)), 0, None)
    ok = errors <= 0.01
    pa = ok.mean(axis=1)
    scd = errors.mean(axis=1)
    return RunScore(
        system=system,
        task_id=task_id,
        status="scored",
        final_from="final.json",
        end_reason="finished",
        has_trajectory=True,
        end_t=ep.end_t,
        pa=float(pa[-1]),
        sr=float(ok[-1].all()),
        sra=float(scd[-1] < 0.02),
        scd=float(scd[-1]),
        part_errors=errors[-1],
        assignment=np.arange(p),
        centred_cd=errors[-1] / 2,
        offset=np.zeros(p),
        moved=ep.moved,
        reg_rotation=np.eye(3),
        reg_translation=np.zeros(3),
        ck_seq=ep.ck_seq,
        ck_t=ep.ck_t,
        ck_pa=pa,
        ck_sr=ok.all(axis=1).astype(float),
        ck_sra=(scd < 0.02).astype(float),
        ck_scd=scd,
        ck_part_errors=errors,
        ck_assignment=np.tile(np.arange(p), (n, 1)),
        ck_reg_rotation=np.tile(np.eye(3), (n, 1, 1)),
        ck_reg_translation=np.zeros((n, 3)),
        call_t=ep.call_t,
        call_kind=ep.call_kind,
        call_ok=ep.call_ok,
        edit_call=ep.edit_call,
        edit_translation=ep.edit_translation,
        edit_rotation_deg=ep.edit_rotation_deg,
        edit_revisit=ep.edit_revisit,
    )


def _size(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=20, help="objects per source (20: the paper's 100 tasks)")
    ap.add_argument("--systems", type=int, default=6)
    ap.add_argument("--checkpoints", type=int, default=100, help="recorded states per run")
    ap.add_argument("--parts", type=int, default=4)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--jobs", type=int, default=1, help="processes building the cards")
    args = ap.parse_args(argv)

    from aw.formats import read_manifest, read_task
    from aw.formats.suite import suite_paths
    from aw_eval.report import AnalysisSettings, build_results, render_markdown
    from aw_eval.report.html import write_html
    from aw_eval.study import RunRecord, Study
    from aw_eval.study.fixtures import box_suite, write_scripted_run
    from aw_eval.study.model import TaskFacts

    if args.out.exists():
        shutil.rmtree(args.out)
    suite = box_suite(args.out / "suite", objects_per_source=args.objects, n_parts=args.parts)
    entries = read_manifest(suite).tasks
    systems = [f"system{i}" for i in range(args.systems)]
    jitter = max(args.checkpoints - 1 - args.parts, 0)  # placements, then nudges, after the initial state
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    records, facts, n_ck = {}, {}, 0
    for e in entries:
        all_ids = read_task(suite_paths(suite, e.task_id)[0]).part_ids
        facts[e.task_id] = TaskFacts(e.task_id, len(all_ids), 1.0, 1.0, list(all_ids))
        for k, s in enumerate(systems):
            run_dir = args.out / "runs" / s / e.task_id
            wrong = all_ids[: k % len(all_ids)]
            write_scripted_run(
                run_dir,
                suite,
                e.task_id,
                system=s,
                correct=[p for p in all_ids if p not in wrong],
                inspect_moves=False,
                jitter_edits=jitter,
                seed=k,
            )
            score = _synthetic_score(s, e.task_id, run_dir, all_ids, all_ids, rng)
            n_ck += score.n_checkpoints
            records[(s, e.task_id)] = RunRecord(score, None, None, run_dir)
    study = Study("bench", entries, systems, records, facts)
    doc = build_results(study, AnalysisSettings(n_draws=200, n_permutations=200), suite_dir=str(suite))
    markdown = render_markdown(doc, {})
    print(
        f"study: {len(entries)} tasks x {len(systems)} systems, {n_ck:,} checkpoints "
        f"(built in {time.perf_counter() - t0:.0f} s)"
    )
    report = args.out / "report"
    for label in ("cold", "warm"):
        stats = write_html(study, doc, markdown, report, suite, jobs=args.jobs)
        files = report / "report_files"
        bundle = sum(p.stat().st_size for p in files.glob("plotly-*.min.js"))
        print(
            f"{label}: {stats.seconds:.1f} s; report.html {stats.html_bytes / 1e6:.2f} MB; report_files "
            f"{_size(files) / 1e6:.1f} MB (plotly bundle {bundle / 1e6:.1f} MB, pictures "
            f"{_size(files / 'renders') / 1e6:.1f} MB in {stats.renders} files, {stats.renders_new} rendered now, "
            f"3D-view data {_size(files / 'viewer') / 1e6:.1f} MB)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
