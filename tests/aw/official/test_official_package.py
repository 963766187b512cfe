"""Official package: per-sample evaluation inputs, checked."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aw.formats import FormatError
from aw.official import OfficialPackage, read_eval_inputs

from official_fixtures import write_package


def _inputs(n=3, seed=0, **changes):
    rng = np.random.default_rng(seed)
    t = np.concatenate([rng.normal(size=(n, 3)), rng.normal(size=(n, 4))], axis=1)
    d = dict(part_ids=np.array([f"p{i + 1:02d}" for i in range(n)]), points=rng.normal(size=(n, 1000, 3)),
             target_poses=t, scale_divisor=np.float64(1.7), equivalence_groups=np.array([0, 1, 1][:n]))
    d.update(changes)
    return {k: v for k, v in d.items() if v is not None}


def test_read_package(tmp_path):
    pkg_dir = write_package(tmp_path / "pkg", [
        {"sample_id": "partnet/chair-1/image", "source": "partnet", "condition": "image", "object_id": "chair-1", "n_parts": 3,
         "eval": "eval/a.npz"},
        {"sample_id": "fb-2", "source": "fantastic_breaks", "n_parts": 2, "weight": 0.5},
    ], {"a": _inputs(), "fb-2": _inputs(2)})
    pkg = OfficialPackage(pkg_dir)
    assert list(pkg.samples) == ["partnet/chair-1/image", "fb-2"]
    a = pkg.eval_inputs("partnet/chair-1/image")
    assert a.part_ids == ["p01", "p02", "p03"] and a.points.shape == (3, 1000, 3) and a.divisor == 1.7
    assert a.groups == [["p01"], ["p02", "p03"]] and a.group_labels().tolist() == [0, 1, 1]
    # kept bit for bit (normalizing here would change scores in the last bits)
    np.testing.assert_array_equal(a.target_poses, _inputs()["target_poses"])
    b = pkg.eval_inputs("fb-2")
    assert b.n_parts == 2 and pkg.samples["fb-2"].condition == "none" and pkg.samples["fb-2"].weight == 0.5


def test_group_forms_and_json_inputs(tmp_path):
    p = tmp_path / "a.npz"
    np.savez(p, **_inputs(equivalence_groups=np.array(json.dumps([["p01", "p03"]]))))
    assert read_eval_inputs(p).groups == [["p01", "p03"], ["p02"]]
    np.savez(p, **_inputs(equivalence_groups=None))
    assert read_eval_inputs(p).groups == [["p01"], ["p02"], ["p03"]]
    d = _inputs()
    j = tmp_path / "b.json"
    j.write_text(json.dumps({"part_ids": d["part_ids"].tolist(), "clouds": d["points"].tolist(), "targets": d["target_poses"].tolist(),
                             "divisor": 2.0, "groups": [["p02", "p03"]]}))
    got = read_eval_inputs(j)
    assert got.divisor == 2.0 and got.groups == [["p01"], ["p02", "p03"]]
    np.testing.assert_array_equal(got.points, d["points"])


@pytest.mark.parametrize("changes, message", [
    ({"points": np.zeros((3, 999, 3))}, r"points: expected shape \(3, 1000, 3\), got \(3, 999, 3\)"),
    ({"points": np.full((3, 1000, 3), np.nan)}, "points: non-finite values"),
    ({"target_poses": np.zeros((3, 6))}, r"target_poses: expected shape \(3, 7\)"),
    ({"target_poses": np.zeros((3, 7))}, "target_poses: zero quaternion for part p01"),
    ({"part_ids": np.array(["p02", "p01", "p03"])}, "part_ids: must be unique and sorted"),
    ({"scale_divisor": np.float64(0.0)}, "scale_divisor: expected one positive number"),
    ({"equivalence_groups": np.array([0, 1])}, r"equivalence_groups: expected one label per part \(3\)"),
    ({"equivalence_groups": np.array(json.dumps([["p01", "p09"]]))}, r"equivalence_groups: unknown part ids \['p09'\]"),
    ({"equivalence_groups": np.array(json.dumps([["p01", "p02"], ["p02", "p03"]]))}, r"parts in several groups \['p02'\]"),
    ({"points": None}, "points: missing"),
])
def test_malformed_inputs(tmp_path, changes, message):
    p = tmp_path / "x.npz"
    np.savez(p, **_inputs(**changes))
    with pytest.raises(FormatError, match=message) as exc:
        read_eval_inputs(p)
    assert str(p) in str(exc.value)


def test_malformed_manifest(tmp_path):
    with pytest.raises(FormatError, match="package manifest not found"):
        OfficialPackage(tmp_path)
    write_package(tmp_path, [{"sample_id": "a", "eval": "../../etc/x.npz"}], {})
    with pytest.raises(FormatError, match=r"samples\[0\].eval: must be a path inside the package"):
        OfficialPackage(tmp_path)
    write_package(tmp_path, [{"sample_id": "a"}, {"sample_id": "a"}], {})
    with pytest.raises(FormatError, match="appears twice"):
        OfficialPackage(tmp_path)
    write_package(tmp_path, [{"sample_id": "a", "n_parts": 4}], {"a": _inputs()})
    with pytest.raises(FormatError, match="part_ids: 3 parts, the package manifest says 4"):
        OfficialPackage(tmp_path).eval_inputs("a")
    write_package(tmp_path, [{"sample_id": "b"}], {})
    with pytest.raises(FormatError, match="b.npz: evaluation inputs not found"):
        OfficialPackage(tmp_path).eval_inputs("b")


def test_facts_from_points(tmp_path):
    pts = np.zeros((2, 1000, 3))
    rng = np.random.default_rng(1)
    pts[0] = rng.uniform(-1, 1, size=(1000, 3)) * [1.0, 0.5, 0.1] + [3, 0, 0]
    pts[1] = rng.uniform(-1, 1, size=(1000, 3)) * [0.25, 0.125, 0.025]
    p = tmp_path / "f.npz"
    np.savez(p, **_inputs(2, points=pts, equivalence_groups=np.array([0, 1])))
    inputs = read_eval_inputs(p)
    np.testing.assert_allclose(inputs.centroids(), pts.mean(axis=1))
    assert inputs.size_ratio() == pytest.approx(4.0, rel=0.02)
