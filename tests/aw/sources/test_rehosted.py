"""Re-hosted common row schema: Parquet and Arrow files, polygon faces, pages, equivalence."""

from __future__ import annotations

import numpy as np
import pytest
from dataset_fixtures import box, chair_boxes, png_bytes, quad_box, rehosted_row, write_rehosted
from roundtrip import oracle_roundtrip

from aw.formats import FormatError
from aw.sources import rehosted
from aw.sources.meshdata import triangulate_polygons


@pytest.fixture
def download(tmp_path):
    root = tmp_path / "dl"
    write_rehosted(
        root / "data" / "partnet-00000-of-00002.parquet",
        [
            rehosted_row("chair_1", "PartNet", "Chair", 6, pages=3),
            rehosted_row("t2", "IKEA-Manual", "Table", 3, up_axis="y"),
        ],
        row_group_size=1,
    )
    write_rehosted(
        root / "data" / "partnet-00001-of-00002.arrow",
        [rehosted_row("g3", "assemblybench", "Gear", 4)],
        fmt="arrow-file",
    )
    write_rehosted(
        root / "data" / "z.arrow", [rehosted_row("f4", "fantastic_breaks", "Mug", 2, pages=0)], fmt="arrow-stream"
    )
    return root


def test_catalog_and_rows(download):
    cat = rehosted.catalog(download)
    assert [(e.source, e.object_id, e.category, e.n_parts) for e in cat] == [
        ("partnet", "chair_1", "chair", 6),
        ("ikea_manual", "t2", "table", 3),
        ("assemblybench", "g3", "gear", 4),
        ("fantastic_breaks", "f4", "mug", 2),
    ]
    objs = [rehosted.load_row(*e.args) for e in cat]
    chair = objs[0]
    assert chair.source == "partnet" and chair.dataset == "rehosted:partnet"
    assert chair.equivalence == [["2", "3", "4", "5"]]
    # quads were triangulated: 6 quads -> 12 triangles, a closed box
    for part, (size, centre) in zip(chair.parts, chair_boxes(4), strict=True):
        assert part.mesh.faces.shape == (12, 3) and part.mesh.is_watertight and part.mesh.volume > 0
        assert np.abs(part.mesh.bounds - box(size, centre).bounds).max() < 1e-12
    assert len(chair.references["manual"]) == 3 and chair.references["image"][0] is chair.references["manual"][-1]
    assert chair.references["manual"][2].getpixel((0, 0)) == (0, 0, 80)  # ordered by page
    # the Y-up row came out Z-up
    table = objs[1]
    assert np.abs(table.parts[0].mesh.bounds - box(*chair_boxes(1)[0]).bounds).max() < 1e-12
    assert not objs[3].references
    # an override of the source
    assert rehosted.load_row(cat[2].args[0], 0, "custom").source == "custom"


def test_non_convex_polygon_is_ear_clipped():
    # an L-shaped face: fanning from vertex 0 would cover the notch
    v = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float)
    tris = triangulate_polygons(v, [[0, 1, 2, 3, 4, 5]])
    assert tris.shape == (4, 3)
    area = 0.0
    for a, b, c in tris:
        n = np.cross(v[b] - v[a], v[c] - v[a])
        assert n[2] > 0  # orientation kept
        area += 0.5 * n[2]
    assert area == pytest.approx(3.0)


def _bad_row(**changes):
    row = rehosted_row("x", "partnet", "chair", 3, pages=1)
    for key, value in changes.items():
        if key.startswith("part1_"):
            row["parts"][1][key[6:]] = value
        else:
            row[key] = value
    return row


@pytest.mark.parametrize(
    "changes, message",
    [
        (
            {"part1_faces": [[0, 1, 3, 2], [4, 6]]},
            r"row 0.parts\[1\].faces\[1\]: a face needs at least 3 vertices, got 2",
        ),
        (
            {"part1_faces": [[0, 1]] * 6},
            r"row 0.parts\[1\].faces: expected faces of at least 3 vertices, got shape \(6, 2\)",
        ),
        ({"part1_faces": [[0, 1, 2, 42]]}, r"row 0.parts\[1\].faces: vertex index out of range"),
        ({"part1_vertices": [[0.0, 1.0]] * 8}, r"row 0.parts\[1\].vertices: expected shape \(n, 3\), got \(8, 2\)"),
        ({"part1_vertices": [[0.0, float("nan"), 1.0]] * 8}, r"row 0.parts\[1\].vertices: 8 non-finite vertices"),
        ({"parts_ct": 4}, r"row 0.parts_ct: says 4 but the row has 3 parts"),
        (
            {"geometric_equivalence_relation": [["2", "7"]]},
            r"row 0.geometric_equivalence_relation\[0\]: unknown part ids \['7'\]",
        ),
    ],
)
def test_malformed_rows(tmp_path, changes, message):
    path = write_rehosted(tmp_path / "bad.parquet", [_bad_row(**changes)])
    with pytest.raises(FormatError, match=message) as exc:
        rehosted.load_row(path, 0)
    assert str(path) in str(exc.value)


