"""Official package + archives -> suite and runs; runs -> official archives (round trip)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aw.formats import read_final, read_manifest, read_run_info, read_targets, read_trajectory
from aw.official.archive import read_archive
from aw.official.convert import convert, initial_archive_path
from aw.official.episode import read_part_episode
from aw.official.errors import ExportError
from aw.official.eval_points import suite_eval_inputs
from aw.official.export import export_run
from aw.official.package import OfficialPackage
from tests.aw.official.builders import FINAL, PART_IDS, write_package, write_run_log

RUN = "2026-01-02T030405.123456+0000-1a2b3c4d"
SYSTEM = "fixture-m"  # <agent>-<model> of the fixture run log's options


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    """A package and a run log (final archives for two blocks holding the same sample id, one
    of them from a timed-out execution), converted to a suite and runs."""
    root = tmp_path_factory.mktemp("conv")
    pkg = OfficialPackage(write_package(root / "benchmark"), strict=False)
    run = write_run_log(
        root / "logs",
        pkg,
        {
            ("partnet-none", "21905"): FINAL,
            ("partnet-final-image", "21905"): FINAL[::-1].copy(),
            ("ikea-manualbook", "Chair/reidar"): FINAL,
        },
        RUN,
    )
    result = run / "blocks" / "partnet-final-image" / "samples" / "21905" / "result.json"
    value = json.loads(result.read_text())
    value.update(status="failed", execution={"status": "timeout"})
    result.write_text(json.dumps(value))
    manifest, runs = convert(pkg.root, root / "logs", root / "suite", root / "runs")
    return root, pkg, manifest, runs


def test_suite_of_the_package(converted):
    """The suite holds the samples the run attempted (package order), not the whole package."""
    root, pkg, manifest, _ = converted
    ids = [t.task_id for t in manifest.tasks]
    assert ids == ["partnet-none--21905", "partnet-final-image--21905", "ikea-manualbook--Chair--reidar"]
    assert [t.condition for t in manifest.tasks] == ["none", "image", "manual"]
    assert read_manifest(root / "suite").tasks == manifest.tasks
    inputs = suite_eval_inputs(root / "suite", "ikea-manualbook--Chair--reidar")
    official = pkg.evaluation_inputs("ikea-manualbook", "Chair/reidar")
    assert np.array_equal(inputs.points, official.points) and inputs.divisor == official.divisor
    targets = read_targets(root / "suite" / "targets" / "ikea-manualbook--Chair--reidar.json")
    assert targets.eval_divisor == official.divisor
    assert (
        initial_archive_path(root / "suite", "partnet-none--21905").read_bytes()
        == pkg.sample("partnet-none", "21905").initial_path.read_bytes()
    )
    assert not initial_archive_path(root / "suite", "partnet-none--743").exists()


def test_runs_of_the_archives(converted):
    root, _, _, runs = converted
    system = SYSTEM
    assert sorted(p.name for p in runs) == [
        "ikea-manualbook--Chair--reidar",
        "partnet-final-image--21905",
        "partnet-none--21905",
    ]
    run = root / "runs" / system / "partnet-final-image--21905"
    traj = read_trajectory(run / "trajectory.jsonl")
    assert traj.header.started_at == "2026-01-02T03:04:07.178Z" and traj.header.part_ids == PART_IDS
    assert [c.tool for c in traj.calls] == [
        "start_episode",
        "get_state",
        "set_object_pose",
        "set_object_pose",
        "set_object_pose",
        "translate_objects",
        "list_objects",
    ]
    assert [c.t for c in traj.calls] == [0.0, 1.5, 3.0, 4.5, 6.0, 7.5, 9.0]
    assert not traj.calls[5].ok and traj.calls[5].error == "Unknown object: nope"
    assert traj.end.reason == "finished"  # an exported official episode is a finished one, not an error
    assert np.array_equal([traj.end.poses[p] for p in PART_IDS], FINAL[::-1])
    assert read_final(run / "final.json").reason == "finished"
    info = read_run_info(run / "run.json")
    assert info.ended == "finished" and info.extra["state_index"] == 3 and info.extra["sample_id"] == "21905"
    assert info.extra["official_status"] == "failed" and info.extra["official_execution"] == "timeout"


def test_round_trip_keeps_states(converted, tmp_path):
    """official -> project -> official: the same state indices and vectors, so the same scores."""
    root, pkg, _, _ = converted
    system = SYSTEM
    original = read_archive(
        root / "logs" / RUN / "blocks" / "ikea-manualbook" / "samples" / "Chair--reidar" / "final.episode.zip"
    )
    initial = pkg.initial_archive("ikea-manualbook", "Chair/reidar")
    again = export_run(
        root / "runs" / system / "ikea-manualbook--Chair--reidar", initial, tmp_path / "again.episode.zip"
    )
    assert [f.index for f in again.states] == [f.index for f in original.states] == [1, 2, 3]
    for a, b in zip([again.initial, *again.states], [original.initial, *original.states], strict=True):
        assert np.array_equal(a.integration, b.integration)
    assert [(c["name"], c["before_index"], c["state_index"], c["status"], c["timestamp"]) for c in again.calls] == [
        (c["name"], c["before_index"], c["state_index"], c["status"], c["timestamp"]) for c in original.calls
    ]
    assert again.manifest["id"] == original.manifest["id"] and again.lifecycle == "active"
    poses, index = pkg.final_state("ikea-manualbook", "Chair/reidar", again.path)
    assert index == 3 and np.array_equal(poses, read_part_episode(original, initial).final_poses())


def test_export_refuses_another_tasks_archive(converted, tmp_path):
    root, pkg, _, _ = converted
    run = root / "runs" / SYSTEM / "partnet-none--21905"
    other = tmp_path / "other.episode.zip"
    from tests.aw.official.builders import write_setup

    with pytest.raises(ExportError, match="parts"):
        export_run(run, write_setup(other, PART_IDS[:2]), tmp_path / "x.episode.zip")


def test_resumed_chain_counts_its_latest_attempt(tmp_path):
    """A resumed run replaces its source run's attempt, even a failed one replacing a saved
    export (which is then not converted), and both stay one system, named from the chain's first run's options."""
    pkg = OfficialPackage(write_package(tmp_path / "benchmark", {"partnet-none": ["21905", "743"]}), strict=False)
    first = write_run_log(
        tmp_path / "logs", pkg, {("partnet-none", "21905"): FINAL, ("partnet-none", "743"): FINAL}, "run-a"
    )
    moved = FINAL.copy()
    moved[0, :3] += 0.25
    write_run_log(
        tmp_path / "logs",
        pkg,
        {("partnet-none", "21905"): moved, ("partnet-none", "743"): None},
        "run-b",
        source_run=first,
    )
    skipped = []
    _, runs = convert(pkg.root, tmp_path / "logs", tmp_path / "suite", tmp_path / "runs", skipped=skipped)
    assert [p.relative_to(tmp_path / "runs").as_posix() for p in runs] == [f"{SYSTEM}/partnet-none--21905"]
    final = read_final(runs[0] / "final.json").poses
    assert np.array_equal([final[p] for p in PART_IDS], moved)
    assert len(skipped) == 1 and "run-b" in skipped[0] and "no saved final archive" in skipped[0]
