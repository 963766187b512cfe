"""The runner against the real ``aw-serve`` over stdio, for every baseline agent."""

from __future__ import annotations

import numpy as np
import pytest

from aw.formats import read_final, read_run_info, read_targets, read_task, read_trajectory, write_run_info
from aw.formats.suite import suite_paths
from aw.meshes import load_task_meshes
from aw.pose import apply_pose
from aw.runner.batch import BatchConfig, RunnerError, run_batch, system_label
from aw.runner.cli import main as aw_run

EDIT_TOOLS = {"translate_objects", "rotate_objects", "set_object_pose"}


def vertex_errors(suite, task_id: str, poses: dict[str, list[float]]) -> dict[str, float]:
    """Largest vertex displacement of each part between ``poses`` and its target pose."""
    task_dir, targets_path = suite_paths(suite, task_id)
    task = read_task(task_dir)
    targets = read_targets(targets_path)
    out = {}
    for part, mesh in zip(task.parts, load_task_meshes(task), strict=True):
        got = apply_pose(np.asarray(poses[part.id]), mesh.vertices)
        want = apply_pose(np.asarray(targets.parts[part.id].pose), mesh.vertices)
        out[part.id] = float(np.abs(got - want).max())
    return out


@pytest.fixture(scope="module")
def agent_runs(tiny_suite, tmp_path_factory):
    """Each agent on one task (the oracle on two), through the real server."""
    from concurrent.futures import ThreadPoolExecutor

    out = tmp_path_factory.mktemp("runs")

    def one(agent: str):
        cfg = BatchConfig(
            suite_dir=tiny_suite,
            system=agent,
            out_dir=out,
            agent=agent,
            jobs=2,
            tasks=["tiny_table_none", "tiny_shelf_none"] if agent == "oracle" else ["tiny_table_none"],
            progress=False,
        )
        return agent, run_batch(cfg)

    # Four batches at once: they share nothing but the suite.
    with ThreadPoolExecutor(4) as pool:
        results = dict(pool.map(one, ("idle", "random", "heuristic", "oracle")))
    return out, results


def test_every_agent_finishes_and_leaves_a_scorable_run(agent_runs):
    out, results = agent_runs
    for agent, res in results.items():
        assert res.endings() == {"finished": len(res.runs)}, (agent, [r.error for r in res.runs])
        for info in res.runs:
            run_dir = out / agent / info.task_id
            disk = read_run_info(run_dir / "run.json")
            assert disk.system == agent and disk.agent == agent and disk.ended == "finished"
            traj = read_trajectory(run_dir / "trajectory.jsonl")
            assert traj.end is not None and traj.end.reason == "disconnect"
            assert read_final(run_dir / "final.json").poses == traj.final_poses()
            # run.json counts what the server recorded, per tool.
            assert disk.mcp_calls == len(traj.calls) == sum(disk.extra["call_counts"].values())
            assert disk.extra["final_source"] == "server"
            assert disk.wall_seconds > 0 and disk.report
            tools = [c.tool for c in traj.calls]
            assert tools[0] == "start_episode"
            # Behaves like an agent: looks (captures kept with the run) and moves the camera.
            assert tools.count("capture_scene") >= 2 and "move_camera" in tools
            assert len(list((run_dir / "captures").glob("*.png"))) == tools.count("capture_scene")
            assert all(c.ok for c in traj.calls), [c.error for c in traj.calls if not c.ok]


def test_idle_never_edits_and_random_does(agent_runs):
    out, _ = agent_runs
    idle = read_trajectory(out / "idle" / "tiny_table_none" / "trajectory.jsonl")
    assert not any(c.tool in EDIT_TOOLS for c in idle.calls)
    assert idle.final_poses() == idle.header.initial_poses
    rnd = read_trajectory(out / "random" / "tiny_table_none" / "trajectory.jsonl")
    edits = [c for c in rnd.calls if c.poses is not None]
    assert len(edits) >= 8
    assert rnd.final_poses() != rnd.header.initial_poses


