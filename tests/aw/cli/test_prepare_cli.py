"""``aw-prepare``: synthetic and folder suites, determinism across workers, errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import trimesh

from aw.cli.prepare import main
from aw.formats import read_manifest, read_targets, read_task
from aw.formats.suite import suite_paths
from aw.meshes import load_task_meshes
from tests.aw.formats.hostile_json import DEEP, inject


def _tree(root) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _check_suite(out):
    manifest = read_manifest(out)
    for t in manifest.tasks:
        task_dir, targets_path = suite_paths(out, t.task_id)
        task = read_task(task_dir)
        targets = read_targets(targets_path)
        assert task.task_id == t.task_id and task.condition == t.condition and task.source == t.source
        assert sorted(targets.parts) == task.part_ids
        assert len(load_task_meshes(task)) == t.n_parts
    return manifest


@pytest.fixture(scope="module")
def small_suite(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "suite"
    assert main(["synthetic", "--out", str(out), "--per-source", "2", "--jobs", "1", "--no-progress"]) == 0
    return out


def test_synthetic_suite_has_every_block_and_pairs_partnet(small_suite, capsys):
    manifest = _check_suite(small_suite)
    by_source = {}
    for t in manifest.tasks:
        by_source.setdefault(t.source, []).append(t)
    assert {s: len(v) for s, v in by_source.items()} == {
        "partnet": 4,
        "ikea_manual": 2,
        "assemblybench": 2,
        "fantastic_breaks": 2,
    }
    assert {t.condition for t in by_source["partnet"]} == {"none", "image"}
    assert {t.condition for t in by_source["ikea_manual"] + by_source["assemblybench"]} == {"manual"}
    assert {t.condition for t in by_source["fantastic_breaks"]} == {"none"}
    assert all(t.n_parts == 2 for t in by_source["fantastic_breaks"])
    for t in by_source["ikea_manual"] + by_source["assemblybench"]:
        assert len(read_task(suite_paths(small_suite, t.task_id)[0]).references) >= 2


def test_summary_is_printed(tmp_path, capsys):
    out = tmp_path / "s"
    assert (
        main(
            [
                "synthetic",
                "--out",
                str(out),
                "--per-source",
                "3",
                "--blocks",
                "fantastic_breaks",
                "--jobs",
                "1",
                "--no-progress",
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "fantastic_breaks" in text and "size ratio median" in text and "2/2/2" in text
    assert "wrote 3 tasks of 3 objects" in text


def test_parallel_build_is_byte_identical(small_suite, tmp_path):
    out = tmp_path / "par"
    args = [
        "synthetic",
        "--out",
        str(out),
        "--per-source",
        "2",
        "--blocks",
        "partnet,fantastic_breaks",
        "--jobs",
        "2",
        "--no-progress",
    ]
    assert main(args) == 0
    tasks = read_manifest(out).tasks
    assert [t for t in read_manifest(small_suite).tasks if t.source in ("partnet", "fantastic_breaks")] == tasks
    for t in tasks:
        for a, b in zip(suite_paths(out, t.task_id), suite_paths(small_suite, t.task_id), strict=True):
            assert (_tree(a) if a.is_dir() else a.read_bytes()) == (_tree(b) if b.is_dir() else b.read_bytes())


def test_existing_suite_needs_overwrite(small_suite, tmp_path, capsys):
    out = tmp_path / "again"
    args = [
        "synthetic",
        "--out",
        str(out),
        "--per-source",
        "1",
        "--blocks",
        "fantastic_breaks",
        "--jobs",
        "1",
        "--no-progress",
    ]
    assert main(args) == 0
    (out / "notes.txt").write_text("mine")
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "already holds a suite" in err and "--overwrite" in err
    assert main(args + ["--overwrite"]) == 0
    assert (out / "notes.txt").read_text() == "mine"  # --overwrite removes only the suite's own files
    assert main(args + ["--force"]) == 0  # the old name still works


def test_bad_arguments_give_one_line_errors(tmp_path, capsys):
    assert main(["synthetic", "--out", str(tmp_path / "a"), "--per-source", "0"]) == 2
    assert "--per-source" in capsys.readouterr().err
    assert main(["synthetic", "--out", str(tmp_path / "b"), "--blocks", "lego"]) == 2
    assert "unknown block" in capsys.readouterr().err
    (tmp_path / "file").write_text("x")
    assert (
        main(["synthetic", "--out", str(tmp_path / "file"), "--per-source", "1", "--blocks", "fantastic_breaks"]) == 2
    )
    assert "not a directory" in capsys.readouterr().err
    assert main(["synthetic", "--out", str(tmp_path / "file" / "sub"), "--per-source", "1"]) == 2
    assert "is a file" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["nonsense"])
    # a source path that cannot be used is a usage error (2), as --out is
    assert main(["compose", "--out", str(tmp_path / "c"), "--partnet", str(tmp_path / "nope")]) == 2
    assert "--partnet " in (err := capsys.readouterr().err) and "nope: no such file or directory" in err
    assert main(["official", str(tmp_path / "nope"), "--out", str(tmp_path / "c")]) == 2
    assert "PKG " + str(tmp_path / "nope") + ": no such directory" in capsys.readouterr().err


def _folder(root):
    for name, meta in (
        ("desk", {"category": "desk", "conditions": ["none", "image"], "source": "partnet"}),
        ("lamp", {"source": "partnet"}),
        ("vase", None),
    ):
        d = root / name
        d.mkdir(parents=True)
        for k in range(3):
            trimesh.creation.box(extents=(0.3 + 0.2 * k, 0.2, 0.1 + 0.05 * k)).apply_translation(
                (0, 0, 0.2 * k)
            ).export(d / f"part{k}.obj")
        if meta:
            (d / "meta.json").write_text(json.dumps(meta))
    return root


def test_folder_suite(tmp_path, capsys):
    src = _folder(tmp_path / "src")
    out = tmp_path / "suite"
    assert (
        main(
            [
                "folder",
                str(src),
                "--out",
                str(out),
                "--source",
                "mine",
                "--jobs",
                "1",
                "--no-progress",
                "--variants",
                "1",
            ]
        )
        == 0
    )
    manifest = _check_suite(out)
    originals = sorted((t.source, t.object_id, t.condition) for t in manifest.tasks if t.variant == "original")
    assert originals == [
        ("mine", "vase", "none"),
        ("partnet", "desk", "image"),
        ("partnet", "desk", "none"),
        ("partnet", "lamp", "none"),
    ]
    # variants for the first object of each source; the lone "mine" object has no donor
    desk_variants = sorted(t.variant for t in manifest.tasks if t.object_id == "desk" and t.condition == "none")
    assert desk_variants == ["distractor", "layout", "layout", "missing", "original"]
    vase_variants = sorted(t.variant for t in manifest.tasks if t.object_id == "vase")
    assert vase_variants == ["layout", "layout", "missing", "original"]
    assert "partnet" in capsys.readouterr().out


def test_folder_errors_name_the_file(tmp_path, capsys):
    src = _folder(tmp_path / "src")
    (src / "lamp" / "part1.obj").write_text("garbage\n")
    assert main(["folder", str(src), "--out", str(tmp_path / "o"), "--jobs", "1", "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "lamp/part1.obj" in err and "no triangles" in err
    assert main(["folder", str(tmp_path / "missing"), "--out", str(tmp_path / "o")]) == 2
    assert "source folder not found" in capsys.readouterr().err


def test_folder_refuses_an_unusable_source_and_objects_that_cannot_be_assessed(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert main(["folder", str(tmp_path / "empty"), "--out", str(tmp_path / "o")]) == 2  # a usage error, said first
    assert "empty: contains no object folders" in capsys.readouterr().err
    src = _folder(tmp_path / "src")
    (src / "single").mkdir()
    trimesh.creation.box(extents=(0.4, 0.3, 0.05)).export(src / "single" / "plate.obj")
    assert main(["folder", str(src), "--out", str(tmp_path / "o"), "--jobs", "1", "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "single: one part (plate) cannot be assessed" in err and "never moves scores PA 100%, SR 1" in err
    assert not (tmp_path / "o").exists()  # refused before any work


def test_folder_refuses_parts_saved_at_their_own_origins_unless_allowed(tmp_path, capsys):
    """A stool whose seat and legs were each exported centred at the origin: refused by name,
    before any work; --allow-overlap keeps it with a warning."""
    src = _folder(tmp_path / "src")
    (src / "stool").mkdir()
    for name, size in (("seat", (0.4, 0.3, 0.04)), ("leg_a", (0.04, 0.04, 0.4)), ("leg_b", (0.04, 0.04, 0.4))):
        trimesh.creation.box(extents=size).export(src / "stool" / f"{name}.obj")
    argv = ["folder", str(src), "--out", str(tmp_path / "o"), "--jobs", "1", "--no-progress"]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == (
        f"aw-prepare: error: {src / 'stool'}: the bounding boxes of its parts mostly overlap (3 of 3 part pairs "
        "share most of the smaller part's box): each part is likely saved centred at its own origin, not where "
        "it sits in the assembled object, so the target would be a pile on one point; export the parts in the "
        "assembled frame, or pass --allow-overlap if they truly nest"
    )
    assert not (tmp_path / "o").exists()
    assert main(argv + ["--allow-overlap"]) == 0
    err = capsys.readouterr().err
    assert f"aw-prepare: warning: {src / 'stool'}: the bounding boxes of its parts mostly overlap" in err
    assert "; kept (--allow-overlap)" in err
    assert (tmp_path / "o" / "tasks" / "custom-stool-none").is_dir()


def test_folder_summary_names_an_empty_category_and_counts_in_the_right_number(tmp_path, capsys):
    src = _folder(tmp_path / "src")
    for extra in ("desk", "lamp"):
        (src / extra / "meta.json").unlink()
        for f in (src / extra).iterdir():
            f.unlink()
        (src / extra).rmdir()
    assert main(["folder", str(src), "--out", str(tmp_path / "o"), "--jobs", "1", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "categories (no category) 1;" in out and "wrote 1 task of 1 object to" in out


@pytest.mark.parametrize(
    "text, message",
    [
        (inject({"source": "partnet"}, ("source",), DEEP), DEEP.message),
        ('{"source": "partnet", "source": "ikea_manual"}', "duplicate key 'source'"),
        (json.dumps({"category": "x" * 101}), "category: String should have at most 100 characters"),
        (
            json.dumps({"category": "x" * (20 << 20)}),
            "'category': a string of 20971520 characters, over the limit of 16777216",
        ),
    ],
    ids=["deep", "duplicate-key", "category-101-chars", "category-20-MiB"],
)
def test_a_hostile_meta_json_is_one_line_and_nothing_is_echoed_whole(tmp_path, text, message):
    """The real command: a hostile meta.json is refused by name before anything is built; a long
    category never reaches the summary or any message."""
    src = _folder(tmp_path / "src")
    (src / "lamp" / "meta.json").write_text(text)
    proc = subprocess.run(
        [str(Path(sys.executable).with_name("aw-prepare")), "folder", str(src), "--out", str(tmp_path / "o")]
        + ["--jobs", "1", "--no-progress"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2 and proc.stdout == "", proc.stdout[:300]
    assert proc.stderr.splitlines() == [f"aw-prepare: error: {src / 'lamp' / 'meta.json'}: {message}"]
    assert not (tmp_path / "o").exists()


def test_folder_warns_of_unknown_meta_keys_in_one_line(tmp_path, capsys):
    src = _folder(tmp_path / "src")
    (src / "lamp" / "meta.json").write_text(json.dumps({"source": "partnet", "scanner": "xyz"}))
    assert main(["folder", str(src), "--out", str(tmp_path / "o"), "--jobs", "1", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "aw-prepare: warning: " in err and "lamp/meta.json: unknown keys ['scanner'] are ignored" in err


def test_entry_point_runs(tmp_path):
    out = tmp_path / "ep"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "aw.cli.prepare",
            "synthetic",
            "--out",
            str(out),
            "--per-source",
            "1",
            "--blocks",
            "fantastic_breaks",
            "--jobs",
            "1",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert "preparing objects" in proc.stderr  # tqdm progress goes to stderr
    assert "fantastic_breaks" in proc.stdout
    assert len(read_manifest(out).tasks) == 1


def _no_suite(out) -> bool:
    return not any((out / n).exists() for n in ("manifest.json", "tasks", "targets", "eval_points"))


def test_folder_name_not_utf8_is_a_named_error_and_writes_nothing(tmp_path, capsys):
    """It once failed with a ValidationError on object_id after the other objects' tasks were written."""
    import os

    src = _folder(tmp_path / "src")
    (src / "lamp").rename(src / os.fsdecode(b"zz-lamp\xff"))
    out = tmp_path / "o"
    assert (
        main(["folder", str(src), "--out", str(out), "--jobs", "1", "--no-progress"]) == 2
    )  # an unusable SRC, found before any work: a usage error
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "zz-lamp\\xff" in err and "not valid UTF-8" in err
    assert _no_suite(out)


