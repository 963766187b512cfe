"""Benchmark composition: stratified, category-covering, seeded sampling and `aw-prepare compose`."""

from __future__ import annotations

import json
import random
from collections import Counter

import pytest
from dataset_fixtures import assemblybench_object, fantastic_breaks_dataset, ikea_dataset, partnet_dataset
from PIL import Image

from aw.cli.prepare import main
from aw.formats import read_manifest, read_targets, read_task
from aw.formats.suite import suite_paths
from aw.sources.compose import BANDS, CatalogEntry, allocate, band_of, compose, sample_source, specs_for


def _catalog(source, spec):
    """spec: {(category, n_parts): count}"""
    out = []
    for (cat, n), k in spec.items():
        for i in range(k):
            out.append(CatalogEntry(source, f"{cat}_{n}_{i}", cat, n, "x:y"))
    return out


def test_bands():
    assert [band_of(n) for n in (1, 2, 5, 6, 10, 11, 20, 21)] == [
        None,
        "2-5",
        "2-5",
        "6-10",
        "6-10",
        "11-20",
        "11-20",
        None,
    ]
    assert [b[0] for b in BANDS] == ["2-5", "6-10", "11-20"]


@pytest.mark.parametrize(
    "n, available, want",
    [
        (20, {"a": 50, "b": 50, "c": 50}, {"a": 7, "b": 7, "c": 6}),
        (20, {"a": 50, "b": 3, "c": 50}, {"a": 9, "b": 3, "c": 8}),
        (20, {"a": 2, "b": 0, "c": 4}, {"a": 2, "b": 0, "c": 4}),
        (3, {"a": 1, "b": 5, "c": 5}, {"a": 1, "b": 1, "c": 1}),
        (2, {"a": 1, "b": 5, "c": 4}, {"a": 0, "b": 1, "c": 1}),
    ],
)
def test_allocate(n, available, want):
    assert allocate(n, available) == want


def test_stratified_counts_and_category_coverage():
    cat = _catalog(
        "partnet",
        {
            ("chair", 3): 30,
            ("chair", 8): 30,
            ("chair", 15): 30,
            ("table", 4): 30,
            ("table", 9): 10,
            ("table", 14): 2,
            ("storage", 12): 5,
            ("chair", 25): 9,
            ("table", 1): 4,
        },
    )
    chosen = sample_source(cat, 20, seed=0)
    assert len(chosen) == 20 and len({e.object_id for e in chosen}) == 20
    bands = Counter(band_of(e.n_parts) for e in chosen)
    assert bands == {"2-5": 7, "6-10": 7, "11-20": 6}
    assert all(2 <= e.n_parts <= 20 for e in chosen)  # 25-part and 1-part objects are not eligible
    per_band_cat = Counter((band_of(e.n_parts), e.category) for e in chosen)
    # inside each band the categories present take turns: counts differ by at most one
    assert per_band_cat[("2-5", "chair")] + per_band_cat[("2-5", "table")] == 7
    assert abs(per_band_cat[("2-5", "chair")] - per_band_cat[("2-5", "table")]) == 1
    assert per_band_cat[("6-10", "chair")] + per_band_cat[("6-10", "table")] == 7
    assert abs(per_band_cat[("6-10", "chair")] - per_band_cat[("6-10", "table")]) == 1
    assert (
        per_band_cat[("11-20", "chair")] == 2
        and per_band_cat[("11-20", "table")] == 2
        and per_band_cat[("11-20", "storage")] == 2
    )
    # deterministic, independent of catalog order; another seed draws other objects
    shuffled = list(cat)
    random.Random(5).shuffle(shuffled)
    assert sample_source(shuffled, 20, seed=0) == chosen
    assert sample_source(cat, 20, seed=1) != chosen


def test_category_coverage_across_bands():
    # one object per band; categories a, b, c: each band's single draw goes to a category not yet taken
    cat = _catalog(
        "ikea_manual",
        {
            ("a", 3): 5,
            ("b", 3): 5,
            ("c", 3): 5,
            ("a", 7): 5,
            ("b", 7): 5,
            ("c", 7): 5,
            ("a", 13): 5,
            ("b", 13): 5,
            ("c", 13): 5,
        },
    )
    for seed in range(6):
        chosen = sample_source(cat, 3, seed=seed)
        assert sorted(e.category for e in chosen) == ["a", "b", "c"]
        assert Counter(band_of(e.n_parts) for e in chosen) == {"2-5": 1, "6-10": 1, "11-20": 1}


def test_fantastic_breaks_by_category_only():
    cat = _catalog("fantastic_breaks", {("mug", 2): 10, ("plate", 2): 10, ("vase", 2): 1, ("bowl", 2): 10})
    chosen = sample_source(cat, 20, seed=3)
    assert sorted(Counter(e.category for e in chosen).values()) == [1, 6, 6, 7]
    assert Counter(e.category for e in chosen)["vase"] == 1
    assert sample_source(cat, 50, seed=3) == sample_source(list(reversed(cat)), 50, seed=3)
    assert len(sample_source(cat, 50, seed=3)) == 31


def test_composition_specs():
    comp = compose(
        {
            "partnet": _catalog("partnet", {("chair", 4): 3}),
            "assemblybench": _catalog("assemblybench", {("gear", 5): 2}),
        },
        2,
        seed=0,
    )
    specs, sources = specs_for(comp)
    assert sources == ["partnet", "partnet", "assemblybench", "assemblybench"]
    assert [s.conditions for s in specs] == [("none", "image")] * 2 + [("manual",)] * 2
    assert specs[0].donor.args == specs[1].args and specs[1].donor.args == specs[0].args  # donor: the next object
    s = comp.summary()
    assert s["sources"]["partnet"]["candidates"] == 3 and s["sources"]["partnet"]["bands"]["2-5"] == 2


