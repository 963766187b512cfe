"""``aw-score`` end to end on a small box suite with hand-made trajectories: every output file,
a truncated trajectory, a missing run, an unreadable run, a final.json-only run, a run for an
unknown task, resumption, and identical results on a Dask LocalCluster and a process pool."""

from __future__ import annotations

import csv
import json
import shutil

import numpy as np
import pytest
from PIL import Image

from aw.formats import read_final, read_manifest
from aw.formats.suite import suite_paths
from aw_eval.cli import main
from aw_eval.study.fixtures import box_suite, write_scripted_run

# Small clouds keep the test fast; the protocol's own numbers are exercised by the evaluator's tests.
CK_MODE = "fast"
PROTO = ["--protocol-setting", "n_surface=256", "--protocol-setting", "n_fps=64", "--checkpoint-mode", CK_MODE]
FAST = ["--bootstrap", "200", "--permutations", "500", "--no-progress"]
ORIGINALS = [
    "partnet-box000-none",
    "partnet-box000-image",
    "ikea_manual-box000-manual",
    "assemblybench-box000-manual",
    "fantastic_breaks-box000-none",
]


def _info(**kw):
    base = {
        "wall_seconds": 300.0,
        "mcp_calls": 20,
        "cost_usd": 1.5,
        "declared_complete": True,
        "tokens": {"input": 1_000_000, "output": 200_000},
    }
    base.update(kw)
    return base


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    root = tmp_path_factory.mktemp("score")
    suite = box_suite(root / "suite", objects_per_source=1, n_parts=[3, 2, 3, 2], variants=True)
    runs = root / "runs"
    tasks = [e.task_id for e in read_manifest(suite).tasks]
    ck = {}
    alpha_tasks = ORIGINALS + [f"partnet-box000-none-{v}" for v in ("layout_a", "distractor", "missing")]
    for t in alpha_tasks:  # alpha: everything right except one AssemblyBench part
        correct = ["p02", "p03"] if t.startswith("assemblybench") else None
        ck[("alpha", t)] = write_scripted_run(
            runs / "alpha" / t, suite, t, system="alpha", correct=correct, run_info=_info(), inspect_moves=False
        ).n_checkpoints
    b = runs / "beta"
    ck[("beta", "partnet-box000-none")] = write_scripted_run(
        b / "partnet-box000-none", suite, "partnet-box000-none", system="beta", end_reason=None, cut_last_line=True
    ).n_checkpoints  # truncated, no final.json
    # partnet-box000-image: missing
    (b / "ikea_manual-box000-manual").mkdir(parents=True)
    (b / "ikea_manual-box000-manual" / "trajectory.jsonl").write_text("{ not a trajectory\n")
    write_scripted_run(root / "tmp_ab", suite, "assemblybench-box000-manual", system="beta")
    (b / "assemblybench-box000-manual").mkdir()
    shutil.copy(root / "tmp_ab" / "final.json", b / "assemblybench-box000-manual" / "final.json")  # final.json only
    ck[("beta", "fantastic_breaks-box000-none")] = write_scripted_run(
        b / "fantastic_breaks-box000-none",
        suite,
        "fantastic_breaks-box000-none",
        system="beta",
        end_reason="timeout",
        run_info=_info(ended="timeout", declared_complete=None),
        inspect_moves=False,
    ).n_checkpoints
    ck[("beta", "partnet-box000-none-layout_a")] = write_scripted_run(
        b / "partnet-box000-none-layout_a", suite, "partnet-box000-none-layout_a", system="beta", inspect_moves=False
    ).n_checkpoints
    shutil.copytree(runs / "alpha" / "ikea_manual-box000-manual", b / "not-a-task")
    out = root / "out"
    rc = main(
        [
            str(suite),
            str(runs),
            "--out",
            str(out),
            "--jobs",
            "1",
            "--seed",
            "3",
            *PROTO,
            *FAST,
            "--geometry-cache",
            str(root / "geometry"),
        ]
    )
    assert rc == 0
    doc = json.loads((out / "scores.json").read_text())
    opts = [*PROTO, "--geometry-cache", str(root / "geometry")]  # later runs share the geometry
    return {
        "root": root,
        "suite": suite,
        "opts": opts,
        "alpha_tasks": alpha_tasks,
        "runs": runs,
        "out": out,
        "doc": doc,
        "ck": ck,
        "tasks": tasks,
    }


def _run(doc, system, task):
    return next(r for r in doc["runs"] if r["system"] == system and r["task_id"] == task)


