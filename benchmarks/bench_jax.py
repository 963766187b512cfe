"""The ``jax`` backend against ``numba`` in ``exact`` mode, on the same checkpoints in one process.

    # the issue's measurement (2, 8, 20 parts at paper resolution), on a GPU: benchmarks/device_jax.sh
    .venv/bin/python benchmarks/bench_jax.py --parts 2 8 20 --n-fps 1000 --checkpoints 256 --numba 8 --out OUT
    # on this repository's CPU-only machine (reduced resolution)
    JAX_PLATFORMS=cpu .venv/bin/python benchmarks/bench_jax.py --parts 2 --n-fps 100 --checkpoints 16 --chunk 16 --numba 16 --out OUT

Synthetic geometry and agent-like trajectory checkpoints (:mod:`aw_eval.fixtures`), per part
count. Times the task's leaf boxes (built once per task on the host: the joined target's and
the parts' baked clouds', :mod:`aw_eval.kernels.leafbox`), then
``score_batch(mode="exact", backend="jax")`` cold (its first chunk, compilation included) and
warm (every checkpoint again, compiled), split into stages (leaf boxes, ICP, part CDs, host work),
with the ICP's lane counters: lanes computed (padding included) against the iterations the
protocol needed, and the share of neighbour queries the leaves did not certify (brute force).
Then ``backend="numba"`` on the first ``--numba`` checkpoints: identical PA/SR and SCD within
1e-9 relative are checked on those, and the ratio is taken on the same checkpoints. The projection to 60,000 checkpoints
is the warm rate times 60,000, labelled as a projection. ``JAX_PLATFORMS`` picks the device
as usual (default: an accelerator when JAX sees one).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(ROOT / ".jax_cache"))

STUDY_CHECKPOINTS = 60_000


def one_part_count(parts: int, args) -> dict:
    import aw_eval
    from aw_eval.fixtures import make_points_geometry, trajectory_checkpoints
    from aw_eval.kernels.jax_icp import max_lanes
    from aw_eval.kernels.leafbox import DEFAULT_CANDIDATES

    settings = aw_eval.ProtocolSettings(n_fps=args.n_fps, n_surface=max(4096, 4 * args.n_fps))
    geom, obj = make_points_geometry(parts, args.n_fps, seed=parts, settings=settings)
    # distinct states only (score_batch scores each unique row once)
    cks = np.unique(trajectory_checkpoints(obj, 4 * args.checkpoints, seed=1000 + parts), axis=0)[: args.checkpoints]
    geom.index()
    t0 = time.perf_counter()
    geom.index()._leaves = None  # time a fresh build
    leaves = geom.index().part_leaves(geom.divisor)
    leaf_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    aw_eval.score_batch(geom, cks[: args.chunk], mode="exact", backend="jax")
    cold = time.perf_counter() - t0
    t0 = time.perf_counter()
    j = aw_eval.score_batch(geom, cks, mode="exact", backend="jax")
    warm = time.perf_counter() - t0
    k = min(args.numba, len(cks))
    aw_eval.score(geom, cks[-1], mode="exact", backend="numba")  # the task's search structures, built once
    t0 = time.perf_counter()
    n = aw_eval.score_batch(geom, cks[:k], mode="exact", backend="numba")
    numba_s = time.perf_counter() - t0

    st = j.stats["jax"]
    jax_per_ck, numba_per_ck = warm / len(cks), numba_s / max(k, 1)
    rel = np.abs(j.scd[:k] - n.scd) / np.maximum(np.maximum(j.scd[:k], n.scd), 1e-300)
    tiny = np.maximum(j.scd[:k], n.scd) < 1e-20  # exact registrations: both are rounding noise
    return {
        "parts": parts,
        "points_per_part": args.n_fps,
        "checkpoints": int(len(cks)),
        "chunk": args.chunk,
        "leaf_boxes_once_per_task_s": round(leaf_s, 4),
        "lanes_per_call_at_most": max_lanes(len(geom.index().target), len(geom.index().target)),
        "leaves_target_parts": [int(a.index.shape[1]) for a in leaves],
        "leaf_size": int(leaves[0].index.shape[2]),
        "leaves_read_per_query": DEFAULT_CANDIDATES,
        "jax_first_chunk_s_incl_compile": round(cold, 2),
        "jax_first_chunk_s_per_ck_incl_compile": cold / min(args.chunk, len(cks)),
        "jax_warm_s_per_ck": jax_per_ck,
        "warm_stage_s_per_ck": {s: st[s] / len(cks) for s in ("structures", "icp", "part_cd", "host")},
        "lanes_computed": int(st["lanes_iterated"]),
        "lane_iterations_needed": int(st["lane_iterations"]),
        "rounds": int(st["rounds"]),
        "brute_force_queries": int(st["brute_queries"]),
        "brute_force_share_of_queries": st["brute_queries"] / max(st["queries"], 1),
        "numba_checkpoints": k,
        "numba_s_per_ck": numba_per_ck,
        "jax_over_numba_speed": numba_per_ck / jax_per_ck,
        "identical_pa_sr": int(np.sum((j.pa[:k] == n.pa) & (j.sr[:k] == n.sr))),
        "max_rel_scd": float(np.max(np.where(tiny, 0.0, rel))) if k else None,
        "projected_minutes_for_60000_checkpoints (warm rate x 60,000: a projection)": jax_per_ck
        * STUDY_CHECKPOINTS
        / 60,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", type=int, nargs="+", default=[2, 8, 20], help="part counts, one task each")
    ap.add_argument("--n-fps", type=int, default=1000, help="points per part (paper: 1000)")
    ap.add_argument("--checkpoints", type=int, default=64, help="checkpoints scored by jax per part count")
    ap.add_argument("--chunk", type=int, default=32, help="checkpoints per jax call (aw_eval.scoring.JAX_CHUNK)")
    ap.add_argument("--numba", type=int, default=4, help="of those, how many numba scores too (agreement, ratio)")
    ap.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder to write the JSON to (a new file)")
    ap.add_argument("--name", default="bench_jax", help="the JSON file's name in --out, without .json")
    ap.add_argument(
        "--leaf-elements",
        type=int,
        metavar="N",
        help="the leaf lookups' budget of box distances held at once (default: jax_icp.leaf_elements())",
    )
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from _output import output_file

    path = output_file(args.out, f"{args.name}.json")  # refused before the run, not after it

    import aw_eval.scoring
    from aw_eval.kernels import jax_icp
    from aw_eval.kernels.jaxcfg import jax_modules
    from aw_eval.registration import resolve_backend

    jax, _ = jax_modules()
    aw_eval.scoring.JAX_CHUNK = args.chunk
    if args.leaf_elements:
        jax_icp.LEAF_ELEMENTS = jax_icp.ACCELERATOR_LEAF_ELEMENTS = args.leaf_elements
    out = {
        "command": " ".join(["benchmarks/bench_jax.py"] + sys.argv[1:]),
        "device": str(jax.devices()[0]),
        "platform": jax.devices()[0].platform,
        "jax": jax.__version__,
        "auto_backend_for_exact": resolve_backend("auto", "exact"),
        "leaf_elements": jax_icp.leaf_elements(),
        "per_part_count": [],
    }
    for parts in args.parts:
        out["per_part_count"].append(one_part_count(parts, args))
        print(json.dumps(out["per_part_count"][-1], indent=2), flush=True)
        out["load_average_after"] = os.getloadavg()
        path.write_text(json.dumps(out, indent=2) + "\n")  # after each part count: a time limit keeps the rest
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
