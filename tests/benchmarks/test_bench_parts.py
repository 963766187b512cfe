"""The part-count sweep's objects and its table (the sweep itself is a benchmark, not a test)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import trimesh

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import bench_parts  # noqa: E402


def test_objects_have_the_promised_parts(tmp_path):
    distinct = bench_parts.part_extents(200, "distinct")
    assert len(set(distinct)) == 200 and all(a >= b >= c > 0.04 for a, b, c in distinct)
    assert bench_parts.part_extents(6, "identical") == [(1.0, 1.0, 0.05)] + [(0.1, 0.1, 0.3)] * 5
    assert len(set(bench_parts.part_extents(4, "replicas"))) == 1
    folder = bench_parts.make_object(tmp_path, 5, "distinct")
    meshes = [trimesh.load(p, force="mesh") for p in sorted(folder.glob("*.obj"))]
    assert len(meshes) == 5 and all(m.is_watertight for m in meshes)
    boxes = np.array([m.bounds for m in meshes])  # no two parts touch
    for i in range(5):
        for j in range(i):
            assert np.any(boxes[i, 0] > boxes[j, 1]) or np.any(boxes[j, 0] > boxes[i, 1])


def test_table_names_stopped_and_skipped_steps(tmp_path):
    geometry = {
        "sampling_s": 0.2,
        "fps_s": 4.6,
        "groups_s": 53.1,
        "index_s": 24.2,
        "peak_rss_mb": 563.0,
        "n_groups": 50,
        "group_sizes": [1],
    }
    rows = [
        {
            "kind": "distinct",
            "parts": 50,
            "prepare": {"prepare_s": 0.5},
            "geometry": geometry,
            "render": {"start_s": 6.7, "picture_s": 1.2},
            "score": {"error": "stopped after 300 s"},
            "official": {"error": "not run (stopped at fewer parts)"},
        }
    ]
    path = tmp_path / "sweep.json"
    path.write_text(json.dumps({"rows": rows}))
    last = bench_parts.table(path).splitlines()[-1]
    assert last == "| distinct | 50 | 0.5 | 0.2 | 4.6 | 53.1 | 24.2 | 563 | 6.7 + 1.2 | stopped | not run | 50 (1) |"


def test_candidate_counts_narrow_from_all_pairs_to_the_rotation_bound():
    found = bench_parts.candidates("distinct", 30)
    assert found["pairs"] == 435
    assert 0 <= found["rotation_candidates"] < found["rigid_candidates"] < found["pairs"]
