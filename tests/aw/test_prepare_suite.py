"""Suite building: object specs, worker errors, output directory rules, summaries."""

from __future__ import annotations

import pytest

from aw.formats import SuiteEntry, SuiteManifest
from aw.prepare import ObjectError, ObjectSpec, SuiteExistsError, build_suite, format_summary, summarize
from aw.prepare.suite import ObjectResult, prepare_output_dir

GOOD = ObjectSpec("aw.sources.synthetic:generate_object", ("fantastic_breaks", 0, 0))
BAD = ObjectSpec("aw.sources.synthetic:generate_object", ("lego", 0, 0))


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_failing_object_is_reported_by_name(tmp_path, jobs):
    with pytest.raises(ObjectError, match="unknown block 'lego'"):
        build_suite([GOOD, BAD], tmp_path / "s", name="t", jobs=jobs, progress=False)
    assert not (tmp_path / "s" / "manifest.json").exists()


def test_loader_must_return_an_assembled_object(tmp_path):
    spec = ObjectSpec("aw.sources.synthetic:plan", ("partnet", 0, 0))
    with pytest.raises(ObjectError, match="not an AssembledObject"):
        build_suite([spec], tmp_path, name="t", jobs=1, progress=False)
    with pytest.raises(ValueError, match="no objects"):
        build_suite([], tmp_path, name="t", force=True)


def test_output_dir_rules(tmp_path):
    out = prepare_output_dir(tmp_path / "new")
    assert (out / "tasks").is_dir() and (out / "targets").is_dir()
    (out / "tasks" / "old").mkdir()
    (out / "keep.txt").write_text("x")
    with pytest.raises(SuiteExistsError, match="--overwrite"):
        prepare_output_dir(out)
    prepare_output_dir(out, force=True)
    assert list((out / "tasks").iterdir()) == [] and (out / "keep.txt").exists()
    (tmp_path / "f").write_text("x")
    with pytest.raises(NotADirectoryError):
        prepare_output_dir(tmp_path / "f")


def test_summary_figures_hand_computed():
    def entry(i, source, cond="none"):
        return SuiteEntry(task_id=f"{source}-{i}-{cond}", source=source, condition=cond, object_id=str(i), n_parts=2)

    results = [
        ObjectResult(0, "0", "a", "x", 3, 1.0),
        ObjectResult(1, "1", "a", "y", 8, 2.0),
        ObjectResult(2, "2", "a", "x", 12, 4.0),
        ObjectResult(3, "3", "a", "x", 20, 10.0),
        ObjectResult(4, "4", "b", "z", 2, 1.5),
    ]
    manifest = SuiteManifest(
        name="t", tasks=[entry(i, "a") for i in range(4)] + [entry(0, "a", "image"), entry(4, "b")]
    )
    s = summarize(manifest, results)
    a = s["a"]
    assert (a["objects"], a["tasks"], a["conditions"]) == (4, 5, {"none": 4, "image": 1})
    assert (a["parts_min"], a["parts_median"], a["parts_max"], a["parts_total"]) == (3, 10.0, 20, 43)
    assert a["part_bands"] == {"2-5": 1, "6-10": 1, "11-20": 2}
    assert a["categories"] == {"x": 3, "y": 1}
    # ratios 1, 2, 4, 10: median 3, quartiles 1.75 and 5.5 (linear interpolation)
    assert (a["size_ratio_median"], a["size_ratio_q1"], a["size_ratio_q3"]) == (3.0, 1.75, 5.5)
    text = format_summary(s)
    assert "3/10/20" in text and "1/1/2" in text and "3.00 [1.75-5.50]" in text