def test_scores_json_statuses_and_final_sources(study):
    doc = study["doc"]
    assert doc["format"] == "assemblyworld.scores" and doc["format_version"] == 1
    assert doc["systems"] == ["alpha", "beta"]
    assert len(doc["runs"]) == 2 * len(study["tasks"])
    assert doc["settings"]["protocol_overrides"] == {"n_fps": 64.0, "n_surface": 256.0}
    assert doc["settings"]["final_mode"] == "exact" and doc["settings"]["checkpoint_mode"] == CK_MODE
    trunc = _run(doc, "beta", "partnet-box000-none")
    assert trunc["status"] == "scored" and trunc["truncated"] and trunc["final_from"] == "trajectory"
    assert trunc["sr"] == 1.0 and trunc["pa"] == 100.0
    assert any("cut mid-write" in p for p in trunc["problems"])
    assert _run(doc, "beta", "partnet-box000-image")["status"] == "missing"
    bad = _run(doc, "beta", "ikea_manual-box000-manual")
    assert bad["status"] == "unreadable" and bad["pa"] == 0 and bad["sr"] == 0 and bad["scd"] is None
    only = _run(doc, "beta", "assemblybench-box000-manual")
    assert only["status"] == "scored" and only["final_from"] == "final.json" and only["n_checkpoints"] == 0
    assert only["sr"] == 1.0
    assert doc["unknown_runs"] == [
        {"system": "beta", "task_id": "not-a-task", "path": str(study["runs"] / "beta" / "not-a-task")}
    ]
    n_missing = (len(study["tasks"]) - len(study["alpha_tasks"])) + (len(study["tasks"]) - 5)
    assert {k: len(v) for k, v in doc["unscored_runs"].items()} == {"missing": n_missing, "unreadable": 1}
    # variants: the distractor is outside the scored parts, the missing-part task scores retained parts
    dis = _run(doc, "alpha", "partnet-box000-none-distractor")
    assert dis["sr"] == 1.0 and len(dis["part_errors"]) == 3
    mis = _run(doc, "alpha", "partnet-box000-none-missing")
    assert mis["sr"] == 1.0 and len(mis["part_errors"]) == 2
    tasks = {t["task_id"]: t for t in doc["tasks"]}
    assert (
        tasks["partnet-box000-none-distractor"]["n_parts"] == 3 and tasks["partnet-box000-none-missing"]["n_parts"] == 2
    )


def test_final_scores_match_the_evaluator_directly(study):
    """The pipeline's final scores equal aw_eval.score on the final poses (exact mode)."""
    import aw_eval
    from aw_eval.settings import ProtocolSettings

    doc = study["doc"]
    settings = ProtocolSettings(n_surface=256, n_fps=64)
    t = "assemblybench-box000-manual"
    task_dir, targets = suite_paths(study["suite"], t)
    geom = aw_eval.load_task_geometry(task_dir, targets, cache_dir=study["root"] / "geometry", settings=settings)
    final = read_final(study["runs"] / "alpha" / t / "final.json")
    poses = np.array([final.poses[p] for p in geom.part_ids])
    direct = aw_eval.score(geom, poses, mode="exact")
    r = _run(doc, "alpha", t)
    assert r["sr"] == float(direct.sr) == 0.0
    assert r["pa"] == pytest.approx(100 * float(direct.pa))
    assert r["scd"] == pytest.approx(float(direct.scd), rel=1e-9)
    assert r["part_errors"] == pytest.approx(np.asarray(direct.part_errors).tolist(), rel=1e-9)


