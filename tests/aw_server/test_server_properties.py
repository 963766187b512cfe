"""Property-based tests of every tool through the real MCP client over stdio: whatever the
arguments, a reply comes, an error changes nothing, every call is recorded, nothing hidden leaks;
and valid edits do exactly what they say."""

from __future__ import annotations

import math

import anyio
import pytest
from anyio.from_thread import start_blocking_portal
from aw_server_helpers import result_text, server_params
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcp import Client
from test_server_errors import LeakChecker

from aw_server.tools import TOOL_SPECS

# Bounded and derandomized for CI (same examples every run); benchmarks/fuzz_server.py explores further.
EXAMPLES = settings(
    max_examples=25,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
REPLY_TIMEOUT_S = 120  # far above any call's time: a call that takes longer is a hang
IDS = ["p01", "p02", "p03"]
KNOWN = {s.name for s in TOOL_SPECS}

FIELDS = sorted({name for spec in TOOL_SPECS for name in spec.args.model_fields} | {"extra"})
scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**20), 10**20),
    st.floats(allow_nan=False, allow_infinity=False),
    st.sampled_from(IDS + ["g1", "", "null", "[1, 2, 3]", '["p01"]', "{}", "1e308", "world", "camera"]),
    st.text(max_size=20),
)
values = st.recursive(
    scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=5), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=10,
)
arguments = st.dictionaries(st.sampled_from(FIELDS), values, max_size=4)


class Live:
    """One server for the module, driven from synchronous hypothesis tests through a portal."""

    def __init__(self, portal, client, run_dir, leaks):
        self.portal, self.client, self.run_dir, self.leaks = portal, client, run_dir, leaks
        self.calls = 0

    def call(self, tool: str, args: dict):
        async def go():
            with anyio.fail_after(REPLY_TIMEOUT_S):
                return await self.client.call_tool(tool, args)

        self.calls += tool in KNOWN  # unknown tools are refused by the SDK before the episode
        return self.portal.call(go)

    def state(self) -> dict:
        s = self.call("get_state", {}).structured_content
        return {"poses": s["poses"], "groups": s["groups"], "camera": s["camera"]}

    def recorded(self) -> int:
        return (self.run_dir / "trajectory.jsonl").read_bytes().count(b"\n") - 1  # lines after the header


@pytest.fixture(scope="module")
def live(box_task, tmp_path_factory):
    task_dir, _, targets = box_task
    run = tmp_path_factory.mktemp("properties") / "run"
    with start_blocking_portal() as portal:
        with portal.wrap_async_context_manager(Client(server_params(task_dir, run))) as client:
            yield Live(portal, client, run, LeakChecker(task_dir, targets))


@EXAMPLES
@given(tool=st.sampled_from([s.name for s in TOOL_SPECS] + ["no_such_tool"]), args=arguments)
def test_any_arguments_to_any_tool(live, tool, args):
    before = live.state()
    result = live.call(tool, args)
    live.leaks.check_result(result)
    after = live.state()
    if result.is_error:
        assert after == before, (tool, args, result_text(result))
        assert result_text(result).startswith(("Error executing tool", "Unknown tool")), result_text(result)
    assert live.recorded() == live.calls  # every call, ok or not, is in the trajectory


coords = st.floats(-2.0, 2.0, allow_nan=False)


@EXAMPLES
@given(
    ids=st.lists(st.sampled_from(IDS), min_size=1, max_size=3, unique=True),
    delta=st.lists(coords, min_size=3, max_size=3),
)
def test_valid_translations_move_exactly_the_selection(live, ids, delta):
    before = live.state()["poses"]
    result = live.call("translate_objects", {"ids": ids, "delta": delta})
    after = live.state()["poses"]
    if result.is_error:  # only the scene's coordinate range can refuse a valid call
        assert "beyond" in result_text(result) and after == before
        return
    # "changed" lists the parts whose pose changed (a delta below float resolution changes none)
    assert sorted(result.structured_content["changed"]) == sorted(p for p in ids if after[p] != before[p])
    for pid in IDS:
        moved = [b + (d if pid in ids else 0.0) for b, d in zip(before[pid]["position"], delta, strict=True)]
        assert all(math.isclose(a, m, abs_tol=1e-9) for a, m in zip(after[pid]["position"], moved, strict=True)), pid
        assert after[pid]["quaternion"] == before[pid]["quaternion"]
