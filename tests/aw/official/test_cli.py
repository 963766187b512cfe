"""``aw-prepare official`` and ``aw-prepare official-export`` end to end on real files."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from aw.cli.prepare import main
from aw.episode import Episode
from aw.formats import Task, TaskPart, read_final, read_trajectory, write_task
from aw.official.archive import read_archive
from aw.official.episode import read_part_episode
from aw.prompt import task_prompt
from tests.aw.formats.hostile_json import DEEP, DUPLICATE, HUGE, inject, inject_line
from tests.aw.official.builders import FINAL, write_package, write_run_log


def test_convert_then_export(tmp_path, capsys):
    pkg_root = write_package(tmp_path / "benchmark", {"partnet-none": ["743"]})
    from aw.official.package import OfficialPackage

    pkg = OfficialPackage(pkg_root, strict=False)
    run = write_run_log(tmp_path / "logs", pkg, {("partnet-none", "743"): FINAL}, "run-1")
    original = read_archive(run / "blocks" / "partnet-none" / "samples" / "743" / "final.episode.zip")
    assert (
        main(
            [
                "official",
                str(pkg_root),
                "--episodes",
                str(tmp_path / "logs"),
                "--out",
                str(tmp_path / "suite"),
                "--runs",
                str(tmp_path / "runs"),
            ]
        )
        == 0
    )
    assert "wrote 1 task to " in capsys.readouterr().out
    run = tmp_path / "runs" / "fixture-m" / "partnet-none--743"
    out = tmp_path / "final.episode.zip"
    assert main(["official-export", str(run), "--suite", str(tmp_path / "suite"), "--out", str(out)]) == 0
    assert "3 states, final state 3" in capsys.readouterr().out
    poses, index = pkg.final_state("partnet-none", "743", out)
    assert index == 3 and np.array_equal(poses, FINAL)
    assert [f.integration.tolist() for f in read_archive(out).states] == [
        f.integration.tolist() for f in original.states
    ]
    assert main(["official-export", str(run), "--suite", str(tmp_path / "suite"), "--out", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err
    assert (
        main(["official-export", str(run), "--suite", str(tmp_path / "suite"), "--out", str(out), "--overwrite"]) == 0
    )


def _native_task(suite: Path) -> tuple[Task, list[trimesh.Trimesh]]:
    """A two-part task of this project's own (no official archive) in ``suite``."""
    task = Task(
        task_id="native",
        source="custom",
        dataset="test",
        object_id="native",
        prompt=task_prompt("none"),
        parts=[TaskPart(id=i, mesh=f"parts/{i}.obj") for i in ("p01", "p02")],
    )
    meshes = [trimesh.creation.box([0.4, 0.2, 0.1]), trimesh.creation.box([0.1, 0.1, 0.3])]
    task_dir = suite / "tasks" / "native"
    (task_dir / "parts").mkdir(parents=True)
    for i, m in zip(task.part_ids, meshes, strict=True):
        m.export(task_dir / "parts" / f"{i}.obj")
    write_task(task_dir, task)
    return task, meshes


