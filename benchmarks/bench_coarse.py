"""Time ``fast``'s coarse stage (``aw_eval.kernels.fast.coarse_icp``: every start on a few samples per part).

Same inputs at every run (random clouds, 24 + P random starts, 8 ICP iterations, ``--samples``
points per part), median of
``--repeat`` calls after a warm-up call (compilation apart). ``--repo`` times the stage of
another checkout, e.g. the JAX version of the previous round::

    git worktree add /tmp/aw-b1ee0b0 b1ee0b0
    .venv/bin/python benchmarks/bench_coarse.py --repo /tmp/aw-b1ee0b0   # JAX, parts padded
    .venv/bin/python benchmarks/bench_coarse.py                          # this checkout
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", type=Path, default=Path(__file__).resolve().parents[1])
    ap.add_argument("--parts", type=int, nargs="+", default=[2, 5, 10, 20])
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--samples", type=int, default=8, help="points per part (FastSettings.coarse)")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(args.repo.resolve()))
    os.environ.setdefault("JAX_PLATFORMS", "cpu")
    os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(args.repo.resolve() / ".jax_cache"))
    from scipy.spatial.transform import Rotation

    from aw_eval.kernels.fast import coarse_icp

    print(f"coarse stage of {args.repo.resolve()}, {args.samples} points per part")
    rng = np.random.default_rng(0)
    for p in args.parts:
        pred = rng.normal(size=(p, 1000, 3))
        target = pred @ Rotation.random(random_state=p).as_matrix().T * 0.9 + 0.01
        n_starts = 24 + p
        r0 = Rotation.random(n_starts, random_state=1).as_matrix()
        t0 = rng.normal(size=(n_starts, 3)) * 0.01
        objs = coarse_icp(pred, target, r0, t0, args.samples, 8, 1e-9)[0]
        times = []
        for _ in range(args.repeat):
            t = time.perf_counter()
            coarse_icp(pred, target, r0, t0, args.samples, 8, 1e-9)
            times.append(time.perf_counter() - t)
        print(
            f"parts={p}: {1000 * np.median(times):.2f} ms per checkpoint ({n_starts} starts), "
            f"objectives sum {objs.sum():.12f}",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
