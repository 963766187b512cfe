"""How many of the jax backend's neighbour queries its cell grids answer, and how many fall back
to brute force, at the starts and at the final registration of real checkpoints.

    .venv/bin/python benchmarks/grid_coverage.py --parts 8 --n-fps 1000 --checkpoints 2 --out OUT

Per checkpoint (synthetic task and trajectory, :mod:`aw_eval.fixtures`): the numba backend's
registration, then the queries of both directions at every start's transform and at the final
one, replayed on the host through the same lookups as the XLA code
(:func:`aw_eval.kernels.cellgrid.leaf_of`): forward, the joined target's grid; backward, the
target points mapped into every part's baked frame, a part skipped where its grid does not
answer only when its box is farther than the best found. Also the grids' build seconds.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _answered(grids, queries: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """``(k,)`` bool: the grids of :class:`PartGrids` ``grids`` answer ``queries (P, k, 3)`` (each
    part's frame) exactly; ``pts (P, n, 3)`` the parts' points in those frames."""
    from aw_eval.kernels.cellgrid import CellGrid, leaf_of

    n_parts, k = queries.shape[:2]
    best = np.full(k, np.inf)
    ok = np.zeros((n_parts, k), bool)
    lb = np.zeros((n_parts, k))
    for q in range(n_parts):
        g = CellGrid(grids.lo[q], grids.inv_h[q], grids.dims[q].astype(np.int64), grids.depth, grids.child[q],
                     grids.cand[q], grids.over[q], None)
        node, inside = leaf_of(g, queries[q])
        ok[q] = inside & ~grids.over[q][node]
        cand = grids.cand[q][node] - q * pts.shape[1]
        d = np.sum((queries[q][:, None, :] - pts[q][cand]) ** 2, axis=-1).min(axis=1)
        best = np.minimum(best, np.where(ok[q], d, np.inf))
        gap = np.maximum(np.maximum(grids.box_lo[q] - queries[q], queries[q] - grids.box_hi[q]), 0.0)
        lb[q] = np.sum(gap * gap, axis=1)
    return ~np.any(~ok & (lb <= best[None]), axis=0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", type=int, nargs="+", default=[8])
    ap.add_argument("--n-fps", type=int, default=1000)
    ap.add_argument("--checkpoints", type=int, default=2)
    ap.add_argument("--out", type=Path, required=True, metavar="DIR")
    ap.add_argument("--name", default="grid_coverage")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from _output import output_file

    path = output_file(args.out, f"{args.name}.json")
    import aw_eval
    from aw_eval.fixtures import make_points_geometry, trajectory_checkpoints
    from aw_eval.registration import checkpoint_starts, jax_part_maps, register_exact

    out = {"command": " ".join(["benchmarks/grid_coverage.py"] + sys.argv[1:]), "rows": []}
    for parts in args.parts:
        settings = aw_eval.ProtocolSettings(n_fps=args.n_fps, n_surface=max(4096, 4 * args.n_fps))
        geom, obj = make_points_geometry(parts, args.n_fps, seed=parts, settings=settings)
        t0 = time.perf_counter()
        tg, pg = geom.index().part_grids(geom.divisor)
        build = time.perf_counter() - t0
        target = geom.index().target
        baked = geom.clouds / geom.divisor
        cks = np.unique(trajectory_checkpoints(obj, 8 * args.checkpoints, seed=1000 + parts), axis=0)[: args.checkpoints]
        for c in cks:
            ck = geom.checkpoint(c)
            maps = jax_part_maps(geom, [ck])[0]
            r0, t0_ = checkpoint_starts(geom, ck)
            reg = register_exact(geom, ck)
            row = {"parts": parts, "points_per_part": args.n_fps, "grids_build_s": round(build, 2)}
            for label, transforms in (("starts", list(zip(r0, t0_))), ("final", [(reg.rotation, reg.translation)])):
                fwd, bwd = [], []
                for r, t in transforms:
                    x = ck.points @ r.T + t
                    fwd.append(_answered(tg, x[None], target[None]))
                    z = (target - t) @ r  # R^T (T - t)
                    y = np.einsum("mk,pjk->pmj", z, maps[:, :, :3]) + maps[:, None, :, 3]
                    bwd.append(_answered(pg, y, baked))
                row[f"{label}_forward_brute_share"] = float(1 - np.concatenate(fwd).mean())
                row[f"{label}_backward_brute_share"] = float(1 - np.concatenate(bwd).mean())
            out["rows"].append(row)
            print(json.dumps(row), flush=True)
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
