"""Hidden targets, suite manifest, final.json and run.json: round trips and malformed files."""

import json

import pytest

from aw.formats import (
    FinalState,
    FormatError,
    PartTarget,
    RunInfo,
    SuiteEntry,
    SuiteManifest,
    Targets,
    TokenUsage,
    read_final,
    read_manifest,
    read_run_info,
    read_targets,
    write_final,
    write_manifest,
    write_run_info,
    write_targets,
)
from aw.formats.suite import suite_paths
from aw.formats.targets import Variant

POSE = [0.1, 0.2, 0.3, 1.0, 0.0, 0.0, 0.0]


def make_targets():
    return Targets(
        task_id="demo-0001",
        parts={
            "p01": PartTarget(pose=POSE, source_name="leg_0"),
            "p02": PartTarget(pose=[0, 0, 0, 0.0, 0.0, 0.0, 2.0], source_name="seat"),
            "p03": PartTarget(pose=POSE, distractor=True),
        },
        equivalence_hint=[["p01", "p02"]],
        scale=0.5,
        variant=Variant(kind="distractor", base_task_id="demo-0000", distractor_from="other-obj"),
    )


def rewrite(path, mutate):
    data = json.loads(path.read_text())
    mutate(data)
    path.write_text(json.dumps(data))


def check_error(reader, path, problem, named=None):
    """``reader(path)`` raises a FormatError naming ``named`` (default ``path``) and the problem."""
    with pytest.raises(FormatError) as info:
        reader(path)
    assert str(named or path) in str(info.value)
    assert problem in info.value.problem, info.value.problem


# ---------------------------------------------------------------- targets
def test_targets_round_trip(tmp_path):
    t = make_targets()
    path = tmp_path / "targets" / "demo-0001.json"
    write_targets(path, t)
    back = read_targets(path)
    assert back == t
    assert back.scored_part_ids == ["p01", "p02"]
    assert back.parts["p02"].pose == [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0]  # stored as given; readers normalize
    assert back.eval_divisor is None and back.seed == 0


@pytest.mark.parametrize(
    "mutate,problem",
    [
        (lambda d: d["parts"]["p01"].update(pose=[0, 0, 0]), "7 numbers"),
        (lambda d: d["parts"]["p01"].update(pose=[0, 0, 0, 0, 0, 0, 0]), "zero length"),
        (lambda d: d["parts"]["p01"].update(pose=[1e308, 0, 0, 1, 0, 0, 0]), "position beyond +-1e+06"),
        (lambda d: d["parts"]["p01"].update(pose=[0, 0, 0, 1e308, 0, 0, 0]), "quaternion component beyond"),
        (lambda d: d["parts"]["p01"].update(pose="identity"), "parts.p01.pose"),
        (lambda d: d["parts"]["p01"].update(distractor="no"), "parts.p01.distractor"),
        (lambda d: d.update(parts={}), "parts"),
        (lambda d: d.update(scale=0), "scale"),
        (lambda d: d.update(scale=-1), "scale"),
        (lambda d: d.update(eval_divisor=0), "eval_divisor"),
        (lambda d: d.update(equivalence_hint=[["p01", "p09"]]), "unknown parts ['p09']"),
        (lambda d: d.update(format_version=7), "unsupported format_version 7"),
        (lambda d: d.update(format="assemblyworld.task"), "expected 'assemblyworld.targets'"),
        (lambda d: d.pop("task_id"), "task_id"),
        (lambda d: d.update(answer=42), "answer"),
        (lambda d: d["variant"].update(kind="mirror"), "variant.kind"),
    ],
)
def test_targets_invalid(tmp_path, mutate, problem):
    path = tmp_path / "t.json"
    write_targets(path, make_targets())
    rewrite(path, mutate)
    check_error(read_targets, path, problem)


