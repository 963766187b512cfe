"""``assemblyworld/assemblyworld`` run by real ``inspect_ai.eval`` calls: Inspect's ``mockllm/model``
scripted by a callable that reads the tools it is offered and the replies it gets, on a real
``aw-serve`` per sample, scored by the real evaluator; ``aw-score`` on the same recordings."""

from __future__ import annotations

import base64
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("inspect_ai", reason="the Inspect AI extra is not installed (pip install -e '.[inspect]')")

from inspect_ai import eval as inspect_eval  # noqa: E402
from inspect_ai.log import resolve_sample_attachments  # noqa: E402
from inspect_ai.model import ContentImage  # noqa: E402
from inspect_helpers import (  # noqa: E402
    MANUAL_TASK,
    NONE_TASK,
    PAGE_COLOURS,
    SERVER_TOOLS,
    USAGE,
    Script,
    last_tool_json,
    make_suite,
    output,
    servers_of,
)

from assemblyworld.hooks import failed_samples  # noqa: E402
from aw.formats import read_final, read_run_info, read_trajectory  # noqa: E402
from aw_eval.cli import main as aw_score  # noqa: E402

HERE = Path(__file__).parent
TASK = "assemblyworld/assemblyworld"


@pytest.fixture(scope="module")
def suite(tmp_path_factory) -> Path:
    stale = HERE.parents[1] / "assemblyworld.egg-info"
    if stale.exists():  # it hides the installed dist-info: Inspect would name the task plain "assemblyworld"
        pytest.fail(f"remove {stale} (a pip by-product; scripts/install.sh removes it)")
    return make_suite(tmp_path_factory.mktemp("inspect") / "suite")


def _first_id(messages) -> str:
    return last_tool_json(messages)["objects"][0]["id"]


def _score(suite: Path, runs: Path, out: Path) -> dict:
    args = [str(suite), str(runs), "--out", str(out), "--final-only", "--jobs", "1", "--no-html", "--no-plots"]
    assert aw_score(args + ["--bootstrap", "20", "--permutations", "20", "--no-progress"]) in (0, 1)
    return json.loads((out / "scores.json").read_text())


@pytest.fixture(scope="module")
def main_eval(suite, tmp_path_factory):
    """Both tasks, one epoch: list the parts, move one, a call Inspect refuses (a string where
    the schema wants numbers), one the server refuses (an empty selection: Inspect's copy of the
    schema has no minItems), a capture, then the report."""
    steps = [
        lambda m: output("call", "list_objects", {}),
        lambda m: output("call", "translate_objects", {"ids": [_first_id(m)], "delta": [0.05, 0.0, 0.0]}),
        lambda m: output("call", "translate_objects", {"ids": ["p01"], "delta": "far"}),
        lambda m: output("call", "rotate_objects", {"ids": [], "angles": [0.0, 0.0, 10.0]}),
        lambda m: output("call", "capture_scene", {}),
    ]
    script = Script(steps)
    root = tmp_path_factory.mktemp("main")
    t0 = time.monotonic()
    [log] = inspect_eval(
        TASK,
        model=script.model(),
        task_args={"suite": str(suite), "runs": str(root / "runs")},
        log_dir=str(root / "logs"),
        display="none",
    )
    return log, script, root, time.monotonic() - t0


def test_each_task_is_a_scored_sample_recorded_where_aw_score_reads_it(main_eval, suite):
    log, script, root, seconds = main_eval
    print(f"two scripted samples took {seconds:.1f} s")
    assert log.status == "success", log.error
    assert sorted(s.id for s in log.samples) == sorted([NONE_TASK, MANUAL_TASK])
    for s in log.samples:
        score = s.scores["assembly_score"]
        assert set(score.value) == {"pa", "sr", "sra", "scd"}
        lines = score.explanation.splitlines()
        assert lines[0].startswith("PA ") and any(line.startswith("p01 -> ") and "CD " in line for line in lines)
        run_dir = root / "runs" / "model" / str(s.id)
        assert (run_dir / "trajectory.jsonl").is_file() and (run_dir / "final.json").is_file()
    metrics = log.results.scores[0].metrics
    assert set(metrics) == {"overall_pa", "overall_sr", "overall_sra", "overall_scd"}


