"""AssemblyBench loader: local part meshes, per-view per-step poses, one diagram per step."""

from __future__ import annotations

import json

import numpy as np
import pytest
from dataset_fixtures import assemblybench_object
from roundtrip import oracle_roundtrip

from aw.formats import FormatError
from aw.sources import assemblybench


@pytest.mark.parametrize("layout", ["folders", "json"])
def test_final_step_first_view_is_the_assembly(tmp_path, layout):
    assembled = assemblybench_object(tmp_path, "pumps", "pump_7", 4, views=3, layout=layout)
    obj = assemblybench.load_object(tmp_path, "pumps/pump_7")
    assert (obj.source, obj.category, obj.object_id) == ("assemblybench", "pumps", "pump_7")
    assert [p.name for p in obj.parts] == ["part0", "part1", "part2", "part3"]
    for part, want in zip(obj.parts, assembled, strict=True):  # view 0 is the assembled frame, not views 1-2
        assert np.abs(part.mesh.vertices - want.vertices).max() < 1e-6
    assert obj.meta["steps"] == [["part0", "part1"], ["part2"], ["part3"]]
    assert obj.meta["n_views"] == 3 and obj.meta["n_steps"] == 3
    assert [p.name for p in obj.references["manual"]] == ["step_0.png", "step_1.png", "step_2.png"]


def test_catalog_and_meta(tmp_path):
    assemblybench_object(tmp_path, "gears", "g1", 3)
    assemblybench_object(tmp_path, "valves", "g1", 5)
    cat = assemblybench.catalog(tmp_path)
    # the same object name in two categories is qualified
    assert [(e.object_id, e.category, e.n_parts) for e in cat] == [("gears_g1", "gears", 3), ("valves_g1", "valves", 5)]
    assert assemblybench.load_object(*cat[1].args).object_id == "valves_g1"
    (tmp_path / "gears" / "g1" / "meta.json").write_text(
        json.dumps({"category": "Gearbox", "equivalence": [["part0", "part2"]]})
    )
    obj = assemblybench.load_object(tmp_path, "gears/g1")
    assert obj.category == "gearbox" and obj.equivalence == [["part0", "part2"]]


def _pose_file(root, view=0, step=-1):
    files = sorted((root / "pumps" / "p" / "poses" / f"view_{view}").glob("step_*.json"))
    return files[step]


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d.pop("part1"), r"final step of view 0: poses missing for parts \['part1'\]"),
        (
            lambda d: d.update(part1=[0, 0, 0, 1, 0, 0]),
            r"poses.part1: expected \[tx, ty, tz, qw, qx, qy, qz\], got shape \(6,\)",
        ),
        (
            lambda d: d.update(part1=[0, 0, float("nan"), 1, 0, 0, 0]),
            r"step_1.json: not valid JSON: NaN at char \d+ \(NaN and Infinity are not JSON numbers\)",
        ),
        (lambda d: d.update(part1=[0, 0, 0, 0, 0, 0, 0]), r"poses.part1: zero quaternion"),
        (lambda d: d.update(ghost=[0, 0, 0, 1, 0, 0, 0]), r"poses for unknown parts \['ghost'\]"),
    ],
)
def test_malformed_poses(tmp_path, edit, message):
    assemblybench_object(tmp_path, "pumps", "p", 3)
    f = _pose_file(tmp_path)
    data = json.loads(f.read_text())
    edit(data)
    f.write_text(json.dumps(data).replace("NaN", "NaN"))
    with pytest.raises(FormatError, match=message):
        assemblybench.load_object(tmp_path, "pumps/p")


def test_missing_files(tmp_path):
    assemblybench_object(tmp_path, "pumps", "p", 3)
    part = tmp_path / "pumps" / "p" / "parts" / "part2.obj"
    part.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 inf\nf 1 2 3\nf 1 2 4\n")
    with pytest.raises(FormatError, match="non-finite") as exc:
        assemblybench.load_object(tmp_path, "pumps/p")
    assert str(part) in str(exc.value)
    import shutil

    shutil.rmtree(tmp_path / "pumps" / "p" / "poses")
    with pytest.raises(FormatError, match="poses: neither poses/ nor poses.json found"):
        assemblybench.load_object(tmp_path, "pumps/p")


def test_roundtrip_oracle(tmp_path):
    assemblybench_object(tmp_path / "ab", "pumps", "p", 4)
    obj = assemblybench.load_object(tmp_path / "ab", "pumps/p")
    (entry,) = oracle_roundtrip(obj, tmp_path / "suite", ("manual",))
    refs = sorted((tmp_path / "suite" / "tasks" / entry.task_id / "references").iterdir())
    assert len(refs) == 3  # one diagram per step
