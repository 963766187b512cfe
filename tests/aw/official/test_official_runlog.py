"""The official run-log tree: layout written by :func:`create_run`/:func:`write_result`, read
back, and resumed chains merged by the official attempt selection."""

from __future__ import annotations

import json
import re

import pytest

from aw.formats import FormatError
from aw.official.runlog import (
    count_tool_calls,
    create_run,
    find_runs,
    read_attempts,
    read_run,
    sample_slug,
    select_attempts,
    write_result,
)

BLOCKS = ("partnet-none", "partnet-final-image")


def _inputs(selection):
    return {
        (b, s): {
            "episode": f"{s}.episode.zip",
            "episode_id": f"awa-{s}",
            "sha256": "0" * 64,
            "parts": 2,
            "initial_path": f"/pkg/{b}/{s}.episode.zip",
            "initial_calls": 0,
            "identity": {"dataset": b},
            "reference": None,
        }
        for b, ids in selection.items()
        for s in ids
    }


def _run(logs, selection, source=None, run_id=None):
    return create_run(
        logs,
        selection,
        _inputs(selection),
        {b: f"Assemble ({b})." for b in selection},
        {b: "none" for b in selection},
        {"agent": "codex", "model": "m"},
        protocol_text="Rules.",
        source_run=source.path if source else None,
        run_id=run_id,
    )


def _finish(run, block, sid, status="completed", archive=b"zip-bytes"):
    write_result(
        run,
        block,
        sid,
        {"status": status, "execution": {"status": status}},
        conversation=[{"type": "tool_call", "name": "get_scene"}, {"type": "tool_result"}],
        final_archive=archive,
    )


def test_sample_slug_is_the_official_folder_name():
    assert sample_slug("Chair/reidar") == "Chair--reidar"
    assert sample_slug("00/00017") == "00--00017"
    assert sample_slug("21905") == "21905"
    for bad in ("", "../x", "a b", "a//b", "./x", "Chair\\reidar"):
        with pytest.raises(ValueError, match="sample id"):
            sample_slug(bad)


def test_create_run_writes_the_official_layout(tmp_path):
    run = _run(tmp_path / "logs", {BLOCKS[0]: ["21905", "Chair/reidar"]})
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d{6}\.\d{6}\+0000-[0-9a-f]{8}", run.run_id)
    meta = json.loads((run.path / "run.json").read_text())
    assert (meta["version"], meta["kind"], meta["status"], meta["source_run"]) == (
        1,
        "assembly-world-bench",
        "running",
        None,
    )
    assert meta["selection"] == {BLOCKS[0]: ["21905", "Chair/reidar"]}
    assert (run.path / "run.json").read_text().endswith("}\n")
    sample = run.path / "blocks" / BLOCKS[0] / "samples" / "Chair--reidar"
    assert sorted(p.name for p in sample.iterdir()) == ["conversation.jsonl", "input.json", "prompt.txt", "result.json"]
    assert json.loads((sample / "result.json").read_text()) == {"status": "pending"}
    inputs = json.loads((sample / "input.json").read_text())
    assert (inputs["block"], inputs["sample_id"], inputs["parts"]) == (BLOCKS[0], "Chair/reidar", 2)
    assert (sample / "prompt.txt").read_text() == f"Assemble ({BLOCKS[0]}).\nRules."

    _finish(run, BLOCKS[0], "Chair/reidar")
    result = json.loads((sample / "result.json").read_text())
    assert result["archive"]["status"] == "saved" and result["tool_calls"] == 1
    assert count_tool_calls(sample / "conversation.jsonl") == 1
    (attempt,) = [a for a in read_attempts(read_run(run.path)) if a.sample_id == "Chair/reidar"]
    assert (
        attempt.archive_saved and attempt.final_archive.read_bytes() == b"zip-bytes" and attempt.slug == "Chair--reidar"
    )


def test_same_sample_id_in_two_blocks_stays_two_samples(tmp_path):
    run = _run(tmp_path / "logs", {BLOCKS[0]: ["2738"], BLOCKS[1]: ["2738"]})
    _finish(run, BLOCKS[0], "2738", archive=b"none")
    _finish(run, BLOCKS[1], "2738", archive=b"image")
    chosen = select_attempts([run.path])
    assert sorted(chosen) == [(BLOCKS[1], "2738"), (BLOCKS[0], "2738")]
    assert chosen[(BLOCKS[1], "2738")].final_archive.read_bytes() == b"image"


def test_resumed_chain_latest_attempt_wins_and_pending_is_skipped(tmp_path):
    logs = tmp_path / "logs"
    first = _run(logs, {BLOCKS[0]: ["a", "b", "c"]}, run_id="r1")
    _finish(first, BLOCKS[0], "a")
    _finish(first, BLOCKS[0], "b")
    resumed = _run(logs, {BLOCKS[0]: ["b", "c"]}, source=first, run_id="r2")
    _finish(resumed, BLOCKS[0], "b", status="failed", archive=None)  # a later failure replaces an earlier success
    # c: pending in both runs (not attempted)
    for given in ([resumed.path], [resumed.path, first.path], [first.path, resumed.path]):
        chosen = select_attempts(given)
        assert sorted(chosen) == [(BLOCKS[0], "a"), (BLOCKS[0], "b")]
        assert chosen[(BLOCKS[0], "a")].run == first.path
        assert chosen[(BLOCKS[0], "b")].run == resumed.path and not chosen[(BLOCKS[0], "b")].archive_saved
        assert chosen[(BLOCKS[0], "b")].root == first.path
    assert find_runs(logs) == [first.path, resumed.path]


def test_unrelated_duplicates_and_sibling_resumes_are_refused(tmp_path):
    logs = tmp_path / "logs"
    first = _run(logs, {BLOCKS[0]: ["a"]}, run_id="r1")
    _finish(first, BLOCKS[0], "a")
    other = _run(logs, {BLOCKS[0]: ["a"]}, run_id="r-other")
    _finish(other, BLOCKS[0], "a")
    with pytest.raises(ValueError, match="Duplicate sample in unrelated runs"):
        select_attempts([first.path, other.path])
    left = _run(logs, {BLOCKS[0]: ["a"]}, source=first, run_id="r2-left")
    right = _run(logs, {BLOCKS[0]: ["a"]}, source=first, run_id="r2-right")
    _finish(left, BLOCKS[0], "a")
    _finish(right, BLOCKS[0], "a")
    with pytest.raises(ValueError, match="Ambiguous sibling attempts"):
        select_attempts([left.path, right.path])


def test_bad_run_logs_get_named_errors(tmp_path):
    run = _run(tmp_path / "logs", {BLOCKS[0]: ["a"]}, run_id="r1")
    meta = json.loads((run.path / "run.json").read_text())
    (run.path / "run.json").write_text(json.dumps({**meta, "kind": "other"}))
    with pytest.raises(FormatError, match="run.json: not an official run log"):
        read_run(run.path)
    (run.path / "run.json").write_text(json.dumps({**meta, "source_run": str(run.path)}))
    with pytest.raises(FormatError, match="source_run: cycle"):
        select_attempts([run.path])
    (run.path / "run.json").write_text(json.dumps(meta))
    (run.path / "blocks" / BLOCKS[0] / "samples" / "a" / "result.json").write_text("{")
    with pytest.raises(FormatError, match="result.json: not valid JSON"):
        select_attempts([run.path])
    with pytest.raises(FormatError, match="no run folder"):
        find_runs(tmp_path)
