"""PartNet (DGL / Manual-PA) loader: shape_data dicts, split lists, part meshes, pages."""

from __future__ import annotations

import os

import numpy as np
import pytest
from dataset_fixtures import partnet_dataset, partnet_shape
from roundtrip import oracle_roundtrip

from aw.formats import FormatError
from aw.sources import partnet


def _close(a, b, tol=1e-6):
    return np.abs(np.asarray(a) - np.asarray(b)).max() < tol


def test_points_only_shape_is_hulled_z_up(tmp_path):
    made = partnet_shape(tmp_path, "1001", 6, pages=3)
    obj = partnet.load_object(tmp_path, "1001", category="chair")
    assert obj.source == "partnet" and obj.object_id == "1001" and obj.category == "chair"
    assert [p.name for p in obj.parts] == [f"part_0{i}" for i in range(6)]
    assert obj.meta["geometry"] == "convex_hull"
    # the hull of points that include the box corners is the box, in the Z-up assembled frame
    for part, box in zip(obj.parts, made["assembled"], strict=True):
        assert _close(part.mesh.bounds, box.bounds)
        assert part.mesh.is_watertight
    # the seat is the flat part at z = 0.45: Y-up data came out Z-up
    assert _close(obj.parts[0].mesh.bounds[:, 2], [0.43, 0.47])
    assert obj.equivalence == [["part_02", "part_03", "part_04", "part_05"]]
    assert obj.meta["geo_part_ids"] == [0, 1, 2, 2, 2, 2] and len(obj.meta["sym"]) == 6
    assert [p.name for p in obj.references["image"]] == ["step_3.png"]  # the final page only


@pytest.mark.parametrize("frame", ["canonical", "assembled"])
def test_part_meshes_in_either_frame(tmp_path, frame):
    made = partnet_shape(tmp_path, "7", 4, meshes=frame)
    obj = partnet.load_object(tmp_path, "7")
    assert obj.meta["geometry"] == "meshes" and obj.meta["mesh_frames"] == [frame] * 4
    for part, box in zip(obj.parts, made["assembled"], strict=True):
        assert _close(part.mesh.vertices, box.vertices)


def test_catalog_reads_split_lists(tmp_path):
    root = partnet_dataset(tmp_path / "pn", {"Chair": [("11", 3), ("12", 7)], "StorageFurniture": [("31", 12)]})
    (root / "Chair.train.npy").write_bytes((root / "Chair.test.npy").read_bytes())
    cat = partnet.catalog(root)
    assert [(e.object_id, e.category, e.n_parts) for e in cat] == [
        ("11", "chair", 3),
        ("12", "chair", 7),
        ("31", "storage", 12),
    ]
    obj = partnet.load_object(*cat[2].args)
    assert obj.category == "storage" and obj.n_parts == 12
    assert [e.object_id for e in partnet.catalog(root, categories=["storage"])] == ["31"]
    # without split lists every shape file is a candidate
    for p in root.glob("*.test.npy"):
        p.unlink()
    for p in root.glob("*.train.npy"):
        p.unlink()
    assert sorted(e.object_id for e in partnet.catalog(root)) == ["11", "12", "31"]


def test_txt_split_list(tmp_path):
    partnet_shape(tmp_path, "5", 3)
    (tmp_path / "Table.test.txt").write_text("5\n")
    assert [(e.object_id, e.category) for e in partnet.catalog(tmp_path)] == [("5", "table")]


def _write(tmp_path, **changes):
    made = partnet_shape(tmp_path, "9", 3)
    data = dict(made["data"], **changes)
    data = {k: v for k, v in data.items() if v is not None}
    np.save(tmp_path / "shape_data" / "9_level3.npy", data)
    return tmp_path / "shape_data" / "9_level3.npy"


@pytest.mark.parametrize(
    "changes, field",
    [
        ({"part_pcs": np.zeros((3, 10, 2))}, "part_pcs: expected shape"),
        ({"part_poses": np.zeros((3, 6))}, "part_poses: expected shape (3, 7)"),
        ({"part_poses": np.tile([0, 0, 0, 0, 0, 0, 0.0], (3, 1))}, "part_poses: zero quaternion"),
        ({"geo_part_ids": np.array([1, 2])}, "geo_part_ids: expected 3 entries"),
        ({"part_pcs": None}, "part_pcs: missing"),
    ],
)
def test_malformed_shape_files(tmp_path, changes, field):
    path = _write(tmp_path, **changes)
    with pytest.raises(FormatError) as exc:
        partnet.load_object(tmp_path, "9")
    assert str(path) in str(exc.value) and field in str(exc.value)


def test_non_finite_points_and_missing_file(tmp_path):
    made = partnet_shape(tmp_path, "9", 3)
    pcs = made["data"]["part_pcs"].copy()
    pcs[1, 4, 2] = np.nan
    path = _write(tmp_path, part_pcs=pcs)
    with pytest.raises(FormatError, match=r"part_pcs: non-finite points \(part 1, point 4\)") as exc:
        partnet.load_object(tmp_path, "9")
    assert str(path) in str(exc.value)
    with pytest.raises(FormatError, match=r"4_level3\.npy: file not found"):
        partnet.load_object(tmp_path, "4")


def test_missing_part_mesh_names_the_part(tmp_path):
    partnet_shape(tmp_path, "7", 4, meshes="assembled")
    (tmp_path / "part_meshes" / "7_level3" / "2.obj").unlink()
    with pytest.raises(FormatError, match=r"part mesh 2: missing .*part_pcs\[2\]"):
        partnet.load_object(tmp_path, "7")


class _Evil:
    def __reduce__(self):
        return (os.system, ("echo pwned > /dev/null",))


def test_pickled_code_is_refused(tmp_path):
    (tmp_path / "shape_data").mkdir()
    arr = np.empty((), dtype=object)
    arr[()] = {"part_pcs": _Evil()}
    path = tmp_path / "shape_data" / "3_level3.npy"
    with open(path, "wb") as fh:
        np.lib.format.write_array(fh, arr, allow_pickle=True)
    with pytest.raises(FormatError, match="refusing to load posix.system|refusing to load os.system"):
        partnet.load_object(tmp_path, "3")


def test_roundtrip_oracle(tmp_path):
    partnet_shape(tmp_path / "pn", "42", 5, pages=2)
    obj = partnet.load_object(tmp_path / "pn", "42", category="chair")
    entries = oracle_roundtrip(obj, tmp_path / "suite", ("none", "image"))
    assert [e.condition for e in entries] == ["none", "image"]
    # paired conditions: identical baked geometry and targets
    none_dir, image_dir = (tmp_path / "suite" / "tasks" / e.task_id for e in entries)
    for f in sorted((none_dir / "parts").iterdir()):
        assert f.read_bytes() == (image_dir / "parts" / f.name).read_bytes()
    assert (image_dir / "references" / "01.png").is_file() and not (none_dir / "references").exists()
