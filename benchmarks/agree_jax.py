"""Agreement sweep: the ``jax`` backend against numba ``exact`` on many checkpoints.

    nice .venv/bin/python benchmarks/agree_jax.py --parts 2 5 10 20 --n-fps 1000 --checkpoints 250 --out OUT
    # what this repository's 2-core machine ran (reduced resolution)
    JAX_PLATFORMS=cpu nice .venv/bin/python benchmarks/agree_jax.py --parts 2 3 5 --n-fps 24 --checkpoints 64 --out OUT

Per part count: one synthetic task (:mod:`aw_eval.fixtures`, identical legs included) and
distinct agent-like trajectory checkpoints, scored by both backends; then the same checkpoints
again under thresholds moved to 1e-7 relative above and below the median part error and SCD that
numba measured (knife edges: decisions that rounding alone would flip if the backends differed
by more). Counts identical PA, SR and SR^a, the largest relative SCD and part-error differences
(SCDs and errors below 1e-20 are rounding noise of exact registrations in both) and the
part errors within 1e-6 relative of the threshold. Writes ``OUT/NAME.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(ROOT / ".jax_cache"))


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    big = np.maximum(np.abs(a), np.abs(b))
    rel = np.where(big < 1e-20, 0.0, np.abs(a - b) / np.maximum(big, 1e-300))
    return float(rel.max()) if rel.size else 0.0


def compare(geom, cks) -> dict:
    import aw_eval

    n = aw_eval.score_batch(geom, cks, mode="exact", backend="numba")
    j = aw_eval.score_batch(geom, cks, mode="exact", backend="jax")
    thr = geom.settings.threshold
    return {
        "checkpoints": int(len(cks)),
        "identical_pa": int(np.sum(n.pa == j.pa)),
        "identical_sr": int(np.sum(n.sr == j.sr)),
        "identical_sra": int(np.sum(n.sra == j.sra)),
        "max_rel_scd": _rel(n.scd, j.scd),
        "max_rel_part_error": _rel(n.part_errors, j.part_errors),
        "part_errors_within_1e-6_of_threshold": int(np.sum(np.abs(n.part_errors / thr - 1) <= 1e-6)),
        # the jax lookups that the leaves certified (the rest took the brute-force path)
        "jax_queries": int(j.stats["jax"].get("queries", 0)),
        "jax_brute_queries": int(j.stats["jax"].get("brute_queries", 0)),
        "numba": n,
        "jax": j,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", type=int, nargs="+", default=[2, 5, 10, 20], help="part counts, one task each")
    ap.add_argument("--n-fps", type=int, default=1000, help="points per part (paper: 1000)")
    ap.add_argument("--checkpoints", type=int, default=250, help="distinct checkpoints per part count")
    ap.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder to write the JSON to (a new file)")
    ap.add_argument("--name", default="agree_jax", help="the JSON file's name in --out, without .json")
    ap.add_argument(
        "--candidates",
        type=int,
        default=None,
        metavar="C",
        help="leaves a jax query reads (default the backend's); fewer than the clouds' leaves at small "
        "--n-fps makes the lookups take the certified path (and its fallback) instead of reading every leaf",
    )
    ap.add_argument("--no-knife-edges", action="store_true", help="score the protocol's thresholds only")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from _output import output_file

    path = output_file(args.out, f"{args.name}.json")

    import aw_eval
    from aw_eval.fixtures import make_points_geometry, trajectory_checkpoints
    from aw_eval.kernels.jaxcfg import jax_modules

    jax, _ = jax_modules()
    if args.candidates is not None:
        from aw_eval.kernels import jax_icp

        jax_icp.CANDIDATES = args.candidates
    out = {"command": " ".join(["benchmarks/agree_jax.py"] + sys.argv[1:]), "device": str(jax.devices()[0]), "rows": []}
    t0 = time.perf_counter()
    for parts in args.parts:
        settings = aw_eval.ProtocolSettings(n_fps=args.n_fps, n_surface=max(64, 4 * args.n_fps))
        geom, obj = make_points_geometry(parts, args.n_fps, seed=parts, settings=settings)
        cks = np.unique(trajectory_checkpoints(obj, 4 * args.checkpoints, seed=2000 + parts), axis=0)[
            : args.checkpoints
        ]
        base = compare(geom, cks)
        rows = [("protocol", base)]
        errors = base["numba"].part_errors[base["numba"].part_errors > 1e-12]
        scds = base["numba"].scd[base["numba"].scd > 1e-12]
        for sign in () if args.no_knife_edges else (-1.0, 1.0):
            if not (len(errors) and len(scds)):
                break
            st = dataclasses.replace(
                settings,
                threshold=float(np.sort(errors)[len(errors) // 2]) * (1 + sign * 1e-7),
                sra_threshold=float(np.sort(scds)[len(scds) // 2]) * (1 + sign * 1e-7),
            )
            knife, _ = make_points_geometry(parts, args.n_fps, seed=parts, settings=st)
            rows.append((f"knife_edge_{'below' if sign < 0 else 'above'}", compare(knife, cks)))
        for label, r in rows:
            r = {k: v for k, v in r.items() if k not in ("numba", "jax")}
            out["rows"].append({"parts": parts, "points_per_part": args.n_fps, "thresholds": label, **r})
            print(json.dumps(out["rows"][-1]), flush=True)
        _total(out, t0)
        path.write_text(json.dumps(out, indent=2) + "\n")  # after each part count: a time limit keeps the rest
    print(json.dumps(out["total"], indent=2))
    print(f"wrote {path}")


def _total(out: dict, t0: float) -> None:
    rows = out["rows"]
    out["total"] = {
        "scored_checkpoints": sum(r["checkpoints"] for r in rows),
        "distinct_checkpoints": sum(r["checkpoints"] for r in rows if r["thresholds"] == "protocol"),
        "identical_pa_sr_sra": sum(min(r["identical_pa"], r["identical_sr"], r["identical_sra"]) for r in rows),
        "max_rel_scd": max(r["max_rel_scd"] for r in rows),
        "max_rel_part_error": max(r["max_rel_part_error"] for r in rows),
        "knife_edge_part_errors": sum(r["part_errors_within_1e-6_of_threshold"] for r in rows),
        "seconds": round(time.perf_counter() - t0, 1),
        "load_average_after": os.getloadavg(),
    }


if __name__ == "__main__":
    main()
