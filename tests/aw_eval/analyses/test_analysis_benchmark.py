"""Table 1 aggregation, resources and outcomes on synthetic per-task outcomes."""

from __future__ import annotations

import numpy as np
import pytest

from aw.formats import RunInfo, TokenUsage
from aw_eval.analyses import outcomes, quality, resources
from aw_eval.report import AnalysisSettings, build_results, render_markdown
from tests.aw_eval.score_helpers import make_study, paper_entries, run_from_errors, table1_study


def test_table1_overall_from_per_task_outcomes():
    study = table1_study()
    q = quality(study)
    assert [c["label"] for c in q["cells"]] == ["PartNet NR", "PartNet IR", "IKEA M", "AB M", "FB NR"]
    astra, qwen = q["systems"]["Astra"], q["systems"]["Qwen"]
    assert [c["sr"] for c in astra["cells"]] == pytest.approx([15, 40, 65, 55, 90])
    assert [c["sr"] for c in qwen["cells"]] == pytest.approx([5, 0, 0, 10, 35])
    assert astra["overall"]["sr"] == pytest.approx(59.375)
    assert qwen["overall"]["sr"] == pytest.approx(11.875)
    # PA: a winning task has 4/4 parts, a losing one 2/4
    assert astra["overall"]["pa"] == pytest.approx(50 + 59.375 / 2)
    assert astra["sources"]["partnet"]["sr"] == pytest.approx(27.5)


def test_table1_is_printed_like_the_paper():
    study = table1_study()
    doc = build_results(study, AnalysisSettings(n_draws=200, n_permutations=500))
    md = render_markdown(doc)
    table = md.split("## Table 1")[1].split("##")[0]
    astra = next(line for line in table.splitlines() if line.startswith("| Astra"))
    qwen = next(line for line in table.splitlines() if line.startswith("| Qwen"))
    cells = [c.strip().strip("*") for c in astra.split("|")[1:-1]]
    assert cells[:7] == ["Astra", "15.00", "40.00", "65.00", "55.00", "90.00", "59.38"]
    cells = [c.strip().strip("*") for c in qwen.split("|")[1:-1]]
    assert cells[:7] == ["Qwen", "5.00", "0.00", "0.00", "10.00", "35.00", "11.88"]  # one value, two decimals
    assert cells[7:9] == ["6.00", "90"]  # time (min) and MCP calls from run.json


def test_missing_runs_count_zero_and_scd_uses_scored_attempts_only():
    entries = paper_entries(n_objects=2)
    runs = {("A", e.task_id): run_from_errors("A", e.task_id, [0.0, 0.0], scd=0.004) for e in entries}
    runs[("A", entries[0].task_id)] = run_from_errors("A", entries[0].task_id, [], status="missing")
    study = make_study(entries, runs)
    q = quality(study)["systems"]["A"]
    pn_none = q["cells"][0]
    assert pn_none["sr"] == pytest.approx(50.0) and pn_none["pa"] == pytest.approx(50.0)
    assert pn_none["scd"] == pytest.approx(4.0)  # x1000, over the one scored attempt
    assert pn_none["n_scored"] == 1
    assert q["overall"]["sr"] == pytest.approx(100 - 0.25 * 0.5 * 50)


def test_resources_are_arithmetic_means_over_available_records():
    entries = paper_entries(n_objects=1)
    runs = {
        ("A", e.task_id): run_from_errors("A", e.task_id, [0.0], end_t=600.0, call_t=np.arange(5.0)) for e in entries
    }
    infos = {
        ("A", entries[0].task_id): RunInfo(
            system="A",
            task_id=entries[0].task_id,
            wall_seconds=120.0,
            mcp_calls=10,
            tokens=TokenUsage(input=1_000_000, output=500_000),
            cost_usd=3.0,
        ),
        ("A", entries[1].task_id): RunInfo(
            system="A", task_id=entries[1].task_id, ended="timeout", tokens=TokenUsage(total=2_500_000), cost_usd=1.0
        ),
    }
    study = make_study(entries, runs, infos)
    r = resources(study)["A"]
    # time: 2 min from run.json, the other 4 tasks from the trajectory (10 min)
    assert r["time_min"]["mean"] == pytest.approx((2 + 4 * 10) / 5) and r["time_min"]["from_trajectory"] == 4
    assert r["mcp_calls"]["mean"] == pytest.approx((10 + 4 * 5) / 5)
    assert r["tokens_m"] == {"mean": pytest.approx(2.0), "n": 2}
    assert r["cost_usd"] == {"mean": pytest.approx(2.0), "n": 2}
    o = outcomes(study)["A"]
    assert o["timeout"] == 1 and o["finished"] == 4 and o["errors_timeouts"] == 1