def test_a_failed_build_leaves_no_partial_suite_and_can_be_rerun(tmp_path, capsys):
    """Objects are written one by one; a failure late in the build (an unreadable reference image,
    found only when it is written) left the earlier objects' tasks and no manifest."""
    src = _folder(tmp_path / "src")
    (src / "vase" / "photo.png").write_bytes(b"not a picture")
    (src / "vase" / "meta.json").write_text(json.dumps({"references": {"image": ["photo.png"]}}))
    out = tmp_path / "o"
    args = ["folder", str(src), "--out", str(out), "--jobs", "1", "--no-progress"]
    assert main(args) == 1
    assert "photo.png" in capsys.readouterr().err
    assert _no_suite(out)
    assert not out.exists() or not any(p.name.startswith(".") for p in out.iterdir())  # no staging folder left
    # an earlier suite survives a failed --overwrite
    (src / "vase" / "meta.json").unlink()
    assert main(args) == 0
    before = _tree(out)
    (src / "vase" / "meta.json").write_text(json.dumps({"references": {"image": ["photo.png"]}}))
    assert main(args + ["--overwrite"]) == 1
    assert _tree(out) == before
    (src / "vase" / "meta.json").unlink()
    assert main(args + ["--overwrite"]) == 0 and _tree(out) == before


def test_skipped_mesh_paths_are_named(tmp_path, capsys):
    """A part path that is a directory or a link to /dev/zero was skipped without a word."""
    src = _folder(tmp_path / "src")
    (src / "desk" / "drawer.obj").mkdir()
    (src / "lamp" / "shade.stl").symlink_to("/dev/zero")
    out = tmp_path / "o"
    assert main(["folder", str(src), "--out", str(out), "--jobs", "1", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "aw-prepare: warning: " in err
    assert "desk/drawer.obj: skipped: a directory, not a mesh file" in err
    assert "lamp/shade.stl: skipped: not a regular file" in err
    assert all(t.n_parts == 3 for t in read_manifest(out).tasks)
