"""Every example in docs/formats.md is read by the real readers, so the doc and the code agree."""

import re
from pathlib import Path

import pytest

from aw.formats import read_final, read_manifest, read_run_info, read_targets, read_task, read_trajectory

DOC = Path(__file__).resolve().parents[3] / "docs" / "formats.md"


def examples() -> dict[str, str]:
    text = DOC.read_text(encoding="utf-8")
    found = re.findall(r"<!-- example: (\w+) -->\n```\w*\n(.*?)\n```", text, flags=re.S)
    return dict(found)


def test_every_format_has_an_example():
    assert set(examples()) == {"task", "targets", "manifest", "trajectory", "final", "run", "poses", "refine_result"}


def test_poses_and_refine_result_examples(tmp_path):
    from aw.formats.poses import read_initial_poses
    from aw.refine.exchange import read_result

    (tmp_path / "poses.json").write_text(examples()["poses"])
    poses = read_initial_poses(tmp_path / "poses.json", "partnet-chair_007-image", ["p01", "p02"])
    assert poses["p02"][:3] == [0.1, -0.2, 0.05]
    (tmp_path / "result.json").write_text(examples()["refine_result"])
    assert read_result("r", tmp_path / "result.json", ["fragment_a", "fragment_b"])[1][3] == 0.7071


def test_task_example(tmp_path):
    d = tmp_path / "partnet-chair_007-image"
    (d / "parts").mkdir(parents=True)
    (d / "references").mkdir()
    for pid in ("p01", "p02"):
        (d / "parts" / f"{pid}.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (d / "references" / "01.png").write_bytes(b"png")
    (d / "task.json").write_text(examples()["task"])
    task = read_task(d)
    assert task.part_ids == ["p01", "p02"] and task.condition == "image"


@pytest.mark.parametrize(
    "name,filename,reader,check",
    [
        ("targets", "t.json", read_targets, lambda t: t.scored_part_ids == ["p01", "p02", "p03"]),
        ("final", "final.json", read_final, lambda f: f.reason == "finished"),
        ("run", "run.json", read_run_info, lambda r: r.tokens.total == 1500),
    ],
)
def test_json_examples(tmp_path, name, filename, reader, check):
    path = tmp_path / filename
    path.write_text(examples()[name])
    assert check(reader(path))


def test_manifest_example(tmp_path):
    (tmp_path / "manifest.json").write_text(examples()["manifest"])
    m = read_manifest(tmp_path)
    assert [t.condition for t in m.tasks] == ["none", "image", "none"]


def test_trajectory_example(tmp_path):
    path = tmp_path / "trajectory.jsonl"
    path.write_text(examples()["trajectory"] + "\n")
    t = read_trajectory(path)
    assert not t.truncated and t.end.reason == "finished"
    assert [c.seq for c in t.checkpoints()] == [0, 2]
    assert t.calls[2].error.startswith("unknown id")
