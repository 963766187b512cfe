"""The benchmark package and its evaluation.json files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aw.official.errors import EvaluationCacheError, PackageError
from aw.official.evaluation_cache import read_evaluation, write_evaluation
from aw.official.package import OfficialPackage
from tests.aw.official.builders import DIVISOR, FINAL, PART_IDS, evaluation_points, write_active, write_package


@pytest.fixture(scope="module")
def package_root(tmp_path_factory):
    return write_package(tmp_path_factory.mktemp("pkg") / "benchmark")


def copy_package(src, dst):
    import shutil

    shutil.copytree(src, dst)
    return dst


def test_blocks_samples_and_inputs(package_root):
    pkg = OfficialPackage(package_root, strict=False)
    assert list(pkg.blocks) == ["partnet-none", "partnet-final-image", "ikea-manualbook"]
    assert pkg.samples() == [
        ("partnet-none", "21905"),
        ("partnet-none", "743"),
        ("partnet-final-image", "21905"),
        ("partnet-final-image", "743"),
        ("ikea-manualbook", "Chair/reidar"),
    ]
    s = pkg.sample("ikea-manualbook", "Chair/reidar")
    assert s.slug == "Chair--reidar" and s.evaluation_path.parent.name == "Chair--reidar"
    assert [p.name for p in s.pages] == ["1.png", "2.png"] and pkg.sample("partnet-none", "743").reference is None
    inputs = pkg.evaluation_inputs("partnet-final-image", "743")
    assert inputs.part_ids == PART_IDS and inputs.points.shape == (3, 1000, 3) and inputs.divisor == DIVISOR
    assert np.array_equal(inputs.points, evaluation_points()) and np.array_equal(inputs.target_poses, FINAL)
    assert inputs.groups == [["0"], ["1"], ["2"]] and inputs.key["similarity"]["threshold"] == 0.0001
    assert pkg.task_text("partnet-none") == "Assemble the parts (partnet-none)."
    with pytest.raises(PackageError, match="expected exactly"):
        OfficialPackage(package_root)  # the official loader wants the five frozen blocks


def test_final_state_of_a_run(package_root, tmp_path):
    pkg = OfficialPackage(package_root, strict=False)
    final = write_active(pkg.initial_archive("partnet-none", "21905"), tmp_path / "final.episode.zip")
    poses, index = pkg.final_state("partnet-none", "21905", final.path)
    assert index == 3 and np.array_equal(poses, FINAL)
    with pytest.raises(Exception, match="id differs"):  # another sample's initial archive
        pkg.final_state("partnet-none", "743", final.path)


def test_evaluation_round_trip(package_root, tmp_path):
    pkg = OfficialPackage(package_root, strict=False)
    inputs = pkg.evaluation_inputs("partnet-none", "743")
    write_evaluation(tmp_path / "evaluation.json", inputs)
    again = read_evaluation(tmp_path / "evaluation.json", sample_id="743", parts=3)
    assert (
        np.array_equal(again.points, inputs.points)
        and again.key == inputs.key
        and again.provenance == inputs.provenance
    )
    assert (tmp_path / "evaluation.json").read_text().endswith("}\n")


def _edit(path, change):
    value = json.loads(path.read_text())
    change(value)
    path.write_text(json.dumps(value))


@pytest.mark.parametrize(
    "change,message",
    [
        (lambda v: v["points"]["1"][0].__setitem__(0, float("inf")), "Infinity|non-finite"),
        (lambda v: v["key"].update(sample_id="other"), "key.sample_id"),
        (lambda v: v["key"].update(evaluation_protocol="assembly-evaluation-v2"), "evaluation_protocol"),
        (lambda v: v["key"]["similarity"].update(threshold=0.001), "threshold"),
        (lambda v: v["equivalence"].update(groups=[["0", "1"]]), "partition"),
        (lambda v: v.update(scale_divisor=0), "scale_divisor"),
        (lambda v: v.update(part_ids=["1", "0", "2"]), "part_ids"),
        (lambda v: v["points"].update({"2": [[0, 0, 0]] * 999}), "1000"),
        (lambda v: v["gt_poses"].update({"2": [0, 0, 0, 0, 0, 0, 0]}), "zero"),
    ],
)
def test_bad_evaluation_inputs(package_root, tmp_path, change, message):
    root = copy_package(package_root, tmp_path / "pkg")
    pkg = OfficialPackage(root, strict=False)
    path = pkg.sample("partnet-none", "743").evaluation_path
    _edit(path, change)
    with pytest.raises(EvaluationCacheError, match=message) as info:
        pkg.evaluation_inputs("partnet-none", "743")
    assert "evaluation.json" in str(info.value)


def test_bad_packages(package_root, tmp_path):
    root = copy_package(package_root, tmp_path / "pkg")
    with pytest.raises(PackageError, match="benchmark.json not found"):
        OfficialPackage(tmp_path)
    _edit(root / "benchmark.json", lambda v: v["evaluation"].update(protocol="assembly-evaluation-v2"))
    with pytest.raises(PackageError, match="evaluation"):
        OfficialPackage(root, strict=False)
    root = copy_package(package_root, tmp_path / "pkg2")
    pkg = OfficialPackage(root, strict=False)
    pkg.sample("partnet-none", "743").initial_path.write_bytes(b"changed")
    with pytest.raises(PackageError, match="SHA-256"):
        OfficialPackage(root, strict=False).sample("partnet-none", "743")
    (root / "partnet-none" / "task.txt").write_text("Another task.")
    with pytest.raises(PackageError, match="task text"):
        OfficialPackage(root, strict=False).configuration("partnet-none")
    pages = (
        root / "partnet-final-image/partnet-manualpa/prep-v1-s0-i0-fixture/cache/21905/reference/final-image/pages.json"
    )
    _edit(pages, lambda v: v["pages"].reverse())
    with pytest.raises(PackageError, match="out of order"):
        OfficialPackage(root, strict=False).sample("partnet-final-image", "21905")
    _edit(root / "benchmark.json", lambda v: v["blocks"].reverse())
    with pytest.raises(PackageError, match="in that order"):
        OfficialPackage(root, strict=False)
