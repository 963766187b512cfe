"""Part-count sweep: every per-task step's time and peak memory from 2 to 500 parts.

    nice .venv/bin/python benchmarks/bench_parts.py --out /tmp/parts [--parts 2,10,20,50,100,200,500]
        [--kinds distinct,identical,replicas] [--replicas-max 20] [--official-max 500] [--limit-s 900]
    .venv/bin/python benchmarks/bench_parts.py --table benchmarks/results/parts_sweep.json
    .venv/bin/python benchmarks/bench_parts.py --candidates distinct 100,500
    PYTHONPATH=CHECKOUT .venv/bin/python benchmarks/bench_parts.py --time-groups OUT/suites/distinct050/geometry.npz
    PYTHONPATH=CHECKOUT .venv/bin/python benchmarks/bench_parts.py --time-icp OUT/suites/identical100/geometry.npz

Objects are generated as meshes, one folder per object (``aw-prepare folder`` layout), in a grid
so that no two parts touch:

- ``distinct``: boxes of seeded random extents in [0.05, 1]^3 (sorted, so no two are the same box);
- ``identical``: a 1 x 1 x 0.05 base plate and ``n - 1`` identical 0.1 x 0.1 x 0.3 pegs (the
  pegs group: two samplings of a small part are within the protocol's 1e-4);
- ``replicas``: ``n`` copies of one 0.6 x 0.25 x 0.1 box, the largest part itself. Two samplings
  of it are about 5e-4 apart, above 1e-4, so no shape bound can rule a pair out and every pair
  is registered in full: the quadratic worst case, run up to ``--replicas-max`` parts.

Steps, each in a fresh process (its peak resident memory is the process's ``ru_maxrss``):
``prepare`` (``aw-prepare folder``), ``geometry`` (``aw_eval.load_task_geometry`` without the cache,
split into mesh loading, surface sampling, FPS, the divisor, the equivalence groups and the
task's search structures), ``render`` (the scene's renderer: start and one 1024 x 768 picture),
``score`` (one checkpoint: the initial poses), and ``official`` (``aw-prepare folder --protocol
official``). A step that runs past ``--limit-s`` is stopped and recorded as such. Writes
``parts_sweep.json`` in ``--out`` (never over an existing file).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _output import output_file  # noqa: E402

KINDS = ("distinct", "identical", "replicas")


def part_extents(n: int, kind: str) -> list[tuple[float, float, float]]:
    """Box extents of the ``n`` parts of a generated object of ``kind``."""
    if kind == "distinct":
        rng = np.random.default_rng(20261126)
        return [tuple(float(v) for v in sorted(rng.uniform(0.05, 1.0, 3), reverse=True)) for _ in range(n)]
    if kind == "identical":
        return [(1.0, 1.0, 0.05)] + [(0.1, 0.1, 0.3)] * (n - 1)
    if kind == "replicas":
        return [(0.6, 0.25, 0.1)] * n
    raise ValueError(f"unknown kind {kind!r}")


def make_object(root: Path, n: int, kind: str) -> Path:
    """Write ``root/<kind><n>/p000.obj ...`` (assembled frame, parts on a grid) and return it."""
    import trimesh

    folder = root / f"{kind}{n:03d}"
    folder.mkdir(parents=True, exist_ok=True)
    side = int(np.ceil(np.sqrt(n)))
    for k, extents in enumerate(part_extents(n, kind)):
        box = trimesh.creation.box(extents=extents)
        box.apply_translation([1.5 * (k % side), 1.5 * (k // side), 0.0])
        box.export(folder / f"p{k:03d}.obj")
    return folder


# ---------------------------------------------------------------- steps (each in its own process)


def _task(suite: Path) -> tuple[Path, Path]:
    task = next(p for p in (suite / "tasks").iterdir() if p.is_dir())
    return task, suite / "targets" / f"{task.name}.json"


def step_geometry(suite: Path) -> dict:
    from aw.formats import read_targets, read_task
    from aw.meshes import load_mesh
    from aw.pair_search import local_workers
    from aw_eval.equivalence import equivalence_groups
    from aw_eval.geometry import TaskGeometry, part_divisor
    from aw_eval.kernels.fps import fps_batch
    from aw_eval.sampling import part_seed, surface_samples
    from aw_eval.settings import ProtocolSettings

    task_dir, targets_path = _task(suite)
    st = ProtocolSettings()
    out, t = {}, time.perf_counter()
    task, targets = read_task(task_dir), read_targets(targets_path)
    ids = [pid for pid in task.part_ids if not targets.parts[pid].distractor]
    paths = {p.id: task_dir / p.mesh for p in task.parts}
    meshes = [load_mesh(paths[pid]) for pid in ids]
    out["load_s"], t = time.perf_counter() - t, time.perf_counter()
    cands = np.stack([surface_samples(m, st.n_surface, part_seed(st.seed, i)) for i, m in enumerate(meshes)])
    out["sampling_s"], t = time.perf_counter() - t, time.perf_counter()
    idx = fps_batch(cands, st.n_fps, threads=local_workers())  # what aw_eval.sampling.part_clouds runs
    clouds = np.take_along_axis(cands, idx[..., None], axis=1)
    out["fps_s"], t = time.perf_counter() - t, time.perf_counter()
    divisor = targets.eval_divisor or max(part_divisor(np.asarray(m.vertices)) for m in meshes)
    out["divisor_s"], t = time.perf_counter() - t, time.perf_counter()
    groups = equivalence_groups(clouds, divisor, st, show_progress=False)
    out["groups_s"], t = time.perf_counter() - t, time.perf_counter()
    poses = np.asarray([targets.parts[pid].pose for pid in ids])
    geom = TaskGeometry(tuple(ids), clouds, poses, divisor, groups, st)
    index = geom.index() if callable(geom.index) else geom.index
    index._build_parts()  # each part's baked tree and graph: what part distances walk (the joined target's graph is
    # built by the first checkpoint's ICP: in the score step)
    out["index_s"] = time.perf_counter() - t
    geom.save(suite / "geometry.npz")  # for the score step
    out["total_s"] = sum(v for k, v in out.items() if k.endswith("_s"))
    out["group_sizes"] = sorted((len(g) for g in groups), reverse=True)[:5]
    out["n_groups"] = len(groups)
    return out


def step_render(suite: Path) -> dict:
    from aw.formats import read_task
    from aw.meshes import load_mesh
    from aw.render import OffscreenRenderer

    task_dir, _ = _task(suite)
    t = time.perf_counter()
    meshes = [load_mesh(task_dir / p.mesh) for p in read_task(task_dir).parts]
    load = time.perf_counter() - t
    t = time.perf_counter()
    r = OffscreenRenderer(meshes)
    start = time.perf_counter() - t
    t = time.perf_counter()
    r.render()
    picture = time.perf_counter() - t
    r.close()
    return {"load_s": load, "start_s": start, "picture_s": picture}


def step_score(suite: Path) -> dict:
    from aw_eval.geometry import TaskGeometry
    from aw_eval.scoring import score

    geom = TaskGeometry.load(suite / "geometry.npz")
    t = time.perf_counter()
    score(geom, np.tile([0.0, 0, 0, 1, 0, 0, 0], (geom.n_parts, 1)))  # the baked layout: identity poses
    return {"score_s": time.perf_counter() - t}


def step_prepare(argv: list[str]) -> dict:
    """``aw-prepare`` with ``argv``, in this process (``--jobs 1``)."""
    from aw.cli.prepare import main as prepare

    t = time.perf_counter()
    code = prepare(argv)
    if code:
        raise SystemExit(f"aw-prepare exited with {code}")
    return {"prepare_s": time.perf_counter() - t}


STEPS = {"geometry": step_geometry, "render": step_render, "score": step_score}


def _in_process(name: str, arg: str) -> None:
    out = step_prepare(json.loads(arg)) if name == "prepare" else STEPS[name](Path(arg))
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps(out))


def _prepare(src: Path, suite: Path, protocol: str, limit: float) -> dict:
    argv = ["folder", str(src.parent), "--out", str(suite), "--jobs", "1", "--no-progress", "--protocol", protocol]
    return _run([sys.executable, __file__, "_step", "prepare", json.dumps(argv)], limit)


def _run(cmd: list[str], limit: float) -> dict:
    t = time.perf_counter()
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=limit)
    except subprocess.TimeoutExpired as exc:
        err = exc.stderr.decode() if isinstance(exc.stderr, bytes) else (exc.stderr or "")
        return {"error": f"stopped after {limit:.0f} s", "warnings": [x for x in err.splitlines() if "Warning" in x]}
    wall = time.perf_counter() - t
    if done.returncode != 0:
        return {"error": (done.stderr.strip().splitlines() or [f"exit {done.returncode}"])[-1]}
    out = json.loads(done.stdout.strip().splitlines()[-1])
    out["wall_s"] = wall
    out["warnings"] = [line for line in done.stderr.splitlines() if "Warning" in line]
    return out


def _cell(step: dict, key: str) -> str:
    if not step:
        return "-"
    if "error" in step:
        return (
            "stopped" if step["error"].startswith("stopped") else ("not run" if "not run" in step["error"] else "error")
        )
    value = step.get(key)
    return "-" if value is None else (f"{value:.1f}" if value < 100 else f"{value:.0f}")


def table(path: Path) -> str:
    """A Markdown table of a ``parts_sweep.json``: seconds per step and the geometry's peak memory."""
    rows = json.loads(Path(path).read_text())["rows"]
    head = [
        "kind",
        "parts",
        "prepare s",
        "sampling s",
        "FPS s",
        "groups s",
        "search structures s",
        "geometry peak MB",
        "render start + picture s",
        "score s",
        "official prepare s",
        "groups (largest)",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        g, rd, sc, of, pr = (r.get(k, {}) for k in ("geometry", "render", "score", "official", "prepare"))
        render = _cell(rd, "start_s") if not rd or "error" in rd else f"{rd['start_s']:.1f} + {rd['picture_s']:.1f}"
        groups = "-" if not g or "error" in g else f"{g['n_groups']} ({g['group_sizes'][0]})"
        cells = [
            r["kind"],
            str(r["parts"]),
            _cell(pr, "prepare_s"),
            _cell(g, "sampling_s"),
            _cell(g, "fps_s"),
            _cell(g, "groups_s"),
            _cell(g, "index_s"),
            _cell(g, "peak_rss_mb"),
            render,
            _cell(sc, "score_s"),
            _cell(of, "prepare_s"),
            groups,
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def candidates(kind: str, n: int) -> dict:
    """The equivalence search's pairs on an object of ``kind`` (the boxes sampled directly, in
    their own frames: the groups do not depend on the layout): all of them, those the rigid
    bound leaves (``aw.shape_bounds``), and those the rotation bound then leaves
    (``aw.rotation_bound``, one thread), with its seconds (box frames included)."""
    import trimesh

    from aw.pair_search import candidate_pairs
    from aw.rotation_bound import box_frame, rules_out
    from aw.shape_bounds import cloud_bounds, lower_bounds
    from aw_eval.equivalence import part_frames
    from aw_eval.geometry import part_divisor
    from aw_eval.sampling import part_clouds
    from aw_eval.settings import ProtocolSettings

    settings = ProtocolSettings()
    meshes = [trimesh.creation.box(extents=e) for e in part_extents(n, kind)]
    divisor = max(part_divisor(np.asarray(m.vertices)) for m in meshes)
    clouds = part_frames(part_clouds(meshes, settings), divisor)
    rigid = candidate_pairs(lower_bounds(cloud_bounds(np.stack(clouds))), settings.equiv_cd)
    rules_out(box_frame(clouds[0]), box_frame(clouds[0]), settings.equiv_cd)  # compiled before the clock starts
    start = time.perf_counter()
    frames = {int(i): box_frame(clouds[i]) for i in np.unique(rigid)}
    left = sum(not rules_out(frames[i], frames[j], settings.equiv_cd) for i, j in rigid.tolist())
    return {
        "pairs": n * (n - 1) // 2,
        "rigid_candidates": len(rigid),
        "rotation_candidates": int(left),
        "rotation_s": time.perf_counter() - start,
    }


def time_groups(path: Path) -> dict:
    """CPU and wall seconds of ``aw_eval.equivalence.equivalence_groups`` on the clouds a geometry
    step saved, with whichever checkout ``PYTHONPATH`` names (older ones included)."""
    import aw_eval.equivalence as eq

    with np.load(path) as z:
        clouds, divisor = z["clouds"], float(z["divisor"])
    quiet = {"show_progress": False} if "show_progress" in eq.equivalence_groups.__code__.co_varnames else {}
    eq.equivalence_groups(clouds[:2], divisor, **quiet)  # compiled kernels loaded before the clock starts
    cpu, wall = time.process_time(), time.perf_counter()
    groups = eq.equivalence_groups(clouds, divisor, **quiet)
    return {
        "module": eq.__file__,
        "cpu_s": time.process_time() - cpu,
        "wall_s": time.perf_counter() - wall,
        "groups": groups,
    }


def time_icp(path: Path) -> dict:
    """CPU seconds of the search structures of one checkpoint (the initial layout) and of the ICP
    of every ``len(starts) // 6``-th start, with whichever checkout ``PYTHONPATH`` names."""
    import aw_eval
    from aw_eval.geometry import TaskGeometry
    from aw_eval.registration import checkpoint_starts

    geom = TaskGeometry.load(path)
    ck = geom.checkpoint(np.tile([0.0, 0, 0, 1, 0, 0, 0], (geom.n_parts, 1)))
    cpu = time.process_time()
    prob = geom.index().assembly_problem(ck.poses, ck.rotations, ck.parts, geom.divisor)
    structures = time.process_time() - cpu
    r0, t0 = checkpoint_starts(geom, ck)
    prob.run(r0[0], t0[0], 2, 1e-9)  # compiled kernels loaded before the clock starts
    cpu = time.process_time()
    runs = [prob.run(r0[k], t0[k], 100, 1e-9) for k in range(0, len(r0), max(1, len(r0) // 6))]
    return {
        "module": aw_eval.__file__,
        "structures_cpu_s": structures,
        "icp_cpu_s": time.process_time() - cpu,
        "objectives": [r.objective for r in runs],
        "iterations": [r.iterations for r in runs],
    }


def main() -> None:
    if len(sys.argv) == 3 and sys.argv[1] == "--time-icp":
        print(json.dumps(time_icp(Path(sys.argv[2]))))
        return
    if len(sys.argv) == 3 and sys.argv[1] == "--time-groups":
        print(json.dumps(time_groups(Path(sys.argv[2]))))
        return
    if len(sys.argv) == 3 and sys.argv[1] == "--table":
        print(table(Path(sys.argv[2])))
        return
    if len(sys.argv) == 4 and sys.argv[1] == "--candidates":
        for n in (int(v) for v in sys.argv[3].split(",")):
            c = candidates(sys.argv[2], n)
            print(
                f"{sys.argv[2]} {n} parts: {c['pairs']} pairs; {c['rigid_candidates']} left by the rigid bound, "
                f"{c['rotation_candidates']} by the rotation bound ({c['rotation_s']:.1f} s, one thread)"
            )
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="folder for the generated objects, suites and parts_sweep.json")
    ap.add_argument("--parts", default="2,10,20,50,100,200,500", help="part counts, comma-separated")
    ap.add_argument("--kinds", default="distinct,identical,replicas", help=f"object kinds of {KINDS}, comma-separated")
    ap.add_argument("--replicas-max", type=int, default=20, help="largest part count of the replicas kind (default 20)")
    ap.add_argument("--official-max", type=int, default=500, help="largest part count prepared by --protocol official")
    ap.add_argument("--steps", default="prepare,geometry,render,score,official", help="steps to run, comma-separated")
    ap.add_argument("--limit-s", type=float, default=900.0, help="a step running longer is stopped (default 900)")
    args = ap.parse_args()
    out_dir = Path(args.out)
    result_path = output_file(out_dir, "parts_sweep.json")
    steps = args.steps.split(",")
    rows = []
    for kind in args.kinds.split(","):
        stopped: set[str] = set()  # a step stopped at some part count is not run at larger ones
        for n in (int(v) for v in args.parts.split(",")):
            if kind == "replicas" and n > args.replicas_max:
                continue
            src = make_object(out_dir / "objects" / f"{kind}{n:03d}", n, kind)
            row = {"kind": kind, "parts": n}
            suite = out_dir / "suites" / f"{kind}{n:03d}"
            if "prepare" in steps or {"geometry", "render", "score"} & set(steps):
                row["prepare"] = _prepare(src, suite, "native", args.limit_s)
            for name in ("geometry", "render", "score"):
                if name in stopped or (name == "score" and "error" in row.get("geometry", {})):
                    row[name] = {"error": "not run (stopped at fewer parts)"} if name in stopped else row.get(name)
                elif name in steps and "error" not in row.get("prepare", {}):
                    row[name] = _run([sys.executable, __file__, "_step", name, str(suite)], args.limit_s)
            if "official" in steps and n <= args.official_max:
                if "official" in stopped:
                    row["official"] = {"error": "not run (stopped at fewer parts)"}
                else:
                    row["official"] = _prepare(
                        src, out_dir / "suites" / f"{kind}{n:03d}-official", "official", args.limit_s
                    )
            row = {k: v for k, v in row.items() if v is not None}
            stopped |= {
                k for k, v in row.items() if isinstance(v, dict) and str(v.get("error", "")).startswith("stopped")
            }
            row["load_average"] = os.getloadavg()[0]
            rows.append(row)
            print(json.dumps(row), flush=True)
    meta = {
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "cpus": os.cpu_count(),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
    }
    result_path.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1) + "\n")
    print(f"wrote {result_path}")


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "_step":
        _in_process(sys.argv[2], sys.argv[3])
    else:
        main()
