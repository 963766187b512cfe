"""A suite prepared by the official protocol from a re-hosted row: the task and its
``eval_points/<task_id>.npz`` carry exactly the official preparation of the row as published."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from aw.cli.prepare import main as prepare_main
from aw.formats import read_targets, read_task
from aw.official import suite_eval_inputs
from aw.prepare import ObjectSpec, build_suite
from aw.prepare.official_protocol import OfficialPart, OfficialSample, prepare_official

sys.path.insert(0, str(Path(__file__).parent / "sources"))
from dataset_fixtures import rehosted_row, write_rehosted  # noqa: E402

Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@pytest.fixture
def row_file(tmp_path):
    row = rehosted_row("chair_9", "PartNet", "Chair", 2, pages=0, up_axis="y")
    return write_rehosted(tmp_path / "partnet.parquet", [row]), row


def test_official_suite_holds_the_official_numbers_of_the_published_row(row_file, tmp_path):
    path, row = row_file
    spec = ObjectSpec("aw.sources.rehosted:load_row", (str(path), 0), ("none",))
    manifest, _ = build_suite([spec], tmp_path / "suite", name="t", seed=0, jobs=1, progress=False, protocol="official")
    tid = manifest.tasks[0].task_id
    # the official adapter's reading of the same row: source-frame vertices, quads, Y up
    parts = tuple(
        OfficialPart(p["part_id"], np.asarray(p["vertices"], dtype=np.float64), tuple(tuple(f) for f in p["faces"]))
        for p in row["parts"]
    )
    expected = prepare_official(OfficialSample("AssemblyWorld/partnet-manualpa", "chair_9", parts, Y_UP), 0)

    got = suite_eval_inputs(tmp_path / "suite", tid)
    assert got.part_ids == expected.part_ids == ["0", "1"]
    assert np.array_equal(got.points, expected.points)
    assert np.array_equal(got.target_poses, expected.targets)
    assert got.divisor == expected.divisor
    assert sorted(got.groups) == sorted(expected.groups)
    with np.load(tmp_path / "suite" / "eval_points" / f"{tid}.npz") as raw:  # the fracture protocol's inputs
        assert (str(raw["dataset"]), str(raw["sample_id"])) == ("AssemblyWorld/partnet-manualpa", "chair_9")
        assert float(raw["fracture_divisor"]) == expected.fracture_divisor > 0
    task = read_task(tmp_path / "suite" / "tasks" / tid)
    assert [p.id for p in task.parts] == ["0", "1"]
    targets = read_targets(tmp_path / "suite" / "targets" / f"{tid}.json")
    assert targets.eval_divisor == expected.divisor
    for pid, pose in zip(expected.part_ids, expected.targets, strict=True):
        assert targets.parts[pid].pose == [float(x) for x in pose]


def test_cli_defaults_and_refusals(row_file, tmp_path, capsys):
    path, _ = row_file
    out = tmp_path / "s"
    assert (
        prepare_main(
            [
                "compose",
                "--rehosted",
                str(path),
                "--per-source",
                "1",
                "--out",
                str(out),
                "--variants",
                "1",
                "--no-progress",
            ]
        )
        == 2
    )  # a usage error
    assert "--variants needs --protocol native" in capsys.readouterr().err
    assert (
        prepare_main(["compose", "--rehosted", str(path), "--per-source", "1", "--out", str(out), "--no-progress"]) == 0
    )
    assert len(list((out / "eval_points").glob("*.npz"))) == 2  # official by default: one per condition
    assert (
        prepare_main(
            [
                "compose",
                "--rehosted",
                str(path),
                "--per-source",
                "1",
                "--out",
                str(out),
                "--no-progress",
                "--protocol",
                "native",
                "--overwrite",
            ]
        )
        == 0
    )
    assert not (out / "eval_points").exists()  # a replaced suite keeps no stale evaluation points


def test_a_source_part_id_that_cannot_name_a_task_part_is_refused_by_name():
    import trimesh

    from aw.assembly import AssembledObject, SourcePart
    from aw.prepare.official_task import official_sample

    box = trimesh.creation.box(extents=(0.2, 0.1, 0.05))
    obj = AssembledObject("o", "partnet", "d", "", [SourcePart("leg.1", box), SourcePart("seat", box.copy())])
    with pytest.raises(ValueError, match=r"part id 'leg.1'"):
        official_sample(obj)
