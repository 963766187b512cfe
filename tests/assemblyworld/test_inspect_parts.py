"""The Inspect task's parts without an eval: its arguments, the recording layout, run.json's
figures from a transcript, the cached default suite."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("inspect_ai", reason="the Inspect AI extra is not installed (pip install -e '.[inspect]')")

from inspect_ai.model import ChatMessageAssistant, ChatMessageTool, ChatMessageUser, ModelUsage  # noqa: E402
from inspect_ai.tool import ToolCallError  # noqa: E402
from inspect_helpers import NONE_TASK, make_suite  # noqa: E402

from assemblyworld.episode import run_dir_for, system_label  # noqa: E402
from assemblyworld.runinfo import refused_calls, token_usage  # noqa: E402
from assemblyworld.samples import task_filter  # noqa: E402
from assemblyworld.suite import DEFAULT_SUITE_NAME, default_suite  # noqa: E402
from assemblyworld.task import assemblyworld  # noqa: E402


@pytest.fixture(scope="module")
def suite(tmp_path_factory) -> Path:
    return make_suite(tmp_path_factory.mktemp("parts") / "suite")


@pytest.mark.parametrize(
    ("args", "said"),
    [
        ({"surface": "web"}, "surface='web': expected one of default, official"),
        ({"budget_minutes": 0}, "budget_minutes=0: must be a positive number of minutes"),
        ({"budget_minutes": "soon"}, "budget_minutes='soon': not a number"),
        ({"system": "a/b"}, "system='a/b': must be a plain folder name"),
        ({"tasks": "nope"}, "tasks=nope: tasks not in the suite: nope"),
    ],
)
def test_bad_task_arguments_are_named_in_one_line(suite, args, said):
    with pytest.raises(ValueError) as err:
        assemblyworld(suite=str(suite), **args)
    assert said in str(err.value) and "\n" not in str(err.value)


def test_a_folder_that_is_no_playable_suite_is_refused(tmp_path, suite):
    with pytest.raises(ValueError, match="suite=.*manifest.json"):
        assemblyworld(suite=str(tmp_path))
    (tmp_path / "scoring").mkdir()
    (tmp_path / "scoring" / "manifest.json").write_bytes((suite / "manifest.json").read_bytes())
    with pytest.raises(ValueError, match="has no tasks/ folder"):
        assemblyworld(suite=str(tmp_path / "scoring"))


def test_the_task_has_one_sample_per_task_and_the_budget_sets_its_time_limit(suite, tmp_path):
    task = assemblyworld(suite=str(suite), tasks=[NONE_TASK], budget_minutes=2, runs=str(tmp_path / "runs"))
    assert [s.id for s in task.dataset] == [NONE_TASK]
    assert task.time_limit == 7 * 60  # the budget plus 5 minutes, as aw-run gives a harness
    assert task.dataset[0].metadata["source"] == "fantastic_breaks" and "targets" not in str(task.dataset[0].metadata)
    assert task_filter(" a, b ,") == ["a", "b"] and task_filter(None) is None


def test_runs_are_laid_out_as_aw_score_reads_them():
    runs = Path("/r")
    assert run_dir_for(runs, "gpt", "t1", 1, 1) == runs / "gpt" / "t1"
    assert run_dir_for(runs, "gpt", "t1", 2, 3) == runs / "gpt" / "attempt-2" / "t1"
    assert system_label("org/model-7b") == "org-model-7b" and system_label("..") == "model"


def test_refused_calls_are_those_inspect_answered_itself():
    messages = [
        ChatMessageUser(content="go"),
        ChatMessageAssistant(content=""),
        ChatMessageTool(
            content="", function="translate_objects", error=ToolCallError("parsing", "'far' is not of type 'array'")
        ),
        ChatMessageTool(content="", function="rotate_objects", error=ToolCallError("unknown", "ids: at least 1 item")),
        ChatMessageTool(content="ok", function="get_state"),
    ]
    assert refused_calls(messages) == [{"tool": "translate_objects", "error": "'far' is not of type 'array'"}]


def test_tokens_count_cache_reads_and_writes_as_input_and_cost_only_when_all_priced():
    a = ModelUsage(
        input_tokens=100, output_tokens=10, input_tokens_cache_read=50, input_tokens_cache_write=5, total_cost=0.25
    )
    b = ModelUsage(input_tokens=10, output_tokens=1)
    tokens, cost = token_usage({"m1": a})
    assert (tokens.input, tokens.output, tokens.total, cost) == (155, 10, 165, 0.25)
    tokens, cost = token_usage({"m1": a, "m2": b})
    assert (tokens.input, tokens.total, cost) == (165, 176, None)
    assert token_usage({}) == (None, None)


def test_the_default_suite_is_reused_from_the_cache(tmp_path, suite, capsys):
    cached = tmp_path / DEFAULT_SUITE_NAME
    cached.mkdir()
    (cached / "manifest.json").write_bytes((suite / "manifest.json").read_bytes())
    assert default_suite(tmp_path) == cached
    assert capsys.readouterr().err == ""  # nothing built, nothing said
