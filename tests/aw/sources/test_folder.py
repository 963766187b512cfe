"""Folder import: one subfolder per object, one mesh per part, optional meta.json."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from PIL import Image

from aw.formats import FormatError
from aw.sources.folder import SkippedPath, load_object, scan_folder, skipped_paths


def _box(path, size, centre):
    m = trimesh.creation.box(extents=size)
    m.apply_translation(centre)
    m.export(path)


def make_chair(root, name="chair", meta=None, suffix=".obj"):
    d = root / name
    d.mkdir(parents=True)
    _box(d / f"seat{suffix}", (0.5, 0.4, 0.04), (0, 0, 0.45))
    _box(d / f"back{suffix}", (0.5, 0.03, 0.4), (0, -0.2, 0.7))
    for k, (x, y) in enumerate([(-0.2, -0.15), (0.2, -0.15), (-0.2, 0.15), (0.2, 0.15)]):
        _box(d / f"leg{k + 1}{suffix}", (0.04, 0.04, 0.43), (x, y, 0.215))
    if meta is not None:
        (d / "meta.json").write_text(json.dumps(meta))
    return d


@pytest.fixture
def src(tmp_path):
    root = tmp_path / "objects"
    make_chair(
        root,
        "a_chair",
        meta={
            "category": "chair",
            "source": "partnet",
            "conditions": ["none", "image"],
            "equivalence": [["leg1", "leg2", "leg3", "leg4"]],
            "steps": [["leg1", "leg2", "leg3", "leg4"], ["seat", "back"]],
        },
    )
    make_chair(root, "c_chair", meta={"condition": "manual"})
    d = make_chair(root, "b_chair", suffix=".ply")
    Image.new("RGB", (20, 10), (9, 9, 9)).save(d / "photo.png")
    (d / "meta.json").write_text(
        json.dumps({"object_id": "chair-b", "references": {"image": ["photo.png"]}, "up_axis": "y"})
    )
    return root


def test_scan_and_load(src):
    found = scan_folder(src)
    assert [(f.object_id, f.conditions) for f in found] == [
        ("a_chair", ["none", "image"]),
        ("chair-b", ["image"]),
        ("c_chair", ["manual"]),
    ]
    a = load_object(found[0].path)
    assert a.source == "partnet" and a.category == "chair" and a.dataset == "folder"
    assert sorted(p.name for p in a.parts) == ["back", "leg1", "leg2", "leg3", "leg4", "seat"]
    assert a.equivalence == [["leg1", "leg2", "leg3", "leg4"]]
    assert a.meta["steps"][1] == ["seat", "back"]
    b = load_object(found[1].path, default_source="mine")
    assert b.object_id == "chair-b" and b.source == "mine"
    assert [p.name for p in b.references["image"]] == ["photo.png"]
    # up_axis y: (x, y, z) -> (x, -z, y): the seat centred at (0, 0, 0.45), 0.4 deep along Y,
    # is centred at (0, -0.45, 0) and 0.4 tall along Z
    seat = {p.name: p.mesh for p in b.parts}["seat"]
    np.testing.assert_allclose(seat.vertices.mean(axis=0), [0.0, -0.45, 0.0], atol=1e-9)
    np.testing.assert_allclose(seat.bounds[:, 2], [-0.2, 0.2], atol=1e-9)


def test_parts_subfolder(tmp_path):
    d = tmp_path / "src" / "thing" / "parts"
    d.mkdir(parents=True)
    _box(d / "x.obj", (1, 2, 3), (0, 0, 0))
    _box(d / "y.stl", (1, 1, 1), (2, 0, 0))
    _box(d.parent / "ignored.obj", (5, 5, 5), (0, 0, 0))
    obj = load_object(d.parent)
    assert sorted(p.name for p in obj.parts) == ["x", "y"]
    # the mesh beside parts/ is not read, and scanning says so by name
    with pytest.warns(SkippedPath, match="thing/ignored.obj: skipped: the object's parts are read from its parts/"):
        scan_folder(tmp_path / "src")
    assert skipped_paths(d.parent) == [(d.parent / "ignored.obj", "the object's parts are read from its parts/ folder")]


def _expect(path_fragment, match, fn, *args):
    with pytest.raises(FormatError, match=match) as info:
        fn(*args)
    assert path_fragment in str(info.value)
    return info.value


def test_malformed_sources(tmp_path):
    _expect("nowhere", "source folder not found", scan_folder, tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    _expect("empty", "no object folders", scan_folder, tmp_path / "empty")
    (tmp_path / "s" / "noparts").mkdir(parents=True)
    (tmp_path / "s" / "noparts" / "readme.txt").write_text("hi")
    _expect("noparts", "no part meshes", load_object, tmp_path / "s" / "noparts")
    _expect("missing_obj", "object folder not found", load_object, tmp_path / "missing_obj")


def test_malformed_meshes(tmp_path):
    d = make_chair(tmp_path, "broken")
    (d / "leg1.obj").write_text("this is not a mesh\n")
    _expect("leg1.obj", "no triangles", load_object, d)

    d = make_chair(tmp_path, "nan")
    (d / "seat.obj").write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")
    _expect("seat.obj", "non-finite", load_object, d)

    d = make_chair(tmp_path, "dup")
    _box(d / "seat.stl", (1, 1, 1), (0, 0, 0))
    _expect("dup", "share the part name", load_object, d)

    d = make_chair(tmp_path, "point")
    (d / "seat.obj").write_text("v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\n")
    _expect("seat.obj", "coincide", load_object, d)


def test_malformed_meta(tmp_path):
    d = make_chair(tmp_path, "badjson")
    (d / "meta.json").write_text("{not json")
    _expect("meta.json", "not valid JSON", load_object, d)

    d = make_chair(tmp_path, "wrongtype", meta={"category": ["chair"]})
    _expect("meta.json", "category", load_object, d)

    make_chair(tmp_path / "c", "badcond", meta={"conditions": ["video"]})
    _expect("meta.json", "conditions", scan_folder, tmp_path / "c")

    d = make_chair(tmp_path / "e", "eq", meta={"equivalence": [["leg1", "leg9"]]})
    _expect("meta.json", "unknown parts", load_object, d)

    d = make_chair(tmp_path / "r", "ref", meta={"references": {"image": ["missing.png"]}})
    _expect("missing.png", "not found", load_object, d)

    d = make_chair(tmp_path / "o", "out", meta={"references": {"image": ["../secret.png"]}})
    _expect("meta.json", "inside the object folder", load_object, d)

    make_chair(tmp_path / "b", "both", meta={"condition": "image", "conditions": ["none"]})
    _expect("meta.json", "either condition or conditions", scan_folder, tmp_path / "b")

    root = tmp_path / "twins"
    make_chair(root, "one", meta={"object_id": "same"})
    make_chair(root, "two", meta={"object_id": "same"})
    _expect("twins", "same", scan_folder, root)


def test_unknown_meta_keys_warn_by_name_and_are_ignored(tmp_path):
    root = tmp_path / "extra"
    make_chair(root, "x", meta={"category": "chair", "categroy": "typo", "license": "CC-BY", "source": "partnet"})
    with pytest.warns(UserWarning, match=r"x/meta.json: unknown keys \['categroy', 'license'\] are ignored"):
        found = scan_folder(root)
    assert [f.object_id for f in found] == ["x"]
    obj = load_object(found[0].path)
    assert (obj.category, obj.source, obj.n_parts) == ("chair", "partnet", 6)
