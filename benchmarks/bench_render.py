"""Offscreen render speed of aw.render on a synthetic industrial assembly (1024x768, default view).

    .venv/bin/python benchmarks/bench_render.py [--platform egl|osmesa] [--block assemblybench]
        [--index 2] [--repeats 5]

Reports renderer start (GL context, mesh upload), the first picture (shader compilation) and the
median of warm pictures, each after moving one part. Timings depend on the CPU rasterizer
(llvmpipe) and on the load of the machine; the script prints the load average with them.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--platform", choices=("egl", "osmesa"), default=None)
    ap.add_argument("--block", default="assemblybench")
    ap.add_argument("--index", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    if args.platform:
        os.environ["PYOPENGL_PLATFORM"] = args.platform

    import numpy as np

    from aw.render import OffscreenRenderer
    from aw.sources.synthetic import generate_object

    meshes = [p.mesh for p in generate_object(args.block, args.index).parts]
    t = time.perf_counter()
    r = OffscreenRenderer(meshes)
    start = time.perf_counter() - t
    t = time.perf_counter()
    r.render()
    first = time.perf_counter() - t
    warm = []
    for k in range(args.repeats):
        poses = np.tile([0.0, 0, 0, 1, 0, 0, 0], (len(meshes), 1))
        poses[k % len(meshes), 0] += 0.1
        t = time.perf_counter()
        r.render(poses)
        warm.append(time.perf_counter() - t)
    r.close()
    faces = sum(len(m.faces) for m in meshes)
    print(
        f"{r.platform}: {len(meshes)} parts, {faces} faces, start {start:.2f} s, first {first:.2f} s, "
        f"warm median {statistics.median(warm):.3f} s (load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs)"
    )


if __name__ == "__main__":
    main()
