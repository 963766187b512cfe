"""``aw-score`` on a suite prepared by the official protocol: it scores from the task's
``eval_points/<task>.npz`` (the official points, divisor and groups), not from the meshes."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from aw.formats import FinalState, read_targets, write_final
from aw.official import suite_eval_inputs
from aw.prepare import ObjectSpec, build_suite
from aw_eval.cli import main

FAST = ["--bootstrap", "200", "--permutations", "500", "--no-progress", "--jobs", "1", "--mode", "fast"]


@pytest.fixture(scope="module")
def scored(tmp_path_factory):
    root = tmp_path_factory.mktemp("official-points")
    obj = root / "objects" / "bench"
    obj.mkdir(parents=True)
    for name, size, centre in (("top", (0.6, 0.25, 0.04), (0, 0, 0.4)), ("post", (0.05, 0.2, 0.38), (0, 0, 0.19))):
        mesh = trimesh.creation.box(extents=size)
        mesh.apply_translation(centre)
        mesh.export(obj / f"{name}.obj")
    spec = ObjectSpec("aw.sources.folder:load_object", (str(obj),), ("none",))
    suite = root / "suite"
    manifest, _ = build_suite([spec], suite, name="t", jobs=1, progress=False, protocol="official")
    tid = manifest.tasks[0].task_id
    runs = root / "runs"
    targets = {p: list(t.pose) for p, t in read_targets(suite / "targets" / f"{tid}.json").parts.items()}
    far = {**targets, "post": [targets["post"][0] + 2.0, *targets["post"][1:]]}  # no rigid motion can mend this
    for system, poses in (("right", targets), ("wrong", far)):
        (runs / system / tid).mkdir(parents=True)
        write_final(runs / system / tid / "final.json", FinalState(task_id=tid, reason="finished", poses=poses))
    out = root / "report"
    assert main([str(suite), str(runs), "--out", str(out), *FAST]) == 0
    return suite, tid, json.loads((out / "scores.json").read_text())


def _run(doc, system):
    return next(r for r in doc["runs"] if r["system"] == system)


def test_runs_are_scored_from_the_official_points(scored):
    suite, tid, doc = scored
    inputs = suite_eval_inputs(suite, tid)
    assert inputs.part_ids == ["post", "top"]
    right, wrong = _run(doc, "right"), _run(doc, "wrong")
    assert right["final_from"] == wrong["final_from"] == "final.json"
    assert right["sr"] == 1 and right["pa"] == 100 and right["scd"] < 1e-20  # the official points, exactly
    assert wrong["sr"] == 0 and wrong["pa"] < 100
    assert np.isfinite(wrong["scd"]) and wrong["scd"] > 0.1
