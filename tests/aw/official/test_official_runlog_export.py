"""Runs recorded here written as an official run log: official -> project -> official keeps
every sample's states, and the run log reads back as the official evaluation reads it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aw.formats import FormatError
from aw.official.convert import write_episode_run
from aw.official.episode import read_part_episode
from aw.official.ids import task_id_for_sample
from aw.official.package import OfficialPackage
from aw.official.runlog import read_run, select_attempts
from aw.official.runlog_export import export_runs
from tests.aw.official.builders import FINAL, write_active, write_package


@pytest.fixture(scope="module")
def package(tmp_path_factory):
    return OfficialPackage(write_package(tmp_path_factory.mktemp("pkg") / "benchmark"), strict=False)


def _project_runs(package, tmp_path):
    """Official archives of three samples (the PartNet id in both blocks) converted to project runs."""
    runs = tmp_path / "runs"
    finals = {}
    samples = [("partnet-none", "21905"), ("partnet-final-image", "21905"), ("ikea-manualbook", "Chair/reidar")]
    for k, (block, sid) in enumerate(samples):
        final = FINAL.copy()
        final[1, :3] += [0.0, 0.01 * k, 0.0]
        arc = write_active(package.initial_archive(block, sid), tmp_path / f"{k}.episode.zip", final)
        ep = read_part_episode(
            arc.path, package.initial_archive(block, sid), package.evaluation_inputs(block, sid).part_ids
        )
        write_episode_run(ep, runs, "mysystem", task_id_for_sample(block, sid))
        finals[(block, sid)] = ep
    return runs / "mysystem", finals


def test_project_runs_become_an_official_run_log_with_the_same_states(package, tmp_path):
    system_dir, finals = _project_runs(package, tmp_path)
    run = export_runs(system_dir, package, tmp_path / "logs", options={"agent": "aw-run", "model": "m"})
    meta = json.loads((run.path / "run.json").read_text())
    assert meta["status"] == "completed" and meta["kind"] == "assembly-world-bench"
    assert meta["selection"] == {
        "partnet-none": ["21905"],
        "partnet-final-image": ["21905"],
        "ikea-manualbook": ["Chair/reidar"],
    }
    assert meta["tasks"]["ikea-manualbook"] == package.task_text("ikea-manualbook")
    package.check_run(read_run(run.path))
    chosen = select_attempts([run.path])
    assert sorted(chosen) == sorted(finals)
    for key, attempt in chosen.items():
        package.check_attempt(attempt)
        assert attempt.directory.name == ("Chair--reidar" if key[1] == "Chair/reidar" else "21905")
        assert attempt.status == "completed" and attempt.archive_saved
        back = read_part_episode(attempt.final_archive, package.initial_archive(*key), finals[key].part_ids)
        assert back.final_index == finals[key].final_index
        assert np.array_equal(back.poses, finals[key].poses)  # every state, not only the last
        poses, index = package.final_state(*key, attempt.final_archive)
        assert index == finals[key].final_index and np.array_equal(poses, finals[key].final_poses())
        rows = [json.loads(line) for line in (attempt.directory / "conversation.jsonl").read_text().splitlines()]
        assert [r["type"] for r in rows[:2]] == ["tool_call", "tool_result"] and attempt.tool_calls == len(rows) // 2


def test_all_samples_leaves_the_unrecorded_ones_pending(package, tmp_path):
    system_dir, finals = _project_runs(package, tmp_path)
    run = export_runs(system_dir, package, tmp_path / "logs", all_samples=True, run_id="r1")
    assert run.selection == {b: package.sample_ids(b) for b in package.blocks}
    assert sorted(select_attempts([run.path])) == sorted(finals)  # pending samples are not attempts
    assert run.status == "failed"


def test_tasks_that_are_not_package_samples_are_refused(package, tmp_path):
    system_dir, _ = _project_runs(package, tmp_path)
    (system_dir / "Chair_reidar").mkdir()
    (system_dir / "Chair_reidar" / "trajectory.jsonl").write_text("{}\n")
    with pytest.raises(FormatError, match="Chair_reidar: task id 'Chair_reidar' is not <block>--<slug>"):
        export_runs(system_dir, package, tmp_path / "logs")


def test_command_line(package, tmp_path, capsys):
    from aw.official.runlog_export import main

    system_dir, finals = _project_runs(package, tmp_path)
    assert main([str(package.root), str(system_dir), "--logs", str(tmp_path / "logs"), "--model", "m"]) == 0
    run = read_run(capsys.readouterr().out.strip())
    assert run.options == {"agent": "mysystem", "model": "m"} and len(run.meta["benchmark"]["revision"]) == 40
    assert sorted(select_attempts([run.path])) == sorted(finals)
    assert main([str(package.root), str(tmp_path / "nowhere"), "--logs", str(tmp_path / "logs")]) == 2
    assert "nowhere: no recorded run" in capsys.readouterr().err


def test_conversion_never_replaces_a_live_recording(package, tmp_path):
    from aw.runlock import RunDirLock

    block, sid = "partnet-none", "21905"
    arc = write_active(package.initial_archive(block, sid), tmp_path / "a.episode.zip", FINAL.copy())
    ep = read_part_episode(
        arc.path, package.initial_archive(block, sid), package.evaluation_inputs(block, sid).part_ids
    )
    task_id = task_id_for_sample(block, sid)
    run_dir = tmp_path / "runs" / "mysystem" / task_id
    with RunDirLock(run_dir, command="aw-serve live"):
        (run_dir / "trajectory.jsonl").write_text("live\n")
        with pytest.raises(FileExistsError, match="being recorded by pid .*aw-serve live"):
            write_episode_run(ep, tmp_path / "runs", "mysystem", task_id, force=True)
        assert (run_dir / "trajectory.jsonl").read_text() == "live\n"
    write_episode_run(ep, tmp_path / "runs", "mysystem", task_id, force=True)  # once it is released
    assert (run_dir / "trajectory.jsonl").read_text() != "live\n"