def test_oracle_uses_both_routes_and_reaches_the_targets(agent_runs, tiny_suite):
    out, _ = agent_runs
    for task_id in ("tiny_table_none", "tiny_shelf_none"):
        traj = read_trajectory(out / "oracle" / task_id / "trajectory.jsonl")
        tools = [c.tool for c in traj.calls]
        assert {"set_object_pose", "rotate_objects", "translate_objects"} <= set(tools)
        errors = vertex_errors(tiny_suite, task_id, read_final(out / "oracle" / task_id / "final.json").poses)
        assert max(errors.values()) < 1e-9, errors


def test_heuristic_moves_parts_without_reading_targets(agent_runs, tiny_suite):
    out, _ = agent_runs
    run_dir = out / "heuristic" / "tiny_table_none"
    traj = read_trajectory(run_dir / "trajectory.jsonl")
    assert sum(1 for c in traj.calls if c.poses is not None) >= 4
    # It stacks by bounding boxes: nothing near the answer, and every part was moved.
    errors = vertex_errors(tiny_suite, "tiny_table_none", traj.final_poses())
    assert min(errors.values()) > 1e-3
    assert all(traj.final_poses()[p] != traj.header.initial_poses[p] for p in traj.header.part_ids)


def test_existing_runs_are_skipped_unless_overwrite(agent_runs, tiny_suite):
    out, _ = agent_runs
    cfg = BatchConfig(
        suite_dir=tiny_suite, system="idle", out_dir=out, agent="idle", tasks=["tiny_table_none"], progress=False
    )
    res = run_batch(cfg)
    assert res.skipped == ["tiny_table_none"] and res.runs == []


def test_a_run_made_with_other_options_is_refused_not_reused(agent_runs, tiny_suite, capsys):
    out, _ = agent_runs
    base = [str(tiny_suite), "--out", str(out), "--tasks", "tiny_table_none", "--no-progress"]
    before = (out / "oracle" / "tiny_table_none" / "run.json").read_bytes()
    assert aw_run([*base, "--agent", "oracle", "--system", "oracle", "--noise", "1.5"]) == 2
    err = capsys.readouterr().err
    assert (
        "aw-run: error: " + str(out / "oracle") + " holds 2 runs made with other options (--noise not set there, "
        "1.5 now); pass --system LABEL to run these options as another system, or --overwrite without --tasks "
        "(or with --tasks also naming tiny_shelf_none) to replace them"
    ) in err
    assert aw_run([*base, "--agent", "idle", "--seed", "3"]) == 2
    assert "(--seed 0 there, 3 now)" in capsys.readouterr().err
    # another task under the same label, with other options: the system would mix two configurations
    other = [str(tiny_suite), "--out", str(out), "--tasks", "tiny_shelf_none", "--no-progress", "--agent", "idle"]
    for extra in ([], ["--overwrite"]):
        assert aw_run([*other, "--seed", "3", *extra]) == 2
        assert (
            "holds 1 run made with other options (--seed 0 there, 3 now); pass --system LABEL to run these "
            "options as another system, or --overwrite without --tasks (or with --tasks also naming "
            "tiny_table_none) to replace them"
        ) in capsys.readouterr().err
    assert not (out / "idle" / "tiny_shelf_none").exists()
    assert (out / "oracle" / "tiny_table_none" / "run.json").read_bytes() == before
    # a run.json written before the settings were kept: its other fields still tell the options
    legacy = out / "legacy"
    (legacy / "tiny_table_none").mkdir(parents=True)
    info = read_run_info(out / "idle" / "tiny_table_none" / "run.json")
    info.extra.pop("settings")
    write_run_info(legacy / "tiny_table_none" / "run.json", info)
    assert aw_run([*base, "--agent", "idle", "--system", "legacy", "--think-seconds", "0.5"]) == 2
    assert "(--think-seconds 0 there, 0.5 now)" in capsys.readouterr().err


