"""Breaking Bad loader: fracture folders of piece meshes and the HDF5 variant."""

from __future__ import annotations

import numpy as np
import pytest
from dataset_fixtures import breaking_bad_dataset, breaking_bad_h5, fractured_box
from roundtrip import oracle_roundtrip

from aw.formats import FormatError
from aw.sources import breaking_bad


@pytest.fixture
def root(tmp_path):
    return breaking_bad_dataset(
        tmp_path / "bb",
        [
            ("everyday", "BeerBottle", "3f91158", "fractured_0", 3),
            ("everyday", "BeerBottle", "3f91158", "fractured_12", 2),
            ("artifact", "Vase", "a77", "mode_1", 4),
        ],
    )


def test_folder_object_and_catalog(root):
    cat = breaking_bad.catalog(root)
    assert [(e.object_id, e.category, e.n_parts) for e in cat] == [
        ("Vase_a77_mode_1", "vase", 4),
        ("BeerBottle_3f91158_fractured_0", "beerbottle", 3),
        ("BeerBottle_3f91158_fractured_12", "beerbottle", 2),
    ]
    assert [e.object_id for e in breaking_bad.catalog(root, subsets=["artifact"])] == ["Vase_a77_mode_1"]
    obj = breaking_bad.load_object(*cat[1].args)
    assert obj.source == "breaking_bad" and obj.meta["subset"] == "everyday"
    assert [p.name for p in obj.parts] == ["piece_0", "piece_1", "piece_2"]
    for part, piece in zip(obj.parts, fractured_box(3), strict=True):
        assert np.abs(part.mesh.bounds - piece.bounds).max() < 1e-7


def test_hdf5_variant(tmp_path):
    path = breaking_bad_h5(
        tmp_path / "bb.hdf5", [("everyday/Cup/c1/fractured_0", 3), ("artifact/Bowl/b2/fractured_4", 2)]
    )
    cat = breaking_bad.hdf5_catalog(path)
    assert [(e.object_id, e.category, e.n_parts) for e in cat] == [
        ("Bowl_b2_fractured_4", "bowl", 2),
        ("Cup_c1_fractured_0", "cup", 3),
    ]
    obj = breaking_bad.load_hdf5_object(*cat[1].args)
    assert [p.name for p in obj.parts] == ["piece_0", "piece_1", "piece_2"]
    for part, piece in zip(obj.parts, fractured_box(3), strict=True):
        assert np.array_equal(part.mesh.vertices, piece.vertices) and np.array_equal(part.mesh.faces, piece.faces)


@pytest.mark.parametrize(
    "field, data, message",
    [
        ("vertices", np.zeros((8, 2)), r"pieces/1.vertices: expected shape \(n, 3\), got \(8, 2\)"),
        ("vertices", np.full((8, 3), np.inf), r"pieces/1.vertices: 8 non-finite vertices"),
        (
            "faces",
            np.array([[0, 1, 2, 3]]),
            r"pieces/1.faces: expected triangles of shape \(m, 3\), got \(1, 4\) \(polygon faces\)",
        ),
        ("faces", np.array([[0, 1, 99]]), r"pieces/1.faces: vertex index out of range"),
    ],
)
def test_malformed_hdf5(tmp_path, field, data, message):
    import h5py

    path = breaking_bad_h5(tmp_path / "bb.h5", [("everyday/Cup/c1/fractured_0", 2)])
    with h5py.File(path, "a") as h5:
        del h5[f"everyday/Cup/c1/fractured_0/pieces/1/{field}"]
        h5[f"everyday/Cup/c1/fractured_0/pieces/1/{field}"] = data
    with pytest.raises(FormatError, match=message) as exc:
        breaking_bad.load_hdf5_object(path, "everyday/Cup/c1/fractured_0")
    assert str(path) in str(exc.value)


def test_missing_things(tmp_path, root):
    import h5py

    path = breaking_bad_h5(tmp_path / "bb.h5", [("everyday/Cup/c1/fractured_0", 2)])
    with h5py.File(path, "a") as h5:
        del h5["everyday/Cup/c1/fractured_0/pieces/0/faces"]
    with pytest.raises(FormatError, match=r"pieces/0/faces: dataset missing"):
        breaking_bad.load_hdf5_object(path, "everyday/Cup/c1/fractured_0")
    with pytest.raises(FormatError, match=r"nope: group not found"):
        breaking_bad.load_hdf5_object(path, "nope")
    with pytest.raises(FormatError, match="HDF5 file not found"):
        breaking_bad.load_hdf5_object(tmp_path / "none.h5", "x")
    folder = root / "everyday" / "BeerBottle" / "3f91158" / "fractured_12"
    (folder / "piece_1.obj").unlink()
    with pytest.raises(FormatError, match="1 piece mesh"):
        breaking_bad.load_object(root, "everyday/BeerBottle/3f91158/fractured_12")
    (folder / "piece_0.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nv 1 1 1\nf 1 2 3\nf 1 3 4\n")
    (folder / "piece_1.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(FormatError, match="non-finite") as exc:
        breaking_bad.load_object(root, "everyday/BeerBottle/3f91158/fractured_12")
    assert "piece_0.obj" in str(exc.value)


def test_roundtrip_oracle(root, tmp_path):
    obj = breaking_bad.load_object(root, "artifact/Vase/a77/mode_1")
    oracle_roundtrip(obj, tmp_path / "suite")
