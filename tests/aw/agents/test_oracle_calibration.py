"""The oracle through the real server on the synthetic suite, scored by the evaluator: zero noise
gives PA = SR = 100 % on every task; noise gives a spread.

Scored with the evaluator's ``fast`` mode (the one ``aw-score`` uses for checkpoints) to keep the
test short; the geometry of these deterministic tasks is cached across runs by ``aw_eval``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import aw_eval
from aw.formats import read_final, read_manifest, read_run_info
from aw.formats.suite import suite_paths
from aw.runner.batch import BatchConfig, run_batch


@pytest.fixture(scope="module")
def synthetic_suite(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("synthetic") / "suite"
    prepare = Path(sys.executable).with_name("aw-prepare")
    subprocess.run(
        [str(prepare), "synthetic", "--out", str(out), "--per-source", "1", "--jobs", "2", "--no-progress"],
        check=True,
        capture_output=True,
    )
    return out


def _scores(suite: Path, runs: Path, system: str, tasks: list[str] | None = None) -> dict[str, tuple[float, float]]:
    out = {}
    for entry in read_manifest(suite).tasks:
        if tasks is not None and entry.task_id not in tasks:
            continue
        task_dir, targets = suite_paths(suite, entry.task_id)
        geom = aw_eval.load_task_geometry(task_dir, targets)
        poses = read_final(runs / system / entry.task_id / "final.json").poses
        res = aw_eval.score(geom, np.array([poses[p] for p in geom.part_ids]), mode="fast")
        out[entry.task_id] = (float(res.pa), float(res.sr))
    return out


def test_oracle_without_noise_scores_100_percent_and_with_noise_does_not(synthetic_suite, tmp_path):
    runs = tmp_path / "runs"
    task_ids = [t.task_id for t in read_manifest(synthetic_suite).tasks]
    noisy_tasks = [t for t in task_ids if t.startswith(("ikea_manual", "partnet"))][:2]
    for system, noise, tasks in (("oracle", 0.0, None), ("oracle-noisy", 3.0, noisy_tasks)):
        res = run_batch(
            BatchConfig(
                suite_dir=synthetic_suite,
                system=system,
                out_dir=runs,
                agent="oracle",
                noise=noise,
                tasks=tasks,
                jobs=2,
                progress=False,
            )
        )
        assert res.endings() == {"finished": len(tasks or task_ids)}
    exact = _scores(synthetic_suite, runs, "oracle")
    assert len(exact) == 5 and all(v == (1.0, 1.0) for v in exact.values()), exact
    noisy = _scores(synthetic_suite, runs, "oracle-noisy", noisy_tasks)
    assert min(pa for pa, _ in noisy.values()) < 1.0, noisy
    stats = [read_run_info(runs / "oracle-noisy" / t / "run.json").extra["agent_stats"] for t in noisy]
    assert all(s["noise"] == 3.0 for s in stats)