def test_the_agent_gets_the_task_text_alone_and_exactly_the_servers_tools(main_eval, suite):
    log, script, root, _ = main_eval
    assert all(offered == SERVER_TOOLS for offered in script.offered)  # no submit tool, nothing else
    assert all(roles[0] == "user" for roles in script.first_roles)  # no system prompt from react()
    prompt = (suite / "tasks" / NONE_TASK / "task.json").read_text()
    sample = next(s for s in log.samples if s.id == NONE_TASK)
    assert sample.messages[0].text == json.loads(prompt)["prompt"]
    assert sample.messages[0].text == subprocess.run(
        [str(Path(sys.executable).with_name("aw-serve")), str(suite / "tasks" / NONE_TASK), "--print-prompt"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.rstrip("\n")


def test_reference_images_and_captures_reach_the_model_as_images(main_eval, suite):
    log, _, _, _ = main_eval
    samples = [resolve_sample_attachments(s) for s in log.samples]  # the log keeps images as attachments
    manual = next(s for s in samples if s.id == MANUAL_TASK)
    images = [c for c in manual.messages[0].content if isinstance(c, ContentImage)]
    assert len(images) == 2
    for image, colour, page in zip(images, PAGE_COLOURS, ("01.png", "02.png"), strict=True):
        data = base64.b64decode(image.image.split(",", 1)[1])
        assert data == (suite / "tasks" / MANUAL_TASK / "references" / page).read_bytes()
        assert colour  # the pages differ, so equal bytes in this order means the paper's order
    none = next(s for s in samples if s.id == NONE_TASK)
    assert not any(isinstance(c, ContentImage) for c in none.messages[0].content)
    for s in samples:
        capture = next(m for m in s.messages if m.role == "tool" and m.function == "capture_scene")
        shots = [c for c in capture.content if isinstance(c, ContentImage)]
        assert len(shots) == 1 and base64.b64decode(shots[0].image.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"


def test_one_connection_records_every_call_that_reached_the_server(main_eval):
    """basic_agent would reconnect per call (a new scene each time, and a second aw-serve on
    the same run folder is refused): react() keeps one session, so the recording holds the
    calls in order and the moved part is still moved at the end."""
    log, _, root, _ = main_eval
    for s in log.samples:
        run_dir = root / "runs" / "model" / str(s.id)
        traj = read_trajectory(run_dir / "trajectory.jsonl")
        assert [c.tool for c in traj.calls] == ["list_objects", "translate_objects", "rotate_objects", "capture_scene"]
        assert [c.ok for c in traj.calls] == [True, True, False, True]
        assert traj.end.reason == "disconnect"
        moved = traj.calls[1].changed[0]
        assert read_final(run_dir / "final.json").poses[moved] != traj.header.initial_poses[moved]


def test_malformed_calls_get_the_tool_error_and_the_run_counts_the_refused_one(main_eval):
    log, _, root, _ = main_eval
    for s in log.samples:
        tools = [m for m in s.messages if m.role == "tool"]
        refused, server = tools[2], tools[3]
        assert refused.error is not None and refused.error.type == "parsing" and "far" in refused.error.message
        assert server.error is not None and "ids" in server.error.message  # aw-serve's own error
        assert s.messages[-1].role == "assistant" and s.messages[-1].text.startswith("Done")  # went on
        info = read_run_info(root / "runs" / "model" / str(s.id) / "run.json")
        assert info.extra["recorded_calls"] == 4 and info.extra["refused_calls"] == 1
        assert info.mcp_calls == 5  # what Claude Code or Codex would have sent to the server
        assert info.extra["refused"][0]["tool"] == "translate_objects"
        assert info.ended == "finished" and info.report == s.messages[-1].text
        assert info.harness.startswith("inspect-ai ") and info.agent == "mockllm/model"
        assert info.tokens.input == 6 * USAGE["input_tokens"] and info.tokens.output == 6 * USAGE["output_tokens"]
        assert info.wall_seconds > 0 and info.extra["tool_errors"] == 1


def test_the_logs_scores_equal_aw_score_on_the_same_runs(main_eval, suite):
    log, _, root, _ = main_eval
    doc = _score(suite, root / "runs", root / "report")
    overall = doc["quality"]["systems"]["model"]["overall"]
    metrics = log.results.scores[0].metrics
    for key in ("pa", "sr", "sra", "scd"):
        assert metrics[f"overall_{key}"].value == pytest.approx(overall[key], abs=1e-9)
    runs = {r["task_id"]: r for r in doc["runs"]}
    for s in log.samples:
        value, run = s.scores["assembly_score"].value, runs[str(s.id)]
        assert 100 * value["pa"] == pytest.approx(run["pa"], abs=1e-9) and value["sr"] == run["sr"]
        assert value["sra"] == run["sra"] and math.isclose(value["scd"], run["scd"], abs_tol=1e-12)
        assert run["run_json"]["mcp_calls"] == 5
    report = (root / "report" / "report.md").read_text()
    assert "MCP calls include the calls the harness refused before they reached aw-serve" in report
    assert "model 2 in 2 runs" in report
    assert "The paper's eight systems are not shown" in report and "not converted from the official" in report


def test_no_server_outlives_the_eval(main_eval, suite):
    assert servers_of(str(suite)) == []


def test_a_limit_ends_the_episode_scored_and_epochs_record_apart(suite, tmp_path):
    """A message limit ends each epoch's episode like a finished one: scored, run.json says
    timeout. Two epochs record in attempt-1/ and attempt-2/, which aw-score reads as two systems."""
    script = Script([lambda m: output("call", "get_state", {})] * 10)
    [log] = inspect_eval(
        TASK,
        model=script.model(),
        task_args={"suite": str(suite), "runs": str(tmp_path / "runs"), "tasks": NONE_TASK, "system": "mock"},
        epochs=2,
        message_limit=4,
        log_dir=str(tmp_path / "logs"),
        display="none",
    )
    assert log.status == "success" and len(log.samples) == 2
    doc = _score(suite, tmp_path / "runs", tmp_path / "report")
    assert sorted(doc["systems"]) == ["mock/attempt-1", "mock/attempt-2"]
    runs = {r["system"]: r for r in doc["runs"]}
    for s in log.samples:
        assert s.limit is not None and s.limit.type == "message"
        run_dir = tmp_path / "runs" / "mock" / f"attempt-{s.epoch}" / NONE_TASK
        info = read_run_info(run_dir / "run.json")
        assert info.ended == "timeout" and "limit" in info.error and info.extra["epoch"] == s.epoch
        assert info.extra["epochs"] == 2
        assert 100 * s.scores["assembly_score"].value["pa"] == pytest.approx(runs[f"mock/attempt-{s.epoch}"]["pa"])
    assert not (tmp_path / "runs" / "mock" / NONE_TASK).exists()


def test_the_spent_budget_ends_the_episode_and_its_state_is_scored(suite, tmp_path):
    async def wait(messages):
        import anyio

        await anyio.sleep(1.5)  # past the 0.6 s budget, which start_episode started
        return output("call", "translate_objects", {"ids": ["p01"], "delta": [0.1, 0.0, 0.0]})

    script = Script(
        [lambda m: output("call", "start_episode", {}), wait] + [lambda m: output("call", "get_state", {})] * 5
    )
    [log] = inspect_eval(
        TASK,
        model=script.model(),
        task_args={"suite": str(suite), "runs": str(tmp_path / "runs"), "tasks": NONE_TASK, "budget_minutes": 0.01},
        log_dir=str(tmp_path / "logs"),
        display="none",
    )
    assert log.status == "success"
    [sample] = log.samples
    run_dir = tmp_path / "runs" / "model" / NONE_TASK
    assert read_final(run_dir / "final.json").reason == "timeout"
    info = read_run_info(run_dir / "run.json")
    assert info.ended == "timeout" and "timeout" in info.error
    assert sum(1 for m in sample.messages if m.role == "assistant") == 2  # nothing after the budget's end
    assert "assembly_score" in sample.scores


def test_a_server_that_dies_fails_the_sample_naming_it(suite, tmp_path):
    def kill(messages):
        for proc in servers_of(str(tmp_path / "runs")):
            proc.kill()
        return output("call", "get_state", {})

    script = Script([lambda m: output("call", "list_objects", {}), kill, lambda m: output("call", "get_state", {})])
    [log] = inspect_eval(
        TASK,
        model=script.model(),
        task_args={"suite": str(suite), "runs": str(tmp_path / "runs"), "tasks": NONE_TASK},
        log_dir=str(tmp_path / "logs"),
        display="none",
    )
    assert log.status == "error" and "ended with status error" in failed_samples(log)
    [sample] = log.samples
    assert sample.error is not None and "aw-serve" in sample.error.message
    assert "exited during the episode" in sample.error.message
    assert not sample.scores  # a failed sample is never scored as if it had run
    info = read_run_info(tmp_path / "runs" / "model" / NONE_TASK / "run.json")
    assert info.ended == "error" and "exited during the episode" in info.error
    assert servers_of(str(tmp_path / "runs")) == []


def _inspect(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "COLUMNS": "200"}
    inspect_bin = str(Path(sys.executable).with_name("inspect"))
    return subprocess.run([inspect_bin, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=600)


def test_inspect_eval_exits_1_when_a_server_refuses_to_start_and_keeps_the_old_recording(suite, tmp_path, main_eval):
    _, _, root, _ = main_eval
    import shutil

    runs = tmp_path / "runs"
    shutil.copytree(root / "runs" / "model" / NONE_TASK, runs / "model" / NONE_TASK)

    def recording() -> dict[str, bytes]:  # .aw-lock names the last server that tried, by design
        return {
            p.name: p.read_bytes()
            for p in (runs / "model" / NONE_TASK).iterdir()
            if p.is_file() and p.name != ".aw-lock"
        }

    before = recording()
    done = _inspect(
        "eval", TASK, "--model", "mockllm/model", "-T", f"suite={suite}", "-T", f"runs={runs}", "-T", f"tasks={NONE_TASK}",
        "--log-dir", str(tmp_path / "logs"), "--display", "plain", "--no-fail-on-error", cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 1, done.stdout + done.stderr
    said = done.stdout + done.stderr
    assert "already holds a recording" in said and "1 sample failed" in said  # the eval itself "succeeded"
    assert recording() == before and "run.json" in before
    assert servers_of(str(runs)) == []


def test_ctrl_c_leaves_no_server_and_keeps_the_recording(suite, tmp_path):
    proc = subprocess.Popen(
        [sys.executable, str(HERE / "interrupted_eval.py"), str(suite), str(tmp_path / "runs"), str(tmp_path / "logs")],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        for line in proc.stdout:
            if line.startswith("WAITING"):
                break
        assert servers_of(str(tmp_path / "runs")) != []
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert servers_of(str(tmp_path / "runs")) == []
    run_dir = tmp_path / "runs" / "model" / NONE_TASK
    assert read_final(run_dir / "final.json").reason in ("disconnect", "interrupted")
    info = read_run_info(run_dir / "run.json")
    assert info.ended == "error" and info.error == "interrupted" and info.extra["recorded_calls"] == 1


def test_a_model_error_fails_the_sample_with_its_own_message(suite, tmp_path):
    def broken(messages):
        raise RuntimeError("the provider is out of reach")

    script = Script([lambda m: output("call", "list_objects", {}), broken])
    [log] = inspect_eval(
        TASK,
        model=script.model(),
        task_args={"suite": str(suite), "runs": str(tmp_path / "runs"), "tasks": NONE_TASK},
        log_dir=str(tmp_path / "logs"),
        display="none",
    )
    [sample] = log.samples
    assert "the provider is out of reach" in sample.error.message and "aw-serve" not in sample.error.message
    info = read_run_info(tmp_path / "runs" / "model" / NONE_TASK / "run.json")
    assert info.ended == "error" and info.error == "the provider is out of reach"
    assert servers_of(str(tmp_path / "runs")) == []
