"""The bidirectional refinement analysis on hand-recorded runs: fracture metrics of each arm's
final state (exact targets score zero error), the matched task set, failures named, the paired
counts at the tolerance."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aw.formats import RunInfo, write_run_info
from aw_eval.analyses.refinement import TOLERANCE, paired_changes, refinement_study
from aw_eval.study.fixtures import box_suite, write_scripted_run

ARMS = {"agent": "a", "refiner": "r", "agent_refiner": "a-then-r", "refiner_agent": "r-then-a"}


@pytest.fixture(scope="module")
def suite(tmp_path_factory):
    return box_suite(
        tmp_path_factory.mktemp("refinement") / "suite",
        objects_per_source=2,
        n_parts=2,
        blocks=(("fantastic_breaks", ("none",)),),
    )


def _study(runs, tasks):
    runs.mkdir(parents=True, exist_ok=True)
    (runs / "refinement_study.json").write_text(
        json.dumps(
            {
                "format": "assemblyworld.refinement-study",
                "format_version": 1,
                "agent": "a",
                "refiner": "r",
                "tasks": tasks,
                "arms": [{"arm": k, "system": v} for k, v in ARMS.items()],
            }
        )
    )


def test_arms_scored_matched_and_failures_named(suite, tmp_path):
    tasks = sorted(json.loads((suite / "manifest.json").read_text())["tasks"], key=lambda t: t["task_id"])
    ids = [t["task_id"] for t in tasks]
    runs = tmp_path / "runs"
    _study(runs, ids)
    for tid in ids:
        write_scripted_run(runs / "a" / tid, suite, tid, system="a", correct=[], wrong_offset=0.5, inspect_moves=False)
        write_scripted_run(runs / "r" / tid, suite, tid, system="r", inspect_moves=False)  # exact
        write_scripted_run(runs / "a-then-r" / tid, suite, tid, system="a-then-r", inspect_moves=False)
    write_scripted_run(runs / "r-then-a" / ids[0], suite, ids[0], system="r-then-a", inspect_moves=False)
    write_run_info(
        runs / "r-then-a" / ids[1] / "run.json",
        RunInfo(system="r-then-a", task_id=ids[1], ended="crashed", error="agent raised KeyError\ntrace"),
    )
    section = refinement_study(suite, runs)
    assert section["tasks"] == 2 and section["matched"] == [ids[0]]
    assert section["failures"]["refiner_agent"] == {ids[1]: "crashed: agent raised KeyError"}
    exact = section["per_task"][ids[0]]["arms"]["refiner"]
    assert exact["re"] == pytest.approx(0, abs=1e-6) and exact["te"] == pytest.approx(0, abs=1e-9)
    assert exact["pa"] == 1.0 and exact["cd"] == pytest.approx(0, abs=1e-12)
    off = section["per_task"][ids[0]]["arms"]["agent"]
    assert off["te"] > 0 and off["cd"] > 0  # one part moved 0.5 along x after anchor alignment
    assert section["table"]["refiner"]["n"] == 1 and section["table"]["refiner_agent"]["failed"] == 1
    by = {(p["arm"], p["baseline"], p["metric"]): p for p in section["pairs"]}
    assert by[("refiner_agent", "refiner", "cd")]["unchanged"] == 1
    assert by[("agent_refiner", "agent", "pa")]["improved"] + by[("agent_refiner", "agent", "pa")]["unchanged"] == 1


def test_no_study_file_no_section_and_a_broken_one_is_named(suite, tmp_path):
    assert refinement_study(suite, tmp_path) is None
    (tmp_path / "refinement_study.json").write_text("{")
    assert "unreadable" in refinement_study(suite, tmp_path)["error"]
    (tmp_path / "refinement_study.json").write_text(json.dumps({"arms": [{"arm": "agent", "system": "a"}]}))
    assert refinement_study(suite, tmp_path)["error"].endswith("arms missing: refiner, agent_refiner, refiner_agent")


def test_paired_changes_count_within_the_tolerance():
    after = np.array([1.0, 0.5, 0.5 + TOLERANCE / 2, 0.2])
    before = np.array([0.5, 1.0, 0.5, 0.2])
    assert paired_changes(after, before, True) == {"improved": 1, "degraded": 1, "unchanged": 2}
    assert paired_changes(after, before, False) == {"improved": 1, "degraded": 1, "unchanged": 2}
    assert paired_changes([0.5 + 2 * TOLERANCE], [0.5], True)["improved"] == 1
