"""IKEA-Manual loader: main_data.json records, per-part OBJ files (Y up), manual pages."""

from __future__ import annotations

import json

import numpy as np
import pytest
from dataset_fixtures import box, chair_boxes, ikea_dataset
from roundtrip import oracle_roundtrip

from aw.formats import FormatError
from aw.sources import ikea_manual


@pytest.fixture
def root(tmp_path):
    return ikea_dataset(tmp_path / "ikea", [("Chair", "applaro", 5), ("Table", "lack", 3)], pages=3)


def test_load_object(root):
    obj = ikea_manual.load_object(root, "Chair/applaro")
    assert (obj.source, obj.dataset, obj.category, obj.object_id) == (
        "ikea_manual",
        "ikea_manual",
        "chair",
        "chair_applaro",
    )
    assert [p.name for p in obj.parts] == ["0", "1", "2", "3", "4"]
    # Y-up files came out Z-up: each part sits where the Z-up chair has it
    for part, (size, centre) in zip(obj.parts, chair_boxes(3), strict=True):
        assert np.abs(part.mesh.bounds - box(size, centre).bounds).max() < 1e-7  # OBJ keeps 8 decimals
    assert obj.equivalence == [["2", "3", "4"]]
    # steps name parts as ints, strings and comma-joined sub-assemblies; each step keeps what it adds
    assert obj.meta["steps"] == [["2", "3", "0"], ["4", "1"]]
    assert obj.meta["connection_relation"][0] == [0, 2] and "assembly_tree" in obj.meta
    assert [p.name for p in obj.references["manual"]] == ["page_1.png", "page_2.png", "page_3.png"]
    # a bare name works when it is unique
    assert ikea_manual.load_object(root, "lack").object_id == "table_lack"


def test_pages_in_natural_order_and_missing_pages(root):
    d = root / "manual_img" / "Chair" / "applaro"
    (d / "page_10.png").write_bytes((d / "page_1.png").read_bytes())
    names = [p.name for p in ikea_manual.load_object(root, "Chair/applaro").references["manual"]]
    assert names == ["page_1.png", "page_2.png", "page_3.png", "page_10.png"]
    for p in d.iterdir():
        p.unlink()
    obj = ikea_manual.load_object(root, "Chair/applaro")
    assert "manual" not in obj.references and obj.meta["references"].startswith("missing")


def test_catalog(root):
    cat = ikea_manual.catalog(root)
    assert [(e.object_id, e.category, e.n_parts) for e in cat] == [
        ("chair_applaro", "chair", 5),
        ("table_lack", "table", 3),
    ]
    assert ikea_manual.load_object(*cat[1].args).n_parts == 3


def _edit(root, fn):
    path = root / "main_data.json"
    data = json.loads(path.read_text())
    fn(data)
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d[0].update(parts_ct=7), r"part meshes \['5', '6'\] missing"),
        (lambda d: d[0].update(parts_ct=4), r"mesh files \['4'\] are not parts 0..3"),
        (lambda d: d[0].update(parts_ct="5"), r"main_data.json: \[0\].parts_ct: expected a positive integer"),
        (
            lambda d: d[0].update(geometric_equivalence_relation=[["2", "9"]]),
            r"\[0\].geometric_equivalence_relation\[0\]: unknown part ids \['9'\]",
        ),
        (lambda d: d[0]["steps"].append({"parts": ["12"]}), r"\[0\].steps\[2\].parts: unknown part ids \['12'\]"),
        (lambda d: d[0].pop("name"), r"\[0\].name: missing"),
        (lambda d: d[0].update(name=float("nan")), r"main_data.json: not valid JSON: NaN at char \d+"),
        (lambda d: d[0].update(notes=json.loads("[" * 70 + "]" * 70)), r"main_data.json: JSON nested deeper than 64"),
    ],
)
def test_malformed_main_data(root, edit, message):
    _edit(root, edit)
    with pytest.raises(FormatError, match=message):
        ikea_manual.load_object(root, "Chair/applaro" if "name: missing" not in message else "lack")


def test_broken_part_file(root):
    part = root / "parts" / "Chair" / "applaro" / "3.obj"
    part.write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(FormatError) as exc:
        ikea_manual.load_object(root, "Chair/applaro")
    assert str(part) in str(exc.value) and "non-finite" in str(exc.value)
    part.unlink()
    with pytest.raises(FormatError, match=r"part meshes \['3'\] missing"):
        ikea_manual.load_object(root, "Chair/applaro")
    (root / "main_data.json").unlink()
    with pytest.raises(FormatError, match="main_data.json: main_data.json not found"):
        ikea_manual.load_object(root, "Chair/applaro")


def test_roundtrip_oracle(root, tmp_path):
    obj = ikea_manual.load_object(root, "Chair/applaro")
    (entry,) = oracle_roundtrip(obj, tmp_path / "suite", ("manual",))
    refs = sorted((tmp_path / "suite" / "tasks" / entry.task_id / "references").iterdir())
    assert [p.name for p in refs] == ["01.png", "02.png", "03.png"]  # every page, in order