def test_targets_duplicate_part_ids_and_bad_json(tmp_path):
    path = tmp_path / "t.json"
    write_targets(path, make_targets())
    text = path.read_text()
    # A second "p01" key would silently replace the first with a plain JSON parser.
    path.write_text(text.replace('"p02": {', '"p01": {', 1))
    check_error(read_targets, path, "duplicate key 'p01'")
    path.write_text(text[: len(text) // 2])
    check_error(read_targets, path, "not valid JSON")
    check_error(read_targets, tmp_path / "missing.json", "file not found")
    check_error(read_targets, tmp_path, "is a directory")


# ---------------------------------------------------------------- suite manifest
def make_manifest():
    return SuiteManifest(
        name="mini",
        generator="test",
        tasks=[
            SuiteEntry(task_id="a-none", source="partnet", condition="none", object_id="a", n_parts=3),
            SuiteEntry(task_id="a-image", source="partnet", condition="image", object_id="a", n_parts=3),
            SuiteEntry(
                task_id="a-missing",
                source="partnet",
                condition="none",
                object_id="a",
                n_parts=2,
                variant="missing",
                base_task_id="a-none",
                weight=0.5,
            ),
        ],
    )


def test_manifest_round_trip(tmp_path):
    write_manifest(tmp_path, make_manifest())
    m = read_manifest(tmp_path)
    assert m == make_manifest()
    assert m.entry("a-image").condition == "image"
    with pytest.raises(KeyError):
        m.entry("zzz")
    assert suite_paths(tmp_path, "a-none") == (tmp_path / "tasks" / "a-none", tmp_path / "targets" / "a-none.json")


@pytest.mark.parametrize(
    "mutate,problem",
    [
        (lambda d: d["tasks"].append(dict(d["tasks"][0])), "duplicate task ids ['a-none']"),
        (lambda d: d["tasks"][0].update(condition="video"), "tasks.0.condition"),
        (lambda d: d["tasks"][0].update(n_parts=0), "tasks.0.n_parts"),
        (lambda d: d["tasks"][0].update(weight=0), "tasks.0.weight"),
        (lambda d: d["tasks"][0].update(n_parts="three"), "tasks.0.n_parts"),
        (lambda d: d.update(tasks={}), "tasks"),
        (lambda d: d.update(format_version=2), "unsupported format_version 2"),
    ],
)
def test_manifest_invalid(tmp_path, mutate, problem):
    write_manifest(tmp_path, make_manifest())
    rewrite(tmp_path / "manifest.json", mutate)
    check_error(read_manifest, tmp_path, problem, named=tmp_path / "manifest.json")


def test_manifest_missing(tmp_path):
    with pytest.raises(FormatError, match="suite directory not found"):
        read_manifest(tmp_path / "nope")
    check_error(read_manifest, tmp_path, "file not found", named=tmp_path / "manifest.json")


# ---------------------------------------------------------------- final.json and run.json
def test_final_round_trip_and_invalid(tmp_path):
    final = FinalState(task_id="demo-0001", reason="timeout", poses={"p01": POSE, "p02": POSE})
    path = tmp_path / "final.json"
    write_final(path, final)
    assert read_final(path) == final
    rewrite(path, lambda d: d.update(reason="bored"))
    check_error(read_final, path, "reason")
    write_final(path, final)
    rewrite(path, lambda d: d["poses"].update(p01=[1, 2, 3]))
    check_error(read_final, path, "poses.p01")
    check_error(read_final, tmp_path / "nope.json", "file not found")


def test_run_info_round_trip_and_invalid(tmp_path):
    info = RunInfo(
        system="random",
        task_id="demo-0001",
        agent="random-agent",
        wall_seconds=12.5,
        mcp_calls=40,
        ended="finished",
        tokens=TokenUsage(input=100, output=20, total=120),
        cost_usd=0.01,
        extra={"seed": 3},
    )
    path = tmp_path / "run.json"
    write_run_info(path, info)
    assert read_run_info(path) == info
    # Unknown top-level fields are kept (harness adapters add their own).
    rewrite(path, lambda d: d.update(harness_version="2.1"))
    assert read_run_info(path).model_extra == {"harness_version": "2.1"}
    rewrite(path, lambda d: d.update(wall_seconds=-1))
    check_error(read_run_info, path, "wall_seconds")
    write_run_info(path, info)
    rewrite(path, lambda d: d.update(ended="exploded"))
    check_error(read_run_info, path, "ended")
    write_run_info(path, info)
    rewrite(path, lambda d: d["tokens"].update(input=-5))
    check_error(read_run_info, path, "tokens.input")
