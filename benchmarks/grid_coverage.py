"""How many of the jax backend's neighbour queries fall back to brute force, at the starts and at
the final registration of real checkpoints: leaf-box certificates against the cell grids they
replaced, on the same queries.

    .venv/bin/python benchmarks/grid_coverage.py --parts 2 8 20 --n-fps 1000 --checkpoints 2 --out OUT

Per checkpoint (synthetic task and trajectory, :mod:`aw_eval.fixtures`): the numba backend's
registration, then the queries of both directions at every start's transform and at the final
one, replayed on the host through the same lookups as the XLA code. Leaves
(:func:`aw_eval.kernels.leafbox.leaf_lookup`, for each ``(S, C)`` of ``--leaf``): forward, the
joined target's leaves; backward, the target points mapped into every part's baked frame, all
parts' leaves as one list. Grids (``--grid``, the design before: the cell-grid module at commit
a61f6f7, imported from ``--grid-src``): forward, the joined target's grid; backward, a part
skipped where its grid does not answer only when its box is farther than the best found. Also
each structure's build seconds (once per task).
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


def _grid_module(path: Path | None):
    """The cell-grid module (removed from the package; ``git show a61f6f7:aw_eval/kernels/cellgrid.py``)."""
    if path is None:
        return None
    import importlib.util

    spec = importlib.util.spec_from_file_location("old_cellgrid", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _grid_answered(cg, grids, queries: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """``(k,)`` bool: the grids of ``grids`` (the old module's ``PartGrids``) answer ``queries
    (P, k, 3)`` (each part's frame) exactly; ``pts (P, n, 3)`` the parts' points in those frames."""
    n_parts, k = queries.shape[:2]
    best = np.full(k, np.inf)
    ok = np.zeros((n_parts, k), bool)
    lb = np.zeros((n_parts, k))
    for q in range(n_parts):
        g = cg.CellGrid(
            grids.lo[q],
            grids.inv_h[q],
            grids.dims[q].astype(np.int64),
            grids.depth,
            grids.child[q],
            grids.cand[q],
            grids.over[q],
            None,
        )
        node, inside = cg.leaf_of(g, queries[q])
        ok[q] = inside & ~grids.over[q][node]
        cand = grids.cand[q][node] - q * pts.shape[1]
        d = np.sum((queries[q][:, None, :] - pts[q][cand]) ** 2, axis=-1).min(axis=1)
        best = np.minimum(best, np.where(ok[q], d, np.inf))
        gap = np.maximum(np.maximum(grids.box_lo[q] - queries[q], queries[q] - grids.box_hi[q]), 0.0)
        lb[q] = np.sum(gap * gap, axis=1)
    return ~np.any(~ok & (lb <= best[None]), axis=0)


def _chunks(k: int, size: int = 2000):
    return [slice(a, min(k, a + size)) for a in range(0, k, size)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", type=int, nargs="+", default=[8], help="part counts, one task each")
    ap.add_argument("--n-fps", type=int, default=1000, help="points per part (paper: 1000)")
    ap.add_argument("--checkpoints", type=int, default=2, help="checkpoints per part count")
    ap.add_argument(
        "--leaf",
        type=int,
        nargs=2,
        action="append",
        metavar=("S", "C"),
        help="leaf size and leaves read per query (repeatable; default 32 4 and 16 8)",
    )
    ap.add_argument(
        "--grid-module",
        type=Path,
        default=None,
        metavar="FILE",
        help="the removed cellgrid.py to compare with (default: leaves only)",
    )
    ap.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder to write the JSON to (a new file)")
    ap.add_argument("--name", default="grid_coverage", help="the JSON file's name in --out, without .json")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from _output import output_file

    path = output_file(args.out, f"{args.name}.json")
    import aw_eval
    from aw_eval.fixtures import make_points_geometry, trajectory_checkpoints
    from aw_eval.kernels.leafbox import build_leaf_boxes, build_part_leaves, leaf_lookup
    from aw_eval.registration import checkpoint_starts, jax_part_maps, register_exact

    cg = _grid_module(args.grid_module)
    leaf_cfgs = [tuple(x) for x in (args.leaf or [(32, 4), (16, 8)])]
    out = {"command": " ".join(["benchmarks/grid_coverage.py"] + sys.argv[1:]), "rows": []}
    for parts in args.parts:
        settings = aw_eval.ProtocolSettings(n_fps=args.n_fps, n_surface=max(4096, 4 * args.n_fps))
        geom, obj = make_points_geometry(parts, args.n_fps, seed=parts, settings=settings)
        target = geom.index().target
        baked = geom.clouds / geom.divisor
        structs, build = {}, {}
        for s_, c_ in leaf_cfgs:
            t0 = time.perf_counter()
            structs[f"leaves_S{s_}_C{c_}"] = (build_leaf_boxes(target, s_), build_part_leaves(baked, s_), c_)
            build[f"leaves_S{s_}_C{c_}"] = time.perf_counter() - t0
        if cg is not None:
            t0 = time.perf_counter()
            structs["grid"] = (
                cg.build_part_grids(target[None], k=cg.JOINED_K, margin_cells=cg.JOINED_MARGIN_CELLS),
                cg.build_part_grids(baked),
                None,
            )
            build["grid"] = time.perf_counter() - t0
        cks = np.unique(trajectory_checkpoints(obj, 8 * args.checkpoints, seed=1000 + parts), axis=0)[
            : args.checkpoints
        ]
        for c in cks:
            ck = geom.checkpoint(c)
            maps = jax_part_maps(geom, [ck])[0]
            r0, t0_ = checkpoint_starts(geom, ck)
            reg = register_exact(geom, ck)
            row = {"parts": parts, "points_per_part": args.n_fps}
            for name, (ts, ps, cand) in structs.items():
                row[name] = {"build_s_once_per_task": round(build[name], 4)}
                for label, transforms in (
                    ("starts", list(zip(r0, t0_, strict=True))),
                    ("final", [(reg.rotation, reg.translation)]),
                ):
                    fwd, bwd = [], []
                    for r, t in transforms:
                        x = ck.points @ r.T + t
                        z = (target - t) @ r  # R^T (T - t)
                        y = np.einsum("mk,pjk->pmj", z, maps[:, :, :3]) + maps[:, None, :, 3]
                        if cand is None:
                            fwd.append(_grid_answered(cg, ts, x[None], target[None]))
                            bwd.append(_grid_answered(cg, ps, y, baked))
                            continue
                        fwd += [leaf_lookup(ts, x[None, sl], x[sl], target, cand)[1] for sl in _chunks(len(x))]
                        bwd += [leaf_lookup(ps, y[:, sl], target[sl], x, cand)[1] for sl in _chunks(len(target))]
                    row[name][f"{label}_forward_brute_share"] = float(1 - np.concatenate(fwd).mean())
                    row[name][f"{label}_backward_brute_share"] = float(1 - np.concatenate(bwd).mean())
            out["rows"].append(row)
            print(json.dumps(row), flush=True)
            path.write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
