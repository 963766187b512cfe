"""Rescoring official runs: one state's official metrics from the ``exact`` evaluator."""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.spatial import cKDTree

from aw.official.evaluation_output import read_metrics, read_summary, summarize
from aw.official.package import OfficialPackage
from aw.official.runlog import create_run, write_result
from aw.pose import apply_pose
from aw_eval.cli import main as cli_main
from aw_eval.official_runs import score_state
from tests.aw.official.builders import FINAL, Recorder, write_active, write_package


@dataclass
class _Inputs:
    part_ids: list[str]
    points: np.ndarray
    target_poses: np.ndarray
    divisor: float
    groups: list[list[str]]


def _inputs() -> _Inputs:
    """Three parts: a plate and two identical, interchangeable pegs (1000 points each)."""
    rng = np.random.default_rng(5)
    plate = rng.uniform([-0.3, -0.2, -0.02], [0.3, 0.2, 0.02], (1000, 3))
    peg = rng.uniform([-0.02, -0.02, -0.1], [0.02, 0.02, 0.1], (1000, 3))
    targets = np.array([[0, 0, 0.1, 1, 0, 0, 0], [-0.2, 0, 0, 1, 0, 0, 0], [0.2, 0, 0, 1, 0, 0, 0]], dtype=float)
    return _Inputs(
        ["peg-a", "peg-b", "plate"],
        np.stack([peg, peg, plate])[[0, 1, 2]],
        targets,
        0.7,
        [["peg-a", "peg-b"], ["plate"]],
    )


def _chamfer(a, b):
    return float(np.mean(cKDTree(b).query(a)[0] ** 2) + np.mean(cKDTree(a).query(b)[0] ** 2))


def test_swapped_identical_parts_are_matched_and_everything_is_correct():
    inp = _inputs()
    inp.points = np.stack([inp.points[0], inp.points[0], inp.points[2]])
    poses = inp.target_poses[[1, 0, 2]]  # the two pegs exchanged
    m = score_state(inp, poses)
    assert (m["PA"], m["SR"]) == (1.0, True)
    assert m["SCD"] < 1e-20
    assert [(p["part_id"], p["target_part_id"], p["correct"]) for p in m["parts"]] == [
        ("peg-a", "peg-b", True),
        ("peg-b", "peg-a", True),
        ("plate", "plate", True),
    ]


def test_metrics_follow_the_official_definitions():
    """SCD = 1000 x the aligned Chamfer; a part is correct when its Chamfer to its matched
    target (after the global alignment) is at most 0.01; PA the fraction, SR all."""
    inp = _inputs()
    poses = inp.target_poses.copy()
    poses[2] = [0.0, 0.1, 0.3, np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0]  # the plate stood on edge, lifted
    m = score_state(inp, poses)
    assert 0 < m["PA"] < 1 and m["SR"] is False
    rot, t = np.array(m["alignment"]["rotation"]), np.array(m["alignment"]["translation"])
    pred = apply_pose(poses, inp.points) / inp.divisor @ rot.T + t
    target = apply_pose(inp.target_poses, inp.points) / inp.divisor
    assert m["alignment"]["chamfer"] * 1000 == m["SCD"]
    assert np.isclose(_chamfer(pred.reshape(-1, 3), target.reshape(-1, 3)), m["alignment"]["chamfer"], rtol=1e-12)
    for p in m["parts"]:
        i, j = inp.part_ids.index(p["part_id"]), inp.part_ids.index(p["target_part_id"])
        assert np.isclose(p["chamfer"], _chamfer(pred[i], target[j]), rtol=1e-12)
        assert p["correct"] == (p["chamfer"] <= 0.01)
    assert m["PA"] == np.mean([p["correct"] for p in m["parts"]]) and m["SR"] == all(p["correct"] for p in m["parts"])
    assert m["alignment"]["seed"].split("-")[0] in ("pca", "part")


# --- aw-score on an official package and its run logs -------------------------------------------