def test_aggregates_follow_eq3(study):
    doc = study["doc"]
    q = doc["quality"]["systems"]
    ab_pa = _run(doc, "alpha", "assemblybench-box000-manual")["pa"]
    assert q["alpha"]["overall"]["sr"] == pytest.approx(75.0)  # 1/4 [1 + 1 + 0 + 1]
    assert q["alpha"]["overall"]["pa"] == pytest.approx((100 + 100 + ab_pa + 100) / 4)
    assert q["beta"]["overall"]["sr"] == pytest.approx(62.5)  # 1/4 [(1 + 0)/2 + 0 + 1 + 1]
    assert doc["outcomes"]["beta"]["missing"] == 1 and doc["outcomes"]["beta"]["unreadable"] == 1
    assert doc["outcomes"]["beta"]["timeout"] == 1
    assert doc["resources"]["alpha"]["time_min"] == {"mean": 5.0, "n": 5, "from_trajectory": 0}
    assert doc["resources"]["alpha"]["tokens_m"]["mean"] == pytest.approx(1.2)
    assert doc["completion"]["alpha"]["declared"] == 5 and doc["completion"]["alpha"]["declared_successful"] == 4
    rows = {r["base_task_id"]: r for r in doc["robustness"]["systems"]["alpha"]["rows"]}
    assert list(rows) == ["partnet-box000-none", "partnet-box000-image"]
    none = rows["partnet-box000-none"]
    assert [none[k][0]["sr"] for k in ("layout", "distractor", "missing")] == [1.0, 1.0, 1.0]
    assert rows["partnet-box000-image"]["layout"][0]["status"] == "missing"
    assert doc["part_scale"]["partnet"]["n"] == 1
    assert len(doc["uncertainty"]["pairs"]) == 1 and doc["uncertainty"]["family_size"] == 2
    fa = doc["failures"]["systems"]["alpha"]
    assert fa["failed_tasks"] == 1 and fa["wrong_parts"] >= 1