def test_a_suite_of_variants_only_still_reports():
    from aw.formats import SuiteEntry

    e = [
        SuiteEntry(
            task_id="v",
            source="partnet",
            condition="none",
            object_id="o",
            n_parts=2,
            variant="layout",
            base_task_id="absent",
        )
    ]
    study = make_study(e, {("A", "v"): run_from_errors("A", "v", [0.0, 0.0])})
    doc = build_results(study, AnalysisSettings(n_draws=10, n_permutations=10))
    md = render_markdown(doc)
    assert "no original (non-variant) tasks" in md
    assert doc["quality"]["systems"] == {}


def test_bold_marks_only_a_real_best_among_systems_that_achieved_something():
    from aw_eval.report.fmt import bold_best, paper, threshold_label

    assert bold_best(["1", "1"], [1.0, 1.0]) == ["1", "1"]  # all tied: no best
    assert bold_best(["5"], [5.0]) == ["5"]  # one system: no best
    assert bold_best(["2", "9"], [2.0, 9.0], higher=True) == ["2", "**9**"]
    # the idle system's 18 calls are fewest, but it achieved nothing
    assert bold_best(["18", "40", "55"], [18, 40, 55], higher=False, eligible=[False, True, True]) == [
        "18",
        "**40**",
        "55",
    ]
    assert paper(85.35) == "85.35" and paper(0) == "0.00" and paper(80) == "80.00"
    assert threshold_label(0.00316228) == "0.0032" and threshold_label(0.01) == "0.01"


def test_composed_runs_add_up_both_stages_and_a_missing_stage_is_never_bold(tmp_path):
    """A run started from another system's final state (run.json extra.initial_poses, as the
    refinement study's composed arms record it) counts that system's time, calls and cost too; a
    run started from a run outside the study or a poses file leaves a stage out: said, never bold."""
    entries = paper_entries(n_objects=1)
    systems = ("agent", "refiner", "agent-then-refiner", "elsewhere-then-refiner")
    runs = {(s, e.task_id): run_from_errors(s, e.task_id, [0.0, 0.0, 0.0, 0.0]) for s in systems for e in entries}

    def info(s: str, tid: str, seconds: float, calls: int, start: str | None) -> RunInfo:
        extra = {"initial_poses": str(tmp_path / "runs" / start / tid / "final.json")} if start else {}
        return RunInfo(system=s, task_id=tid, wall_seconds=seconds, mcp_calls=calls, cost_usd=1.0, extra=extra)

    infos = {}
    for e in entries:
        t = e.task_id
        infos[("agent", t)] = info("agent", t, 600.0, 40, None)
        infos[("refiner", t)] = info("refiner", t, 6.0, 0, None)
        infos[("agent-then-refiner", t)] = info("agent-then-refiner", t, 6.0, 0, "agent")
        infos[("elsewhere-then-refiner", t)] = info("elsewhere-then-refiner", t, 3.0, 0, "not-in-this-study")
    study = make_study(entries, runs, infos)
    res = resources(study)
    both = res["agent-then-refiner"]
    assert both["time_min"]["mean"] == pytest.approx(10.1) and both["mcp_calls"]["mean"] == 40
    assert both["cost_usd"]["mean"] == 2.0 and both["time_min"]["composed"] == 5
    assert "stages_left_out" not in both["time_min"]
    short = res["elsewhere-then-refiner"]
    assert short["time_min"]["mean"] == pytest.approx(0.05) and short["time_min"]["stages_left_out"] == 5
    assert res["agent"]["time_min"] == {"mean": 10.0, "n": 5, "from_trajectory": 0}  # no new keys
    md = render_markdown(build_results(study, AnalysisSettings(n_draws=20, n_permutations=20)))
    table = md.split("## Table 1")[1].split("##")[0]
    rows = {line.split("|")[1].strip(): line.split("|")[-5:-1] for line in table.splitlines() if line.count("|") > 8}
    assert [c.strip() for c in rows["elsewhere-then-refiner"][:2]] == ["0.05", "0"]  # cheapest, yet not bold
    assert [c.strip() for c in rows["refiner"][:2]] == ["**0.10**", "**0**"]
    assert [c.strip() for c in rows["agent-then-refiner"][:2]] == ["10.10", "40"]
    assert "agent-then-refiner started from another system's final states: their resources add up both stages" in md
    assert "elsewhere-then-refiner: resources leave out the stage that made their start states" in md