OFF = FINAL.copy()
OFF[2, :3] += [0.0, 0.0, 1.5]  # one part far from its place


@pytest.fixture(scope="module")
def package(tmp_path_factory):
    return OfficialPackage(write_package(tmp_path_factory.mktemp("pkg") / "benchmark"), strict=False)


def _new_run(pkg, logs, selection, source=None, run_id=None):
    inputs = {
        (b, s): {
            **pkg.sample(b, s).expected,
            "initial_path": str(pkg.sample(b, s).initial_path),
            "initial_calls": 0,
            "identity": pkg.configuration(b)[1]["identity"],
            "reference": pkg.sample(b, s).reference,
        }
        for b, ids in selection.items()
        for s in ids
    }
    return create_run(
        logs,
        selection,
        inputs,
        {b: pkg.task_text(b) for b in selection},
        {b: pkg.blocks[b]["reference_mode"] for b in selection},
        {"agent": "codex", "model": "m1"},
        source_run=source.path if source else None,
        run_id=run_id,
    )


def _attempt(pkg, run, block, sid, final, tmp_path, status="completed"):
    arc = write_active(
        pkg.initial_archive(block, sid), tmp_path / f"{block}-{sid.replace('/', '_')}.episode.zip", final
    )
    write_result(
        run,
        block,
        sid,
        {"status": status, "execution": {"status": status, "usage": {"input_tokens": 10}}, "duration_seconds": 3.0},
        conversation=[{"type": "tool_call", "name": "get_state"}],
        final_archive=arc.path.read_bytes(),
        archive_calls=len(arc.calls),
    )


def test_aw_score_rescores_an_official_run_chain(package, tmp_path):
    logs = tmp_path / "logs"
    everything = {b: package.sample_ids(b) for b in package.blocks}
    first = _new_run(package, logs, everything, run_id="r1")
    _attempt(package, first, "partnet-none", "21905", FINAL, tmp_path)
    _attempt(package, first, "partnet-final-image", "21905", OFF, tmp_path)  # same id, other block, other state
    write_result(first, "ikea-manualbook", "Chair/reidar", {"status": "failed", "execution": {"status": "failed"}})
    resumed = _new_run(package, logs, {"partnet-none": ["743"]}, source=first, run_id="r2")
    _attempt(package, resumed, "partnet-none", "743", FINAL, tmp_path)
    out = tmp_path / "out"
    assert (
        cli_main([str(package.root), str(logs), "--out", str(out), "--jobs", "2"]) == 1
    )  # one attempt is an error row
    folder = out / "official" / "codex-m1"
    rows = read_metrics(folder / "metrics.jsonl")
    assert [(r["block"], r["sample_id"], r["status"]) for r in rows] == [
        ("ikea-manualbook", "Chair/reidar", "error"),
        ("partnet-final-image", "21905", "scored"),
        ("partnet-none", "21905", "scored"),
        ("partnet-none", "743", "scored"),
    ]  # partnet-final-image/743: pending
    error, off, good, resumed_row = rows
    assert error["error"].startswith("FileNotFoundError") and (error["PA"], error["SR"], error["SCD"]) == (0.0, 0, None)
    assert (good["PA"], good["SR"]) == (1.0, 1) and good["SCD"] < 1e-12 and good["state_index"] == 3
    assert resumed_row["run"] == str(resumed.path) and good["run"] == str(first.path)
    inputs = package.evaluation_inputs("partnet-final-image", "21905")
    expected = score_state(inputs, OFF)
    assert (off["SCD"], off["PA"], off["SR"]) == (expected["SCD"], expected["PA"], int(expected["SR"])) and off[
        "SR"
    ] == 0
    assert off["parts"] == expected["parts"] and off["scale_divisor"] == inputs.divisor
    summary = read_summary(folder / "summary.json")
    assert summary == summarize(rows, package.benchmark)
    assert summary["status"] == "partial" and summary["official_overall"] is None and summary["scored"] == 3
    assert summary["blocks"]["partnet-none"]["PA"] == 1.0 and summary["blocks"]["ikea-manualbook"]["SCD"] is None