def test_the_default_label_carries_the_oracle_noise(tiny_suite, tmp_path, capsys):
    assert system_label("oracle", None, {"noise": 0.5}) == "oracle-noise0.5" and system_label("idle", None) == "idle"
    base = [str(tiny_suite), "--out", str(tmp_path), "--tasks", "tiny_table_none", "--no-progress", "--agent", "oracle"]
    assert aw_run([*base, "--noise", "1.5"]) == 0
    assert capsys.readouterr().out.startswith("oracle-noise1.5: 1 episode in ")
    assert aw_run([*base, "--agent-option", "noise=1.5"]) == 0  # the same configuration: reused
    assert "skipped 1 with an existing run.json (same options)" in capsys.readouterr().out
    settings = read_run_info(tmp_path / "oracle-noise1.5" / "tiny_table_none" / "run.json").extra["settings"]
    assert settings["option.noise"] == 1.5 and settings["agent"] == "oracle" and settings["seed"] == 0


@pytest.mark.parametrize(
    "args, message",
    [
        (["--agent", "nobody"], "unknown agent"),
        (["--agent", "idle", "--noise", "0.5"], "--noise applies to the oracle"),
        (["--agent", "oracle", "--noise", "-1"], "--noise must be"),
        (["--agent", "idle", "--tasks", "no_such_task"], "tasks not in the suite"),
    ],
)
def test_cli_rejects_bad_arguments_before_running(tiny_suite, tmp_path, capsys, args, message):
    code = aw_run([str(tiny_suite), "--out", str(tmp_path), "--no-progress", *args])
    assert code == 2
    assert message in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_cli_rejects_a_bad_jobs_count_as_a_usage_error(tiny_suite, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        aw_run([str(tiny_suite), "--out", str(tmp_path), "--agent", "idle", "--jobs", "0"])
    assert exc.value.code == 2 and "--jobs must be >= 1" in capsys.readouterr().err


def test_cli_rejects_a_missing_suite(tmp_path, capsys):
    assert aw_run([str(tmp_path / "nope"), "--agent", "idle", "--out", str(tmp_path / "o")]) == 2
    assert "suite directory not found" in capsys.readouterr().err


def test_config_needs_exactly_one_of_agent_or_harness(tiny_suite, tmp_path):
    with pytest.raises(RunnerError, match="exactly one"):
        run_batch(BatchConfig(suite_dir=tiny_suite, system="x", out_dir=tmp_path, progress=False))


def test_unknown_agent_options_are_refused_with_the_known_list(tiny_suite, tmp_path, capsys):
    # `edit` is a typo of the random agent's `edits`: once accepted and ignored.
    rc = aw_run([str(tiny_suite), "--agent", "random", "--agent-option", "edit=3", "--out", str(tmp_path / "o")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "unknown --agent-option edit for agent 'random'; known: edits" in err
    assert not (tmp_path / "o").exists()
    with pytest.raises(RunnerError, match="known: none"):
        run_batch(
            BatchConfig(
                suite_dir=tiny_suite,
                system="x",
                out_dir=tmp_path / "o",
                agent="heuristic",
                agent_options={"views": 2},
                progress=False,
            )
        )


def test_a_run_dir_a_live_server_records_into_is_left_untouched(tiny_suite, tmp_path):
    import os
    import subprocess
    import sys

    run_dir = tmp_path / "o" / "idle" / "tiny_table_none"
    hold = (
        "import sys, time; from aw.runlock import RunDirLock; RunDirLock(sys.argv[1], command='live-server')"
        ".acquire(); print('locked', flush=True); time.sleep(120)"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", hold, str(run_dir)],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
    )
    try:
        assert proc.stdout.readline().strip() == "locked"
        (run_dir / "trajectory.jsonl").write_text("live\n")
        res = run_batch(
            BatchConfig(
                suite_dir=tiny_suite,
                system="idle",
                out_dir=tmp_path / "o",
                agent="idle",
                tasks=["tiny_table_none"],
                overwrite=True,
                progress=False,
            )
        )
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
    (info,) = res.runs
    assert info.ended == "error" and f"being recorded by pid {proc.pid}" in info.error and "live-server" in info.error
    assert (run_dir / "trajectory.jsonl").read_text() == "live\n" and not (run_dir / "run.json").exists()
