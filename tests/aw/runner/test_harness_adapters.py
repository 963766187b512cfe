"""Harness adapters, proven offline with a stand-in executable that plays the real harness's part.

The stand-in (``fake_harness.py``) parses the command line the adapter builds, reads the MCP
configuration it wrote, launches the configured ``aw-serve`` itself over stdio with the SDK
client, plays a short episode, and prints a transcript in the harness's own output format.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import psutil
import pytest

from aw.formats import read_final, read_run_info, read_trajectory
from aw.runner.batch import BatchConfig, run_batch
from aw.runner.harness import HARNESSES, HarnessOptions
from aw.runner.harness.codex import _toml
from aw.runner.harness.prices import PRICES_USD_PER_MTOK, estimate_cost, load_price_table

FAKE = Path(__file__).with_name("fake_harness.py")


@pytest.fixture
def fake_bin(tmp_path) -> str:
    """An executable wrapper, as a real harness binary would be."""
    path = tmp_path / "fake-harness"
    path.write_text(f'#!/bin/sh\nexec {sys.executable} {FAKE} "$@"\n')
    path.chmod(0o755)
    return str(path)


@pytest.mark.parametrize("harness", ["claude-code", "codex"])
def test_stand_in_harness_episode_is_recorded_and_scorable(harness, tiny_suite, tmp_path, fake_bin):
    out = tmp_path / "runs"
    cfg = BatchConfig(
        suite_dir=tiny_suite,
        system=f"fake-{harness}",
        out_dir=out,
        harness=harness,
        harness_bin=fake_bin,
        harness_model="gpt-5" if harness == "codex" else None,
        tasks=["tiny_table_image"],
        jobs=1,
        timeout_minutes=2.0,
        progress=False,
    )
    (info,) = run_batch(cfg).runs
    run_dir = out / cfg.system / "tiny_table_image"
    assert info.ended == "finished", info.error
    disk = read_run_info(run_dir / "run.json")
    assert disk.harness.startswith(harness)
    # The stand-in really drove the server: start, look, three edits, look again.
    traj = read_trajectory(run_dir / "trajectory.jsonl")
    tools = [c.tool for c in traj.calls]
    assert tools[0] == "start_episode" and tools.count("capture_scene") == 2
    assert sum(1 for c in traj.calls if c.poses is not None) == 3
    assert traj.end.reason == "disconnect"
    final = read_final(run_dir / "final.json")
    assert final.poses == traj.final_poses() and final.poses != traj.header.initial_poses
    assert disk.mcp_calls == len(traj.calls) == 9
    # Transcript kept; usage collected.
    lines = (run_dir / "transcript.jsonl").read_text().splitlines()
    assert all(json.loads(line) for line in lines)
    assert disk.report and "edits" in disk.report
    assert (run_dir / "prompt.txt").read_text().startswith("Assemble the supplied parts into a coherent object.")
    if harness == "claude-code":
        # 9 calls x (200 input + 800 cache read) + 100 cache creation; cost as reported.
        assert disk.tokens.input == 9 * 1000 + 100 and disk.tokens.output == 9 * 50
        assert disk.cost_usd == pytest.approx(0.0123)
        assert disk.agent == "claude-fake-1"
        cfgj = json.loads((run_dir / "mcp_config.json").read_text())
        assert list(cfgj["mcpServers"]) == ["assemblyworld"]
        assert "/tiny_table_image/references/01.png" in (run_dir / "prompt.txt").read_text()
    else:
        assert disk.tokens.input == 9 * 1000 and disk.tokens.output == 9 * 50
        assert disk.extra["cost_estimated"] is True and disk.extra["cached_input_tokens"] == 9 * 800
        p_in, p_cached, p_out = PRICES_USD_PER_MTOK["gpt-5"]
        assert disk.cost_usd == pytest.approx((9 * 200 * p_in + 9 * 800 * p_cached + 9 * 50 * p_out) / 1e6)
        assert "[mcp_servers.assemblyworld]" in (run_dir / "codex_mcp.toml").read_text()


def test_scoring_the_stand_in_run(tiny_suite, tmp_path, fake_bin):
    """The recorded final state goes through the evaluator like any other run."""
    import aw_eval
    from aw.formats.suite import suite_paths

    out = tmp_path / "runs"
    cfg = BatchConfig(
        suite_dir=tiny_suite,
        system="fake",
        out_dir=out,
        harness="claude-code",
        harness_bin=fake_bin,
        tasks=["tiny_table_none"],
        progress=False,
    )
    (info,) = run_batch(cfg).runs
    assert info.ended == "finished", info.error
    task_dir, targets = suite_paths(tiny_suite, "tiny_table_none")
    geom = aw_eval.load_task_geometry(task_dir, targets)
    poses = read_final(out / "fake" / "tiny_table_none" / "final.json").poses
    import numpy as np

    res = aw_eval.score(geom, np.array([poses[p] for p in geom.part_ids]), mode="fast")
    assert 0.0 <= res.pa <= 1.0 and res.scd >= 0


def test_a_harness_that_hangs_is_killed_with_the_server_it_started(tiny_suite, tmp_path, fake_bin, monkeypatch):
    monkeypatch.setenv("FAKE_HARNESS_MODE", "hang")
    out = tmp_path / "runs"
    cfg = BatchConfig(
        suite_dir=tiny_suite,
        system="hang",
        out_dir=out,
        harness="codex",
        harness_bin=fake_bin,
        tasks=["tiny_shelf_none"],
        timeout_minutes=0.25,
        progress=False,
    )
    (info,) = run_batch(cfg).runs
    assert info.ended == "timeout"
    run_dir = out / "hang" / "tiny_shelf_none"
    # The server (started by the harness in a session of its own) is gone too.
    assert not [p for p in psutil.process_iter(["cmdline"]) if str(run_dir) in " ".join(p.info["cmdline"] or [])]
    traj = read_trajectory(run_dir / "trajectory.jsonl")
    assert sum(1 for c in traj.calls if c.poses is not None) == 3
    assert read_final(run_dir / "final.json").poses == traj.final_poses()


def test_a_failing_harness_is_an_error_with_its_message(tiny_suite, tmp_path, fake_bin, monkeypatch):
    monkeypatch.setenv("FAKE_HARNESS_MODE", "fail")
    cfg = BatchConfig(
        suite_dir=tiny_suite,
        system="fail",
        out_dir=tmp_path,
        harness="claude-code",
        harness_bin=fake_bin,
        tasks=["tiny_shelf_none"],
        progress=False,
    )
    (info,) = run_batch(cfg).runs
    assert info.ended == "error" and "error_during_execution" in info.error
    assert info.cost_usd == pytest.approx(0.0123)


def test_missing_harness_binary_is_recorded_not_raised(tiny_suite, tmp_path):
    cfg = BatchConfig(
        suite_dir=tiny_suite,
        system="nobin",
        out_dir=tmp_path,
        harness="claude-code",
        harness_bin=str(tmp_path / "no-such-claude"),
        tasks=["tiny_shelf_none"],
        progress=False,
    )
    (info,) = run_batch(cfg).runs
    assert info.ended == "error" and "no-such-claude" in info.error


def test_claude_transcript_without_result_sums_messages_once(tmp_path):
    """Killed at the limit: no result event; each message's usage counts once (stream-json
    repeats it per content block), and no cost is invented."""
    t = tmp_path / "t.jsonl"
    msg = {
        "id": "m1",
        "usage": {"input_tokens": 10, "cache_read_input_tokens": 90, "output_tokens": 5},
        "content": [{"type": "tool_use", "name": "mcp__assemblyworld__capture_scene"}],
    }
    lines = [json.dumps({"type": "assistant", "message": msg})] * 2 + ["not json", "[" * 3000 + "]" * 3000]
    t.write_text("\n".join(lines) + "\n")
    usage = HARNESSES["claude-code"].parse(t, HarnessOptions())
    assert usage.tokens.input == 100 and usage.tokens.output == 5
    assert usage.cost_usd is None and usage.extra["usage_partial"] is True
    assert usage.extra["harness_tool_uses"] == {"mcp__assemblyworld__capture_scene": 2}
    assert usage.extra["transcript_unparsed_lines"] == 2  # the 3,000-deep line too, by the one JSON reader


def test_codex_cost_is_none_for_an_unpriced_model_and_uses_a_given_table(tmp_path):
    t = tmp_path / "t.jsonl"
    t.write_text(
        json.dumps(
            {
                "type": "turn.completed",
                "usage": {"input_tokens": 1000, "cached_input_tokens": 400, "output_tokens": 100},
            }
        )
        + "\n"
    )
    usage = HARNESSES["codex"].parse(t, HarnessOptions(model="mystery-model"))
    assert usage.cost_usd is None and "mystery-model" in usage.extra["cost_note"]
    table = tmp_path / "prices.json"
    table.write_text(json.dumps({"mystery-model": [2.0, 1.0, 10.0]}))
    usage = HARNESSES["codex"].parse(t, HarnessOptions(model="mystery-model", price_table=table))
    assert usage.cost_usd == pytest.approx((600 * 2.0 + 400 * 1.0 + 100 * 10.0) / 1e6)
    assert usage.extra["price_source"] == str(table)
    assert estimate_cost("gpt-5", 10, 0, 0, {}) is None


@pytest.mark.parametrize(
    "text, problem",
    [
        ("[" * 3000 + "]" * 3000, "JSON nested deeper than 64 levels"),
        ('{"m": [1, 2, 3], "m": [1, 2, 3]}', "duplicate key 'm'"),
        ('{"m": [1, 2]}', "list index out of range"),
        ("[]", "expected a JSON object, got an array"),
    ],
)
def test_a_bad_price_table_is_named(tmp_path, text, problem):
    table = tmp_path / "prices.json"
    table.write_text(text)
    with pytest.raises(ValueError) as info:
        load_price_table(table)
    assert str(info.value) == f"{table}: not a price table {{model: [input, cached_input, output]}} ({problem})"


def test_toml_values_round_trip():
    import tomllib

    value = {"A_B": 'x "quoted" \\ path', "n": "1"}
    for v in ("/a b/c", ["x", "y z"], value, 300, 1.5):
        assert tomllib.loads(f"v = {_toml(v)}")["v"] == v