def test_bad_files(tmp_path):
    path = write_rehosted(tmp_path / "ok.parquet", [_bad_row()])
    with pytest.raises(FormatError, match=r"row 5: out of range \(the file has 1 rows\)"):
        rehosted.load_row(path, 5)
    junk = tmp_path / "junk.parquet"
    junk.write_bytes(b"PAR1 nonsense")
    with pytest.raises(FormatError, match="cannot be read as Parquet/Arrow"):
        rehosted.load_row(junk, 0)
    row = _bad_row()
    row["manual_pages"][0]["image"] = {"bytes": b"not an image", "path": "p.png"}
    bad_img = write_rehosted(tmp_path / "img.parquet", [row])
    with pytest.raises(FormatError, match=r"row 0.manual_pages\[0\].image: cannot be decoded as an image"):
        rehosted.load_row(bad_img, 0)
    (tmp_path / "empty").mkdir()
    with pytest.raises(FormatError, match="no .parquet or .arrow files"):
        rehosted.catalog(tmp_path / "empty")


def test_roundtrip_oracle(download, tmp_path):
    obj = rehosted.load_row(download / "data" / "partnet-00000-of-00002.parquet", 0)
    oracle_roundtrip(obj, tmp_path / "suite", ("none", "image"))


def _official_assemblybench_row():
    """A row in the official AssemblyBench schema: local part meshes, view/step poses, diagrams."""
    v, f = quad_box((0.2, 0.1, 0.05), (0, 0, 0))
    turn = [0.9238795325112867, 0.0, 0.0, 0.3826834323650898]  # 45 degrees about Z
    pages = [
        {
            "kind": "diagram",
            "view_id": v_id,
            "step_id": step,
            "image": {"bytes": png_bytes((step, int(v_id), 9)), "path": None},
        }
        for step in (1, 2)
        for v_id in ("0", "1")
    ] + [{"kind": "photo", "view_id": "0", "step_id": 2, "image": {"bytes": png_bytes((1, 1, 1)), "path": None}}]
    return {
        "object_id": "gearbox_7",
        "parts_ct": 2,
        "steps": [{"step_id": 1}, {"step_id": 2}],
        "parts": [{"part_id": "a", "vertices": v, "faces": f}, {"part_id": "b", "vertices": v, "faces": f}],
        "poses": {
            "0": {
                "1": {"a": [0, 0, 0, 1, 0, 0, 0], "b": None},
                "2": {"a": [0, 0, 0, 1, 0, 0, 0], "b": [0.3, 0.0, 0.0, *turn]},
            },
            "1": {"2": {"a": [9, 9, 9, 1, 0, 0, 0], "b": [9, 9, 9, 1, 0, 0, 0]}},
        },
        "manual_pages": pages,
    }


def test_official_rows_source_from_path_poses_and_diagrams(tmp_path):
    from aw.prepare.official_task import official_sample

    write_rehosted(
        tmp_path / "datasets--AssemblyWorld--assemblybench" / "data" / "test.parquet", [_official_assemblybench_row()]
    )
    (entry,) = rehosted.catalog(tmp_path / "datasets--AssemblyWorld--assemblybench")
    assert (entry.source, entry.object_id) == ("assemblybench", "gearbox_7")
    obj = rehosted.load_row(*entry.args)
    a, b = (np.asarray(p.mesh.vertices) for p in obj.parts)
    assert np.allclose(b.mean(0), a.mean(0) + [0.3, 0, 0])  # the final step of view 0 assembles the parts
    assert np.allclose(np.ptp(b, axis=0)[:2], [0.15 * np.sqrt(2)] * 2)  # turned 45 degrees
    # the view-0 diagrams, one per step, in step order
    assert [im.getpixel((0, 0))[:2] for im in obj.references["manual"]] == [(1, 0), (2, 0)]
    official = official_sample(obj)
    assert official.dataset == "AssemblyWorld/assemblybench" and official.sample_id == "gearbox_7"
    part_b = official.parts[1]
    assert np.array_equal(
        part_b.vertices, np.asarray(_official_assemblybench_row()["parts"][1]["vertices"], dtype=float)
    )
    assert np.allclose(part_b.pose, [0.3, 0, 0, 0.9238795325112867, 0, 0, 0.3826834323650898])
    assert rehosted.source_of_download(tmp_path / "ikea-manual" / "x.parquet") == "ikea_manual"
    assert rehosted.category_of(None, "Bench/applaro") == "bench" and rehosted.category_of("Chair", "x/y") == "chair"
    assert rehosted.category_of(None, "688") == ""
    assert rehosted.source_of_download(tmp_path / "elsewhere" / "x.parquet") is None
