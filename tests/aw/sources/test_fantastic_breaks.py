"""Fantastic Breaks loader: model_b_0 / model_r_0 / model_c / meta_0.npz per object."""

from __future__ import annotations

import numpy as np
import pytest
from dataset_fixtures import fantastic_breaks_dataset, fractured_box
from roundtrip import oracle_roundtrip

from aw.formats import FormatError
from aw.sources import fantastic_breaks


@pytest.fixture
def root(tmp_path):
    return fantastic_breaks_dataset(tmp_path / "fb", [("Mug", "mug_03"), ("Plate", "p1"), ("Mug", "mug_01")])


def test_load_and_catalog(root):
    cat = fantastic_breaks.catalog(root)
    assert [(e.object_id, e.category, e.n_parts) for e in cat] == [
        ("mug_mug_01", "mug", 2),
        ("mug_mug_03", "mug", 2),
        ("plate_p1", "plate", 2),
    ]
    obj = fantastic_breaks.load_object(*cat[0].args)
    assert (obj.source, obj.category) == ("fantastic_breaks", "mug") and not obj.references
    assert [p.name for p in obj.parts] == ["broken", "restoration"]
    for part, piece in zip(obj.parts, fractured_box(2), strict=True):
        assert np.abs(part.mesh.bounds - piece.bounds).max() < 1e-6
    assert obj.meta["npz"]["break_axis"] == [1.0, 0.0, 0.0]
    assert obj.meta["npz"]["points"] == {"shape": [500, 3], "dtype": "float64"}
    assert obj.meta["complete_model"].endswith("model_c.ply")


def test_malformed(root):
    d = root / "Plate" / "p1"
    (d / "meta_0.npz").write_bytes(b"not a zip")
    with pytest.raises(FormatError, match=r"meta_0.npz: cannot be read as .npz"):
        fantastic_breaks.load_object(root, "Plate/p1")
    (d / "meta_0.npz").unlink()
    (d / "model_r_0.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 nan\n0 1 0\n3 0 1 2\n"
    )
    with pytest.raises(FormatError, match="non-finite") as exc:
        fantastic_breaks.load_object(root, "Plate/p1")
    assert "model_r_0.ply" in str(exc.value)
    (d / "model_r_0.ply").unlink()
    with pytest.raises(FormatError, match=r"model_r_0.ply: restoration fragment \(model_r\): file not found"):
        fantastic_breaks.load_object(root, "Plate/p1")
    assert [e.object_id for e in fantastic_breaks.catalog(root)] == ["mug_mug_01", "mug_mug_03"]


def test_roundtrip_oracle(root, tmp_path):
    oracle_roundtrip(fantastic_breaks.load_object(root, "Mug/mug_03"), tmp_path / "suite")