def test_aw_score_takes_a_folder_of_archives(package, tmp_path):
    folder = tmp_path / "episodes"
    write_active(
        package.initial_archive("partnet-final-image", "743"), folder / "partnet-final-image" / "743.episode.zip", OFF
    )
    out = tmp_path / "out"
    assert cli_main([str(package.root), str(folder), "--out", str(out), "--jobs", "1"]) == 0
    (row,) = read_metrics(out / "official" / "episodes" / "metrics.jsonl")
    expected = score_state(package.evaluation_inputs("partnet-final-image", "743"), OFF)
    assert (row["block"], row["sample_id"]) == ("partnet-final-image", "743")
    assert (row["SCD"], row["PA"]) == (expected["SCD"], expected["PA"])
    assert cli_main([str(package.root), str(folder), "--out", str(out)]) == 2  # never overwrites an evaluation


def test_a_cancelled_last_call_is_scored_from_the_last_state(package, tmp_path):
    """An attempt whose last call was cancelled as the page was exported: physics traces that
    carry a part away follow the last state, and events.jsonl has nothing for that call. The
    official reader accepts it and the official scorer restores the last state: PA 1, SR 1."""
    rec = Recorder(package.initial_archive("partnet-none", "743"))
    rec.query("start_episode")
    for k, pose in enumerate(FINAL):
        rec.move(k, pose)
    rec.cancel(2, OFF[2])
    path = tmp_path / "episodes" / "partnet-none" / "743.episode.zip"
    arc = rec.save(path)
    last_call = arc.calls[-1]
    assert last_call["error_code"] == "cancelled" and not [e for e in arc.events if e["call_id"] == last_call["id"]]
    assert not np.array_equal(arc.traces[-1].integration, arc.final_state().integration)  # the last row moved
    out = tmp_path / "out"
    assert cli_main([str(package.root), str(path.parent.parent), "--out", str(out), "--jobs", "1"]) == 0
    (row,) = read_metrics(out / "official" / "episodes" / "metrics.jsonl")
    assert row["status"] == "scored" and row["state_index"] == 3
    assert (row["PA"], row["SR"]) == (1.0, 1) and row["SCD"] < 1e-12


def test_run_logs_that_differ_from_the_package_are_refused(package, tmp_path, capsys):
    logs = tmp_path / "logs"
    run = _new_run(package, logs, {"partnet-none": ["21905"]}, run_id="r1")
    meta = json.loads((run.path / "run.json").read_text())
    meta["tasks"]["partnet-none"] = "Another task."
    (run.path / "run.json").write_text(json.dumps(meta))
    _attempt(package, run, "partnet-none", "21905", FINAL, tmp_path)
    assert cli_main([str(package.root), str(logs), "--out", str(tmp_path / "out")]) == 2
    assert "run.json: tasks['partnet-none'] differs" in capsys.readouterr().err


def test_the_evaluation_is_written_outside_the_runs(package, tmp_path, capsys):
    logs = tmp_path / "logs"
    run = _new_run(package, logs, {"partnet-none": ["21905"]}, run_id="r1")
    _attempt(package, run, "partnet-none", "21905", FINAL, tmp_path)
    assert cli_main([str(package.root), str(logs), "--out", str(logs / "eval")]) == 2
    assert "must be written outside" in capsys.readouterr().err


def test_unusable_runs_folders_get_one_line_errors(package, tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    stray = tmp_path / "stray" / "nowhere" / "21905.episode.zip"
    stray.parent.mkdir(parents=True)
    stray.write_bytes(b"not a zip")
    for runs, message in (
        (tmp_path / "missing", "runs directory not found"),
        (tmp_path / "empty", "no *.episode.zip archive"),
        (tmp_path / "stray", "no block folder above the archive"),
    ):
        assert cli_main([str(package.root), str(runs), "--out", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