def test_csv_files(study):
    out, ck = study["out"], study["ck"]
    with open(out / "tasks.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2 * len(study["tasks"])
    by = {(r["system"], r["task_id"]): r for r in rows}
    assert by[("beta", "partnet-box000-image")]["status"] == "missing"
    assert by[("beta", "partnet-box000-none")]["truncated"] == "1"
    assert by[("beta", "partnet-box000-none")]["final_from"] == "trajectory"
    assert by[("alpha", "ikea_manual-box000-manual")]["sr"] == "1.0"
    assert by[("beta", "fantastic_breaks-box000-none")]["ended"] == "timeout"
    with open(out / "checkpoints.csv") as fh:
        cks = list(csv.DictReader(fh))
    counts: dict[tuple[str, str], int] = {}
    for r in cks:
        counts[(r["system"], r["task_id"])] = counts.get((r["system"], r["task_id"]), 0) + 1
    assert counts == ck  # every checkpoint of every readable trajectory, nothing else
    last = [r for r in cks if r["system"] == "alpha" and r["task_id"] == "ikea_manual-box000-manual"][-1]
    assert float(last["pa"]) == 1.0 and last["n_correct"] == "2" and last["n_parts"] == "2"
    first = [r for r in cks if r["system"] == "alpha"][0]
    assert first["seq"] == "0" and float(first["t"]) == 0.0


def test_report_and_plots(study):
    out = study["out"]
    md = (out / "report.md").read_text()
    table1 = md.split("## Table 1")[1].split("\n## ")[0]
    alpha = next(line for line in table1.splitlines() if line.startswith("| alpha"))
    assert "75.00" in alpha
    beta = next(line for line in table1.splitlines() if line.startswith("| beta"))
    assert "62.50" in beta
    for heading in (
        "Table A-3",
        "Table A-4",
        "Table A-5",
        "Table A-6",
        "Table A-7",
        "Table A-8",
        "Table A-9",
        "Table A-10",
        "Table A-11",
        "Table A-12",
        "Quality over time",
        "Completion reports",
    ):
        assert f"## {heading}" in md
    runs = md.split("## Runs")[1].split("\n## ")[0]
    assert "beta / partnet-box000-image" in runs and "**missing**" in runs
    assert "beta / ikea_manual-box000-manual" in runs and "**unreadable**" in runs
    assert "not-a-task" in runs
    assert "final state from trajectory" in runs
    assert "Protocol overrides" in md
    doc = study["doc"]
    assert set(doc["plots"]) == {
        "quality_normalized",
        "quality_budget",
        "thresholds",
        "activity",
        "magnitudes",
        "reference",
    }
    page = (out / "report.html").read_text()  # the same report as a page (tests/aw_eval/report/)
    assert "Table 1: benchmark results</h2>" in page and "beta / partnet-box000-image" in page
    for rel in doc["plots"].values():
        assert f"]({rel})" in md and f'<img src="{rel}"' in page
        with Image.open(out / rel) as im:
            assert im.format == "PNG" and im.width > 300 and im.height > 200


def test_second_run_recomputes_nothing_and_a_changed_run_only_that(study):
    out = study["out"]
    args = [
        str(study["suite"]),
        str(study["runs"]),
        "--out",
        str(out),
        "--jobs",
        "1",
        "--seed",
        "3",
        *study["opts"],
        *FAST,
        "--no-plots",
    ]
    assert main(args) == 0
    doc = json.loads((out / "scores.json").read_text())
    assert doc["scoring"]["scored_runs"] == 0
    assert doc["scoring"]["cached_runs"] == 13  # 8 alpha + 5 beta run directories with files
    assert doc["quality"] == study["doc"]["quality"]
    # fix alpha's AssemblyBench run: only that run is rescored
    t = "assemblybench-box000-manual"
    shutil.rmtree(study["runs"] / "alpha" / t)
    write_scripted_run(
        study["runs"] / "alpha" / t, study["suite"], t, system="alpha", run_info=_info(), inspect_moves=False
    )
    assert main(args) == 0
    doc = json.loads((out / "scores.json").read_text())
    assert doc["scoring"]["scored_runs"] == 1 and doc["scoring"]["cached_runs"] == 12
    assert doc["quality"]["systems"]["alpha"]["overall"]["sr"] == pytest.approx(100.0)


def _comparable(doc):
    return {
        (r["system"], r["task_id"]): (r["status"], r["pa"], r["sr"], r["scd"], r["part_errors"], r["n_checkpoints"])
        for r in doc["runs"]
    }


def test_dask_local_cluster_gives_identical_results(study, tmp_path):
    from distributed import LocalCluster

    ref = json.loads((study["out"] / "scores.json").read_text())  # after the resumption test, if it ran
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        rc = main(
            [
                str(study["suite"]),
                str(study["runs"]),
                "--out",
                str(tmp_path / "dask"),
                "--scheduler",
                cluster.scheduler_address,
                *study["opts"],
                *FAST,
                "--seed",
                "3",
                "--no-plots",
                "--no-html",
            ]
        )
    assert rc == 0
    doc = json.loads((tmp_path / "dask" / "scores.json").read_text())
    assert doc["scoring"]["executor"].startswith("dask:")
    assert _comparable(doc) == _comparable(ref)
    assert doc["quality"] == ref["quality"] and doc["uncertainty"] == ref["uncertainty"]
    with open(tmp_path / "dask" / "checkpoints.csv") as a, open(study["out"] / "checkpoints.csv") as b:
        assert a.read() == b.read()


def test_final_only(study, tmp_path):
    rc = main(
        [
            str(study["suite"]),
            str(study["runs"]),
            "--out",
            str(tmp_path / "fo"),
            "--final-only",
            "--jobs",
            "1",
            *study["opts"],
            *FAST,
            "--no-plots",
        ]
    )
    assert rc == 0
    doc = json.loads((tmp_path / "fo" / "scores.json").read_text())
    ref = json.loads((study["out"] / "scores.json").read_text())
    assert all(r["n_checkpoints"] == 0 for r in doc["runs"])
    assert {k: v[:4] for k, v in _comparable(doc).items()} == {k: v[:4] for k, v in _comparable(ref).items()}
    with open(tmp_path / "fo" / "checkpoints.csv") as fh:
        assert len(fh.read().strip().splitlines()) == 1  # the header alone


def test_bad_inputs(tmp_path, capsys):
    assert main([str(tmp_path / "nope"), str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert "suite directory not found" in capsys.readouterr().err
    suite = box_suite(tmp_path / "suite", objects_per_source=1, n_parts=2, blocks=(("fantastic_breaks", ("none",)),))
    assert main([str(suite), str(tmp_path / "runs"), "--out", str(tmp_path / "o")]) == 2
    assert "runs directory not found" in capsys.readouterr().err
    (tmp_path / "runs").mkdir()
    assert main([str(suite), str(tmp_path / "runs"), "--out", str(tmp_path / "o")]) == 2
    assert "no system directories" in capsys.readouterr().err
    assert main([str(suite), str(tmp_path / "runs"), "--out", str(tmp_path / "o"), "--protocol", "bogus=1"]) == 2
    assert "unknown protocol setting 'bogus'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([str(suite), str(tmp_path / "runs"), "--out", str(tmp_path / "o"), "--jobs", "0"])


def test_unreachable_scheduler_is_a_clear_error(study, tmp_path, capsys):
    rc = main(
        [
            str(study["suite"]),
            str(study["runs"]),
            "--out",
            str(tmp_path / "x"),
            "--scheduler",
            "bogus://nowhere",
            *study["opts"],
            *FAST,
        ]
    )
    assert rc == 2
    assert "cannot connect to the Dask scheduler at bogus://nowhere" in capsys.readouterr().err
