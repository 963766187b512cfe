"""Where an interrupt can come back as another exception: SIGINT at seeded moments of each compiled
or native call that aw-score makes (numba's ICP and coarse starts, the task geometry, XLA, Qhull,
SciPy's k-d tree and assignment, trimesh's oriented box), with aw.interrupts' handler installed::

    .venv/bin/python benchmarks/interrupt_kernels.py --out OUT [--trials 6] [--jax]

For each call: how long one call takes, and what came out of the signal in each trial (the
exception type; for a type other than KeyboardInterrupt, whether aw.interrupts.is_interrupt
recognises it, and its message). A Python signal handler runs between bytecodes, so inside a
native call it waits for the call to return: the call's duration bounds how late Ctrl-C acts.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from aw import interrupts  # noqa: E402


def _fire(delay: float) -> None:
    time.sleep(delay)
    os.kill(os.getpid(), signal.SIGINT)


def probe(name: str, call: Callable[[], object], trials: int, seed: int) -> dict:
    """Signal this process ``trials`` times at a random moment of repeated ``call()``s."""
    rng = random.Random(seed)
    call()  # compiled, warmed
    t0 = time.perf_counter()
    call()
    seconds = time.perf_counter() - t0
    seen: dict[str, int] = {}
    for _ in range(trials):
        with interrupts.handled():
            threading.Thread(target=_fire, args=(rng.uniform(0.0, seconds),), daemon=True).start()
            try:
                end = time.perf_counter() + 3 * seconds + 1.0
                while time.perf_counter() < end:
                    call()
                kind = "no exception"
            except BaseException as exc:  # noqa: BLE001 - what came out is the measurement
                kind = type(exc).__name__
                if not isinstance(exc, KeyboardInterrupt):
                    kind += f" (recognised: {interrupts.is_interrupt(exc)}; {str(exc)[:90]})"
        seen[kind] = seen.get(kind, 0) + 1
    row = {"call": name, "seconds_per_call": round(seconds, 3), "outcomes": seen}
    print(json.dumps(row), flush=True)
    return row


def main() -> None:
    from benchmarks._output import output_file

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="folder for interrupt_kernels.json")
    ap.add_argument("--trials", type=int, default=6, help="signals per call (default 6)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jax", action="store_true", help="also the jax backend (compiles for minutes on a CPU)")
    args = ap.parse_args()
    target = output_file(args.out, "interrupt_kernels.json")

    import trimesh
    from scipy.optimize import linear_sum_assignment
    from scipy.spatial import ConvexHull, Delaunay, cKDTree

    import aw_eval
    from aw.formats import read_manifest
    from aw.formats.suite import suite_paths
    from aw_eval.settings import ProtocolSettings
    from aw_eval.study.fixtures import box_suite

    work = Path(tempfile.mkdtemp(prefix="aw-kernels-"))
    suite = box_suite(work / "suite", objects_per_source=1, n_parts=[6])
    task_dir, targets = suite_paths(suite, read_manifest(suite).tasks[0].task_id)
    small = ProtocolSettings(n_surface=256, n_fps=64)
    geom = aw_eval.load_task_geometry(task_dir, targets, cache_dir=None, settings=small)
    poses = np.repeat(geom.target_poses[None], 3, axis=0).copy()
    poses[:, :, :3] += np.random.default_rng(0).normal(0.0, 0.05, poses[:, :, :3].shape)
    pts = np.random.default_rng(1).normal(size=(100_000, 3))
    tree = cKDTree(pts)
    cost = np.random.default_rng(2).random((800, 800))
    calls: list[tuple[str, Callable[[], object]]] = [
        ("numba: exact scoring (ICP from every start)", lambda: aw_eval.score_batch(geom, poses, mode="exact")),
        ("numba: fast scoring (coarse starts, ICP)", lambda: aw_eval.score_batch(geom, poses, mode="fast")),
        (
            "task geometry (trimesh load, FPS, box frames)",
            lambda: aw_eval.load_task_geometry(task_dir, targets, settings=small, use_cache=False),
        ),
        ("Qhull: scipy.spatial.ConvexHull", lambda: ConvexHull(pts)),
        ("Qhull: scipy.spatial.Delaunay", lambda: Delaunay(pts[:5000])),
        ("SciPy: cKDTree.query", lambda: tree.query(pts[:50_000], k=4)),
        ("SciPy: linear_sum_assignment", lambda: linear_sum_assignment(cost)),
        ("trimesh: bounds.oriented_bounds (Qhull)", lambda: trimesh.bounds.oriented_bounds(pts[:20_000])),
    ]
    if args.jax:
        calls.append(
            ("XLA: exact scoring, jax backend", lambda: aw_eval.score_batch(geom, poses, mode="exact", backend="jax"))
        )
    rows = [probe(name, call, args.trials, args.seed) for name, call in calls]
    doc = {
        "command": " ".join(["benchmarks/interrupt_kernels.py", *sys.argv[1:]]),
        "load": os.getloadavg(),
        "task": "a 6-part box task, protocol overrides n_surface=256 n_fps=64, 3 states per call",
        "rows": rows,
    }
    target.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {target}")


if __name__ == "__main__":
    main()