@pytest.fixture
def datasets(tmp_path):
    root = tmp_path / "data"
    partnet_dataset(
        root / "pn", {"Chair": [("11", 3), ("12", 7), ("13", 12)], "Table": [("21", 4), ("22", 8)]}, pages=2
    )
    ikea_dataset(root / "ik", [("Chair", "a", 3), ("Table", "b", 6), ("Bench", "c", 4)], pages=3)
    assemblybench_object(root / "ab", "gear", "g1", 3)
    assemblybench_object(root / "ab", "valve", "v1", 4)
    fantastic_breaks_dataset(root / "fb", [("Mug", "m1"), ("Plate", "p1"), ("Mug", "m2")])
    return root


def _args(root, out, *extra):
    return [
        "compose",
        "--out",
        str(out),
        "--partnet",
        str(root / "pn"),
        "--ikea-manual",
        str(root / "ik"),
        "--assemblybench",
        str(root / "ab"),
        "--fantastic-breaks",
        str(root / "fb"),
        "--per-source",
        "2",
        "--jobs",
        "1",
        "--no-progress",
        "--protocol",
        "native",
        *extra,
    ]


def test_compose_cli_builds_the_benchmark(datasets, tmp_path, capsys):
    out = tmp_path / "suite"
    assert main(_args(datasets, out)) == 0
    manifest = read_manifest(out)
    by_source = Counter(t.source for t in manifest.tasks)
    assert by_source == {"partnet": 4, "ikea_manual": 2, "assemblybench": 2, "fantastic_breaks": 2}
    comp = json.loads((out / "composition.json").read_text())
    pn = comp["sources"]["partnet"]
    assert pn["bands"] == {"2-5": 1, "6-10": 1, "11-20": 0} and pn["categories"] == {"chair": 1, "table": 1}
    assert comp["sources"]["fantastic_breaks"]["categories"] == {"mug": 1, "plate": 1}

    # PartNet objects twice, identical geometry, layout and targets; image = the final page
    pn_tasks = [t for t in manifest.tasks if t.source == "partnet"]
    for object_id in {t.object_id for t in pn_tasks}:
        none_t, image_t = (
            next(t for t in pn_tasks if t.object_id == object_id and t.condition == c) for c in ("none", "image")
        )
        (nd, nt), (idir, it) = suite_paths(out, none_t.task_id), suite_paths(out, image_t.task_id)
        assert read_targets(nt).parts == read_targets(it).parts
        for f in (nd / "parts").iterdir():
            assert f.read_bytes() == (idir / "parts" / f.name).read_bytes()
        assert read_task(nd).references == [] and read_task(idir).references == ["references/01.png"]
        page = datasets / "pn" / "diagrams" / object_id / "step_2.png"
        assert Image.open(idir / "references" / "01.png").tobytes() == Image.open(page).tobytes()
    for t in manifest.tasks:
        task = read_task(suite_paths(out, t.task_id)[0])
        if t.source == "ikea_manual":
            assert t.condition == "manual" and len(task.references) == 3  # all pages
        if t.source == "assemblybench":
            assert t.condition == "manual" and len(task.references) == t.n_parts - 1  # one diagram per step
        if t.source == "fantastic_breaks":
            assert t.condition == "none" and t.n_parts == 2

    # deterministic: the same command gives the same suite
    out2 = tmp_path / "suite2"
    assert main(_args(datasets, out2)) == 0
    assert read_manifest(out2).tasks == manifest.tasks
    for t in manifest.tasks:
        assert suite_paths(out, t.task_id)[1].read_bytes() == suite_paths(out2, t.task_id)[1].read_bytes()


def test_compose_cli_dry_run_and_errors(datasets, tmp_path, capsys):
    assert main(_args(datasets, tmp_path / "dry", "--dry-run")) == 0
    assert not (tmp_path / "dry" / "manifest.json").exists()
    assert '"per_source": 2' in capsys.readouterr().out
    assert main(["compose", "--out", str(tmp_path / "x")]) == 2  # a usage error
    assert "no dataset given" in capsys.readouterr().err
    (datasets / "ik" / "main_data.json").write_text('[{"name": "a"}]')
    assert main(_args(datasets, tmp_path / "y")) == 1
    assert "main_data.json: [0].category: missing" in capsys.readouterr().err


def test_compose_cli_rehosted_rows_join_their_source(tmp_path):
    from dataset_fixtures import rehosted_row, write_rehosted

    write_rehosted(
        tmp_path / "dl" / "a.parquet",
        [
            rehosted_row("c1", "PartNet", "Chair", 4, pages=2),
            rehosted_row("c2", "partnet", "Table", 7, pages=2),
            rehosted_row("m1", "fantastic_breaks", "Mug", 2, pages=0),
        ],
    )
    out = tmp_path / "suite"
    assert (
        main(
            [
                "compose",
                "--out",
                str(out),
                "--rehosted",
                str(tmp_path / "dl"),
                "--per-source",
                "5",
                "--jobs",
                "1",
                "--no-progress",
                "--protocol",
                "native",
            ]
        )
        == 0
    )
    tasks = read_manifest(out).tasks
    assert sorted((t.source, t.object_id, t.condition) for t in tasks) == [
        ("fantastic_breaks", "m1", "none"),
        ("partnet", "c1", "image"),
        ("partnet", "c1", "none"),
        ("partnet", "c2", "image"),
        ("partnet", "c2", "none"),
    ]
    image = next(t for t in tasks if t.object_id == "c1" and t.condition == "image")
    ref = Image.open(suite_paths(out, image.task_id)[0] / "references" / "01.png")
    assert ref.getpixel((0, 0)) == (0, 0, 40)  # the final page (page 1 of 0..1)
