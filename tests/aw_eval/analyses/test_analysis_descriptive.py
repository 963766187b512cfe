"""SCD concentration, part-size ratios, part-count bands, completion reports, robustness pairing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from aw.formats import RunInfo, SuiteEntry
from aw_eval.analyses import completion_reports, part_count_bands, part_scale, robustness, scd_tail
from aw_eval.analyses.part_count import band_of
from aw_eval.analyses.part_scale import ratio_summary
from aw_eval.analyses.scd_tail import scd_concentration
from aw_eval.study import TaskFacts
from tests.aw_eval.score_helpers import make_study, paper_entries, run_from_errors


def test_scd_concentration_hand_computed():
    v = np.array([1.0] * 19 + [81.0]) / 1000  # N = 20 -> k = 1
    s = scd_concentration(v)
    assert s["k"] == 1 and s["n"] == 20
    assert s["contribution"] == pytest.approx(81.0)
    assert (
        s["mean"] == pytest.approx(5.0)
        and s["median"] == pytest.approx(1.0)
        and s["remaining_mean"] == pytest.approx(1.0)
    )
    assert scd_concentration(np.arange(21.0))["k"] == math.ceil(0.05 * 21) == 2
    assert scd_concentration([np.nan]) is None


def test_ratio_summary_against_numpy():
    r = np.array([1.0, 2.0, 3.0, 12.0, 20.0])
    s = ratio_summary(r)
    assert s["median"] == 3.0 and s["q1"] == 2.0 and s["q3"] == 12.0
    assert s["p90"] == pytest.approx(np.percentile(r, 90)) and s["above_10"] == pytest.approx(40.0)


def test_part_scale_counts_each_object_once():
    entries = paper_entries(n_objects=2)
    facts = {e.task_id: TaskFacts(e.task_id, 4, 2.0 + int(e.object_id[1:]), 1.0, []) for e in entries}
    study = make_study(
        entries, {("A", e.task_id): run_from_errors("A", e.task_id, [0.0]) for e in entries}, facts=facts
    )
    ps = part_scale(study)
    assert list(ps) == ["partnet", "ikea_manual", "assemblybench", "fantastic_breaks"]
    assert ps["partnet"]["n"] == 2 and ps["partnet"]["median"] == pytest.approx(2.5)


def test_part_count_bands():
    assert [band_of(n) for n in (1, 2, 5, 6, 10, 11, 20, 21)] == [
        "1",
        "2-5",
        "2-5",
        "6-10",
        "6-10",
        "11-20",
        "11-20",
        ">20",
    ]
    entries = [
        SuiteEntry(task_id=f"t{n}", source="partnet", condition="none", object_id=f"o{n}", category="chair", n_parts=n)
        for n in (3, 4, 8, 15)
    ]
    runs = {
        ("A", "t3"): run_from_errors("A", "t3", [0.0] * 3),
        ("A", "t4"): run_from_errors("A", "t4", [0.0, 0.0, 1, 1]),
        ("A", "t8"): run_from_errors("A", "t8", [1.0] * 8),
        ("A", "t15"): run_from_errors("A", "t15", [0.0] * 15),
    }
    rows = part_count_bands(make_study(entries, runs))["systems"]["A"]
    assert len(rows) == 1
    b = rows[0]["bands"]
    assert b["2-5"] == {"n": 2, "pa": pytest.approx(75.0), "sr": pytest.approx(50.0)}
    assert b["6-10"]["sr"] == 0.0 and b["11-20"]["sr"] == 100.0


def test_completion_reports():
    entries = paper_entries(n_objects=1, n_parts=4)
    runs = {}
    infos = {}
    flags = [True, True, False, None, True]
    for e, flag, errs in zip(
        entries, flags, ([0, 0, 0, 0], [0, 0, 1, 1], [0, 0, 0, 0], [1, 1, 1, 1], [0, 1, 1, 1]), strict=True
    ):
        runs[("A", e.task_id)] = run_from_errors("A", e.task_id, errs)
        infos[("A", e.task_id)] = RunInfo(system="A", task_id=e.task_id, declared_complete=flag)
    c = completion_reports(make_study(entries, runs, infos))["A"]
    assert c == {
        "declared": 3,
        "declared_successful": 1,
        "not_declared": 1,
        "no_report": 1,
        "median_incorrect_fraction_of_failed_claims": pytest.approx(62.5),
    }


def test_robustness_pairs_variants_with_their_original():
    entries = [
        SuiteEntry(task_id="base", source="ikea_manual", condition="manual", object_id="o1", n_parts=3),
        SuiteEntry(
            task_id="base-layout_a",
            source="ikea_manual",
            condition="manual",
            object_id="o1",
            n_parts=3,
            variant="layout",
            base_task_id="base",
        ),
        SuiteEntry(
            task_id="base-missing",
            source="ikea_manual",
            condition="manual",
            object_id="o1",
            n_parts=2,
            variant="missing",
            base_task_id="base",
        ),
    ]
    runs = {
        ("A", "base"): run_from_errors("A", "base", [0, 0, 1]),
        ("A", "base-layout_a"): run_from_errors("A", "base-layout_a", [0, 0, 0]),
        ("A", "base-missing"): run_from_errors("A", "base-missing", [0, 0]),
    }
    study = make_study(entries, runs)
    assert study.original_ids == ["base"]  # variants stay out of the benchmark aggregate
    rb = robustness(study)["systems"]["A"]
    row = rb["rows"][0]
    assert row["original"]["pa"] == pytest.approx(200 / 3) and row["original"]["sr"] == 0.0
    assert row["layout"][0]["sr"] == 1.0 and row["missing"][0]["pa"] == 100.0 and row["distractor"] == []
    assert {(s["kind"], s["n"]) for s in rb["summary"]} == {("layout", 1), ("missing", 1)}


def test_scd_tail_per_cell():
    entries = paper_entries(n_objects=3, n_parts=2)
    runs = {
        ("A", e.task_id): run_from_errors(
            "A", e.task_id, [0.0, 0.0], scd=0.001 * (1 + int(e.object_id[1:])), moved=[False, False]
        )
        for e in entries
    }
    rows = scd_tail(make_study(entries, runs))["systems"]["A"]
    pn = next(r for r in rows if r["label"] == "PartNet NR")
    assert pn["n"] == 3 and pn["k"] == 1 and pn["contribution"] == pytest.approx(50.0) and pn["tail_never_moved"] == 1
