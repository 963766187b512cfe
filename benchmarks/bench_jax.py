"""The ``jax`` backend against ``numba`` in ``exact`` mode, on the same checkpoints in one process.

    # the issue's target measurement: 8 parts at paper resolution, on a GPU (not run here)
    .venv/bin/python benchmarks/bench_jax.py --parts 8 --n-fps 1000 --checkpoints 256 --numba 8 --out OUT
    # what this repository's CPU-only machine measured (reduced resolution)
    JAX_PLATFORMS=cpu .venv/bin/python benchmarks/bench_jax.py --parts 2 --n-fps 100 --checkpoints 16 --numba 16 --out OUT

Synthetic geometry and agent-like trajectory checkpoints (:mod:`aw_eval.fixtures`). Times
``score_batch(mode="exact", backend="jax")`` cold (compilation included) and warm, and
``backend="numba"`` on the first ``--numba`` checkpoints; checks identical PA/SR and SCD within
1e-9 relative on those; projects the warm throughput to 60,000 checkpoints (a projection from
the measured rate, labelled as such). ``JAX_PLATFORMS`` picks the device as usual (default:
an accelerator when JAX sees one).
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", type=int, default=8)
    ap.add_argument("--n-fps", type=int, default=1000, help="points per part (paper: 1000)")
    ap.add_argument("--checkpoints", type=int, default=64, help="checkpoints scored by jax (a multiple of --chunk)")
    ap.add_argument("--chunk", type=int, default=32, help="checkpoints per jax call (aw_eval.scoring.JAX_CHUNK)")
    ap.add_argument("--numba", type=int, default=4, help="of those, how many numba scores too (agreement, ratio)")
    ap.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder to write the JSON to (a new file)")
    ap.add_argument("--name", default="bench_jax", help="the JSON file's name in --out, without .json")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from _output import output_file

    path = output_file(args.out, f"{args.name}.json")  # refused before the run, not after it

    import aw_eval
    import aw_eval.scoring
    from aw_eval.fixtures import make_points_geometry, trajectory_checkpoints
    from aw_eval.kernels.jaxcfg import jax_modules

    jax, _ = jax_modules()
    aw_eval.scoring.JAX_CHUNK = args.chunk
    settings = aw_eval.ProtocolSettings(n_fps=args.n_fps, n_surface=max(4096, 4 * args.n_fps))
    geom, obj = make_points_geometry(args.parts, args.n_fps, seed=args.parts, settings=settings)
    # distinct states only (score_batch scores each unique row once)
    cks = np.unique(trajectory_checkpoints(obj, 4 * args.checkpoints, seed=1000 + args.parts), axis=0)[: args.checkpoints]

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

    jax_per_ck, numba_per_ck = warm / len(cks), numba_s / max(k, 1)
    rel = np.abs(j.scd[:k] - n.scd) / np.maximum(np.maximum(j.scd[:k], n.scd), 1e-300)
    tiny = np.maximum(j.scd[:k], n.scd) < 1e-20  # exact registrations: both are rounding noise
    out = {
        "command": " ".join(["benchmarks/bench_jax.py"] + sys.argv[1:]),
        "device": str(jax.devices()[0]), "platform": jax.devices()[0].platform,
        "parts": args.parts, "points_per_part": args.n_fps, "checkpoints": int(len(cks)), "chunk": args.chunk,
        "jax_first_chunk_s_incl_compile": round(cold, 2), "jax_s_per_ck": jax_per_ck,
        "numba_checkpoints": k, "numba_s_per_ck": numba_per_ck, "jax_over_numba_speed": numba_per_ck / jax_per_ck,
        "identical_pa_sr": int(np.sum((j.pa[:k] == n.pa) & (j.sr[:k] == n.sr))),
        "max_rel_scd": float(np.max(np.where(tiny, 0.0, rel))) if k else None,
        "projected_minutes_for_60000_checkpoints (from the measured rate)": jax_per_ck * STUDY_CHECKPOINTS / 60,
        "load_average_after": os.getloadavg(),
    }
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