def test_export_a_native_run(tmp_path, capsys):
    task, meshes = _native_task(tmp_path / "suite")
    ids = task.part_ids
    ep = Episode(task, meshes, tmp_path / "run", system="unit", budget_minutes=5.0)
    ep.call("start_episode", {})
    ep.call("set_object_pose", {"id": "p02", "position": [0.1, 0.2, 0.3], "quaternion": [0, 0, 1, 0]})
    ep.call("get_scene", {})
    ep.call("translate_objects", {"ids": ["p01"], "delta": [0, 0, 0.25]})
    ep.call("get_object", {"id": "p02"})
    ep.call("group_objects", {"ids": ["p01", "p02"]})
    ep.call("list_objects", {})
    ep.call("get_state", {})
    try:
        ep.call("set_object_pose", {"id": "nope", "position": [0, 0, 0]})
    except Exception:
        pass
    ep.close("finished")
    out = tmp_path / "native.episode.zip"
    assert main(["official-export", str(tmp_path / "run"), "--suite", str(tmp_path / "suite"), "--out", str(out)]) == 0
    arc = read_archive(out)
    assert [c["name"] for c in arc.calls] == [
        "start_episode",
        "set_object_pose",
        "get_scene",
        "translate_objects",
        "get_object",
        "group_objects",
        "list_objects",
        "get_state",
        "set_object_pose",
    ]
    assert [c["state_index"] for c in arc.calls] == [0, 1, 1, 2, 2, 3, 3, 3, 3] and arc.lifecycle == "active"
    by_name = {c["name"]: c for c in arc.calls[:-1]}
    assert arc.calls[1]["arguments"]["id"] == "part-0002" and arc.calls[3]["arguments"]["ids"] == ["part-0001"]
    assert by_name["start_episode"]["result"] == {"status": "active"}
    assert by_name["group_objects"]["result"] == {"status": "completed", "physics": "disabled", "index": 3}
    assert (
        by_name["get_scene"]["result"]["up"] == "Z"
        and by_name["list_objects"]["result"]["objects"] == arc.manifest["objects"]
    )
    state = by_name["get_state"]["result"]
    assert state["index"] == 3 and [o["id"] for o in state["objects"]] == ["part-0001", "part-0002"]
    assert by_name["get_object"]["result"]["id"] == "part-0002" and by_name["get_object"]["result"]["mass"] == 1.0
    assert arc.calls[-1]["status"] == "error" and "result" not in arc.calls[-1]
    assert arc.manifest["objects"][1] == {
        "id": "part-0002",
        "name": "Part p02",
        "type": "rigid",
        "collisionEnabled": False,
    }
    final = read_final(tmp_path / "run" / "final.json").poses
    restored = read_part_episode(out)
    np.testing.assert_allclose(restored.final_poses(), [final[p] for p in ids], atol=1e-12)
    np.testing.assert_allclose(
        [o["position"] + o["quaternion"] for o in state["objects"]], restored.final_poses(), atol=1e-12
    )
    header = read_trajectory(tmp_path / "run" / "trajectory.jsonl").header
    np.testing.assert_allclose(restored.poses[0], [header.initial_poses[p] for p in ids], atol=1e-12)


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda run: inject_line(run / "trajectory.jsonl", 2, DEEP), f"trajectory.jsonl: line 2: {DEEP.message}"),
        (lambda run: inject_line(run / "trajectory.jsonl", 1, DUPLICATE), "trajectory.jsonl: line 1: duplicate key"),
        (lambda run: _hostile_pose(run / "final.json", HUGE), f"final.json: {HUGE.message}"),
        (lambda run: _hostile_pose(run / "final.json", DEEP), f"final.json: {DEEP.message}"),
    ],
    ids=["trajectory-deep", "trajectory-duplicate-key", "final-integer-401-digits", "final-deep"],
)
def test_export_of_a_hostile_run_is_one_line(tmp_path, damage, message):
    """The real command on a run whose trajectory or final.json holds what no writer makes."""
    task, meshes = _native_task(tmp_path / "suite")
    ep = Episode(task, meshes, tmp_path / "run", system="unit", budget_minutes=5.0)
    ep.call("translate_objects", {"ids": ["p01"], "delta": [0, 0, 0.25]})
    ep.close("finished")
    damage(tmp_path / "run")
    out = tmp_path / "native.episode.zip"
    proc = subprocess.run(
        [str(Path(sys.executable).with_name("aw-prepare")), "official-export", str(tmp_path / "run")]
        + ["--suite", str(tmp_path / "suite"), "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    (line,) = proc.stderr.splitlines()
    assert line.startswith(f"aw-prepare: error: {tmp_path / 'run'}/{message}") and not out.exists()


def _hostile_pose(path: Path, fragment) -> None:
    final = json.loads(path.read_text())
    path.write_text(inject(final, ("poses", "p01", 0), fragment))


def test_one_line_errors(tmp_path, capsys):
    assert main(["official", str(tmp_path), "--out", str(tmp_path / "suite")]) == 2  # an unusable path
    err = capsys.readouterr().err
    assert err.startswith("aw-prepare: error: ") and "benchmark.json not found" in err and len(err.splitlines()) == 1
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "trajectory.jsonl").write_text("")
    (tmp_path / "bad.episode.zip").write_bytes(b"PK not really")
    assert (
        main(
            [
                "official-export",
                str(tmp_path / "run"),
                "--initial",
                str(tmp_path / "bad.episode.zip"),
                "--out",
                str(tmp_path / "x.episode.zip"),
            ]
        )
        == 1
    )
    assert len(capsys.readouterr().err.splitlines()) == 1


def _partly_downloaded(tmp_path):
    """A package of which only what a run of partnet-none/743 needs was downloaded (another
    block's config.json, another sample's initial archive and evaluation.json are absent), and
    that run."""
    from aw.official.package import OfficialPackage

    pkg_root = write_package(tmp_path / "benchmark")
    pkg = OfficialPackage(pkg_root, strict=False)
    write_run_log(tmp_path / "logs", pkg, {("partnet-none", "743"): FINAL}, "run-1")
    sample = pkg.sample("partnet-none", "21905")
    sample.initial_path.unlink()
    sample.evaluation_path.unlink()
    folder = pkg.configuration("ikea-manualbook")[0]
    (pkg_root / folder / "config.json").unlink()
    return pkg_root, pkg


def test_a_partly_downloaded_package_converts_what_the_runs_need(tmp_path, capsys):
    pkg_root, _ = _partly_downloaded(tmp_path)
    assert (
        main(
            [
                "official",
                str(pkg_root),
                "--episodes",
                str(tmp_path / "logs"),
                "--out",
                str(tmp_path / "suite"),
                "--runs",
                str(tmp_path / "runs"),
            ]
        )
        == 0
    )
    assert "wrote 1 task to" in capsys.readouterr().out
    assert (tmp_path / "runs" / "fixture-m" / "partnet-none--743" / "trajectory.jsonl").is_file()


def test_what_the_runs_need_and_the_package_lacks_is_named(tmp_path, capsys):
    """Every missing file in one line, before anything is written; without --episodes the
    whole package is needed."""
    pkg_root, pkg = _partly_downloaded(tmp_path)
    sample = pkg.sample("partnet-none", "743")
    sample.evaluation_path.unlink()
    assert (
        main(
            [
                "official",
                str(pkg_root),
                "--episodes",
                str(tmp_path / "logs"),
                "--out",
                str(tmp_path / "suite"),
                "--runs",
                str(tmp_path / "runs"),
            ]
        )
        == 1
    )
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "1 files the suite needs are not in the package" in err
    assert str(sample.evaluation_path.relative_to(pkg_root)) in err
    assert not (tmp_path / "suite" / "manifest.json").exists() and not (tmp_path / "runs").exists()
    assert main(["official", str(pkg_root), "--out", str(tmp_path / "suite")]) == 1
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "4 files the suite needs are not in the package" in err
    gone = pkg.sample("partnet-none", "21905")
    for path in (sample.evaluation_path, gone.initial_path, gone.evaluation_path):
        assert str(path.relative_to(pkg_root)) in err
    assert "ikea-manualbook/ikea-manual/prep-v1-s0-i0-fixture/config.json" in err


def test_a_run_whose_end_contradicts_its_calls_is_refused_or_exported_as_said(tmp_path, capsys):
    """final.json moved after the calls (as aw-score flags it): refused in one line; with
    --trust-final exported with its closing state as one more state, and said."""
    import json

    ids = ["p01", "p02"]
    task = Task(
        task_id="native",
        source="custom",
        dataset="test",
        object_id="native",
        prompt=task_prompt("none"),
        parts=[TaskPart(id=i, mesh=f"parts/{i}.obj") for i in ids],
    )
    task_dir = tmp_path / "suite" / "tasks" / "native"
    (task_dir / "parts").mkdir(parents=True)
    meshes = [trimesh.creation.box([0.4, 0.2, 0.1]), trimesh.creation.box([0.1, 0.1, 0.3])]
    for i, m in zip(ids, meshes, strict=True):
        m.export(task_dir / "parts" / f"{i}.obj")
    write_task(task_dir, task)
    ep = Episode(task, meshes, tmp_path / "run", system="unit", budget_minutes=5.0)
    ep.call("start_episode", {})
    ep.call("translate_objects", {"ids": ["p01"], "delta": [0, 0, 0.25]})
    ep.close("finished")
    final = json.loads((tmp_path / "run" / "final.json").read_text())
    final["poses"]["p02"][0] += 0.5  # an edit that no call records
    (tmp_path / "run" / "final.json").write_text(json.dumps(final))
    argv = ["official-export", str(tmp_path / "run"), "--suite", str(tmp_path / "suite")]
    capsys.readouterr()
    assert main([*argv, "--out", str(tmp_path / "a.episode.zip")]) == 1
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "contradicts the state its calls leave (parts ['p02'])" in err
    assert "--trust-final" in err and not (tmp_path / "a.episode.zip").exists()
    assert main([*argv, "--out", str(tmp_path / "b.episode.zip"), "--trust-final"]) == 0
    said = capsys.readouterr()
    assert "the closing state contradicts the calls (parts ['p02']); exported as recorded" in said.err
    arc = read_archive(tmp_path / "b.episode.zip")
    assert arc.calls[-1]["state_index"] == 1 and arc.final_state().index == 2  # one more state than the calls'
    assert "final state 2" in said.out
