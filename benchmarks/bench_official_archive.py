"""Time reading an official episode archive and restoring every state's part poses.

An archive of ``--parts`` boxes with ``--moves`` recorded moves (one state and two trace frames
each, as the official runtime records an edit), written by this project's writers::

    .venv/bin/python benchmarks/bench_official_archive.py --parts 20 --moves 300
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aw.official.archive import read_archive, write_archive  # noqa: E402
from aw.official.episode import read_part_episode  # noqa: E402
from aw.official.world import setup_archive  # noqa: E402
from tests.aw.official.builders import Recorder, box  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", type=int, default=20)
    ap.add_argument("--moves", type=int, default=300)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    ids = [f"{k:03d}" for k in range(args.parts)]
    meshes = [box(tuple(rng.uniform(0.05, 0.3, 3))) for _ in ids]
    poses = np.hstack([rng.normal(size=(args.parts, 3)), np.tile([1.0, 0, 0, 0], (args.parts, 1))])
    folder = Path(tempfile.mkdtemp(prefix="aw-bench-archive-"))
    setup = write_archive(setup_archive(ids, meshes, poses, name="bench"), folder / "setup.episode.zip")
    rec = Recorder(setup)
    rec.query("start_episode")
    for i in range(args.moves):
        q = rng.normal(size=4)
        rec.move(i % args.parts, np.concatenate([rng.normal(size=3), q / np.linalg.norm(q)]))
    path = folder / "final.episode.zip"
    rec.save(path)
    reads, restores = [], []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        arc = read_archive(path)
        t1 = time.perf_counter()
        read_part_episode(arc, setup, ids)
        reads.append(t1 - t0)
        restores.append(time.perf_counter() - t1)
    print(
        f"{path.stat().st_size / 1e6:.2f} MB, {len(arc.states)} states, {len(arc.traces)} traces: "
        f"read_archive {np.median(reads):.3f} s, restore every state {np.median(restores):.3f} s (median of {args.repeat})"
    )


if __name__ == "__main__":
    main()
