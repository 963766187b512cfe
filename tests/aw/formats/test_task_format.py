"""task.json and the public task directory: round trip and every malformed path."""

import json
import os

import pytest

from aw.formats import FormatError, Task, read_task, write_task


def edit_task_json(task_dir, **changes):
    path = task_dir / "task.json"
    data = json.loads(path.read_text())
    for k, v in changes.items():
        if v is KeyError:
            data.pop(k)
        else:
            data[k] = v
    path.write_text(json.dumps(data))
    return path


def test_round_trip(task_dir):
    task = read_task(task_dir)
    assert task.task_id == "demo-0001" and task.part_ids == ["p01", "p02"]
    assert task.format == "assemblyworld.task" and task.format_version == 1
    assert task.root == task_dir
    assert task.mesh_path("p02") == task_dir / "parts" / "p02.obj"
    assert task.conventions["up"] == "+Z" and task.conventions["rotation_order"] == "X, then Y, then Z"
    assert task.budget_minutes == 60.0
    copy_dir = task_dir.parent / "copy"
    write_task(copy_dir, task)
    again = Task.model_validate_json((copy_dir / "task.json").read_bytes())
    assert again.model_dump() == task.model_dump()
    # Written deterministically: sorted keys, fixed indentation.
    assert (copy_dir / "task.json").read_bytes() == (task_dir / "task.json").read_bytes()


def test_image_condition_with_reference(tmp_path, make_task):
    d = make_task(tmp_path, condition="image", task_id="t-img")
    task = read_task(d)
    assert task.reference_paths() == [d / "references" / "01.png"]


def expect_error(path_fragment, problem, task_dir):
    with pytest.raises(FormatError) as info:
        read_task(task_dir)
    assert path_fragment in str(info.value.path)
    assert problem in info.value.problem, info.value.problem
    assert str(info.value).startswith(str(info.value.path))
    return info.value


def test_missing_directory_and_file(tmp_path, task_dir):
    expect_error("nowhere", "task directory not found", tmp_path / "nowhere")
    (task_dir / "task.json").unlink()
    expect_error("task.json", "file not found", task_dir)


def test_bad_json(task_dir):
    (task_dir / "task.json").write_text('{"task_id": "x",')
    expect_error("task.json", "not valid JSON", task_dir)
    (task_dir / "task.json").write_text("")
    expect_error("task.json", "not valid JSON", task_dir)
    (task_dir / "task.json").write_bytes(b'{"task_id": "\xff"}')
    expect_error("task.json", "not valid JSON", task_dir)


def test_nan_and_duplicate_keys_are_rejected(task_dir):
    text = (task_dir / "task.json").read_text()
    (task_dir / "task.json").write_text(text.replace('"budget_minutes": 60.0', '"budget_minutes": NaN'))
    expect_error("task.json", "not valid JSON", task_dir)
    (task_dir / "task.json").write_text(
        text.replace('"budget_minutes": 60.0', '"budget_minutes": 60.0, "budget_minutes": 5')
    )
    expect_error("task.json", "duplicate key 'budget_minutes'", task_dir)


@pytest.mark.parametrize(
    "changes,problem",
    [
        ({"parts": "p01"}, "parts"),
        ({"parts": []}, "parts"),
        ({"budget_minutes": "long"}, "budget_minutes"),
        ({"budget_minutes": 0}, "budget_minutes"),
        ({"task_id": 5}, "task_id"),
        ({"task_id": "../escape"}, "task_id"),
        ({"prompt": KeyError}, "prompt"),
        ({"condition": "video"}, "condition"),
        ({"surprise": 1}, "surprise"),
        ({"format_version": 2}, "unsupported format_version 2"),
        ({"format": "assemblyworld.targets"}, "format is 'assemblyworld.targets'"),
        ({"parts": [{"id": "p01", "mesh": "parts/p01.obj"}, {"id": "p01", "mesh": "parts/p02.obj"}]}, "unique"),
        ({"parts": [{"id": "p 01", "mesh": "parts/p01.obj"}]}, "parts.0.id"),
        ({"parts": [{"id": "p01", "mesh": "parts/p01.txt"}]}, "mesh must be one of"),
        ({"parts": [{"id": "p01", "mesh": "parts/../../../etc/passwd.obj"}]}, "relative path under parts/"),
        ({"parts": [{"id": "p01", "mesh": "/etc/p01.obj"}]}, "relative path under parts/"),
        ({"parts": [{"id": "p01", "mesh": "other/p01.obj"}]}, "relative path under parts/"),
        ({"references": ["references/01.png"]}, "condition 'none' must have no references"),
        ({"condition": "image"}, "needs at least one reference image"),
        ({"condition": "manual", "references": ["../secret.png"]}, "relative path under references/"),
    ],
)
def test_invalid_fields_name_the_problem(task_dir, changes, problem):
    edit_task_json(task_dir, **changes)
    expect_error("task.json", problem, task_dir)


def test_missing_referenced_files(task_dir):
    (task_dir / "parts" / "p02.obj").unlink()
    err = expect_error("task.json", "listed file parts/p02.obj is missing", task_dir)
    assert "p02" in str(err)
    # check_files=False reads the metadata alone.
    assert read_task(task_dir, check_files=False).part_ids == ["p01", "p02"]


def test_symlink_out_of_the_task_dir_is_rejected(tmp_path, task_dir):
    outside = tmp_path / "secret.obj"
    outside.write_text("v 0 0 0\n")
    target = task_dir / "parts" / "p02.obj"
    target.unlink()
    os.symlink(outside, target)
    expect_error("task.json", "resolves outside the task directory", task_dir)
