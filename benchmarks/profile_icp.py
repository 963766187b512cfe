"""Where `exact`'s time goes on one checkpoint: ICP over every start vs the prediction's graph.

Scores the first checkpoint of the benchmark trajectories (as ``bench_eval.py`` does) with every
start of the protocol at full resolution, timing the ICP runs (best of ``--repeat``) apart from
the prediction's Delaunay graph, and counts ICP iterations, query evaluations (points x
evaluations, both directions) and searches (walks or tree searches; the rest were certified).
``--no-graphs`` runs the same ICP on KD-trees alone (the previous round's search) and checks
that the objectives are identical.

    .venv/bin/python benchmarks/profile_icp.py --parts 2 5 10
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import aw_eval  # noqa: E402
from aw_eval.engine import starts_for, task_context  # noqa: E402
from aw_eval.fixtures import make_points_geometry, trajectory_checkpoints  # noqa: E402
from aw_eval.icp import ICPProblem, build_tree, compile_kernels, graph_for  # noqa: E402


def profile(p: int, checkpoint: int, repeat: int, graphs: bool) -> dict:
    st = aw_eval.ProtocolSettings(n_fps=1000, n_surface=4096)
    geom, obj = make_points_geometry(p, 1000, seed=p, settings=st)
    poses = trajectory_checkpoints(obj, checkpoint + 1, seed=1000 + p)[checkpoint]
    ctx = task_context(geom)
    pred = np.ascontiguousarray(geom.pred_parts(poses).reshape(-1, 3))
    r0, t0 = starts_for(pred, ctx.target_frame, poses, geom.target_poses, geom.divisor)
    tree_p = build_tree(pred)
    t = time.perf_counter()
    graph_p = graph_for(tree_p) if graphs else None
    t_graph = time.perf_counter() - t
    prob = ICPProblem(pred, ctx.target, tree_t=ctx.tree_t, tree_p=tree_p,
                      graph_t=ctx.graph_t if graphs else None, graph_p=graph_p)
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        res = [prob.run(r0[k], t0[k], st.max_iters, st.tol) for k in range(len(r0))]
        best = min(best, time.perf_counter() - t)
    iters = sum(r.iterations for r in res)
    evals = (iters + len(r0)) * (len(pred) + len(ctx.target))
    return {"parts": p, "graphs": graphs, "starts": len(r0), "icp_s": best, "prediction_graph_s": t_graph,
            "iterations": iters, "query_evaluations": evals, "searches": sum(r.searched for r in res),
            "ns_per_query_evaluation": 1e9 * best / evals, "objectives": [r.objective for r in res]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", type=int, nargs="+", default=[2, 5, 10])
    ap.add_argument("--checkpoint", type=int, default=0, help="index into the benchmark trajectories")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-graphs", action="store_true", help="also run on KD-trees alone and compare")
    args = ap.parse_args(argv)
    compile_kernels()
    for p in args.parts:
        runs = [profile(p, args.checkpoint, args.repeat, True)]
        if args.no_graphs:
            runs.append(profile(p, args.checkpoint, args.repeat, False))
        for r in runs:
            print(f"parts={p} graphs={r['graphs']}: {r['starts']} starts, {r['iterations']} iterations, ICP {r['icp_s']:.3f} s "
                  f"(best of {args.repeat}), prediction graph {r['prediction_graph_s']:.3f} s, "
                  f"{r['query_evaluations'] / 1e6:.2f} M query evaluations, {r['searches'] / 1e6:.2f} M searches, "
                  f"{r['ns_per_query_evaluation']:.0f} ns per query evaluation", flush=True)
        if args.no_graphs:
            same = runs[0]["objectives"] == runs[1]["objectives"]
            print(f"parts={p}: objectives with and without graphs identical: {same}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
