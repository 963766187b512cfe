"""Property-based tests of the recording readers: ``read_trajectory``, ``read_final`` and the
scorer's ``read_episode`` either return a valid reading or raise their one documented error,
whatever the bytes; and what the writer writes reads back unchanged."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aw.formats import (
    FinalState,
    FormatError,
    TrajectoryCall,
    TrajectoryEnd,
    TrajectoryHeader,
    TrajectoryWriter,
    read_final,
    read_trajectory,
    write_final,
)
from aw_eval.study.episode import RunUnreadable, read_episode

IDS = ["p01", "p02"]
I7 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
# Bounded and derandomized for CI (same examples every run); benchmarks/fuzz_server.py explores further.
FAST = settings(
    max_examples=25, deadline=None, derandomize=True, database=None, suppress_health_check=[HealthCheck.too_slow]
)

json_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**30), 10**30),
    st.floats(allow_nan=False, allow_infinity=False),
    st.text(max_size=12),
)
json_values = st.recursive(
    json_scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)),
    max_leaves=12,
)
finite = st.floats(-1e3, 1e3, allow_nan=False)
poses = st.lists(finite, min_size=3, max_size=3).flatmap(
    lambda p: (
        st.lists(st.floats(-1, 1, allow_nan=False), min_size=4, max_size=4)
        .filter(lambda q: sum(v * v for v in q) > 1e-6)
        .map(lambda q: p + q)
    )
)


def _header() -> TrajectoryHeader:
    return TrajectoryHeader(
        task_id="t1", system="s", started_at="2026-01-01T00:00:00Z", part_ids=IDS, initial_poses={p: I7 for p in IDS}
    )


def _valid_lines() -> list[dict]:
    return [
        _header().model_dump(mode="json", exclude_none=True),
        {"type": "call", "seq": 1, "server_t": 0.5, "tool": "get_state", "ok": True, "episode_active": False},
        {
            "type": "call",
            "seq": 2,
            "t": 0.0,
            "server_t": 1.0,
            "tool": "translate_objects",
            "ok": True,
            "changed": ["p01"],
            "poses": {"p01": [1, 0, 0, 1, 0, 0, 0], "p02": I7},
        },
        {
            "type": "end",
            "reason": "finished",
            "t": 2.0,
            "server_t": 3.0,
            "poses": {"p01": [1, 0, 0, 1, 0, 0, 0], "p02": I7},
        },
    ]


def _scratch():
    return tempfile.TemporaryDirectory(prefix="aw-prop-")


def _read_all(run: Path) -> None:
    """Every reader of a run directory: returns or raises its documented error, nothing else."""
    try:
        traj = read_trajectory(run / "trajectory.jsonl")
    except FormatError as exc:
        assert str(run / "trajectory.jsonl") in str(exc)  # the error names the file
    else:
        assert [c.seq for c in traj.calls] == sorted({c.seq for c in traj.calls})
        assert all(isinstance(c.t, float) for c in traj.calls)
        assert traj.final_poses().keys() == set(traj.header.part_ids)
    try:
        read_final(run / "final.json")
    except FormatError as exc:
        assert "final.json" in str(exc)
    centroids = np.zeros((2, 3))
    try:
        ep = read_episode(run, "t1", IDS, IDS, centroids, 1.0)
    except RunUnreadable:
        return
    assert ep.final_poses.shape == (2, 7) and np.isfinite(ep.final_poses).all()
    assert len(ep.call_t) == len(ep.call_kind) == len(ep.call_ok)


@FAST
@given(data=st.binary(max_size=400))
def test_arbitrary_bytes(data):
    with _scratch() as d:
        run = Path(d)
        (run / "trajectory.jsonl").write_bytes(data)
        (run / "final.json").write_bytes(data)
        _read_all(run)


@FAST
@given(
    line=st.integers(0, 3),
    key=st.sampled_from(
        [
            "type",
            "seq",
            "t",
            "server_t",
            "tool",
            "ok",
            "poses",
            "changed",
            "part_ids",
            "initial_poses",
            "reason",
            "extra",
        ]
    ),
    value=json_values,
    cut=st.integers(0, 2000),
)
def test_mutated_recordings(line, key, value, cut):
    """A valid recording with one field of one line replaced by any JSON value, optionally cut."""
    lines = _valid_lines()
    lines[line][key] = value
    text = "".join(json.dumps(rec) + "\n" for rec in lines)
    final = {
        "format": "assemblyworld.final",
        "format_version": 1,
        "task_id": "t1",
        "reason": "finished",
        "poses": {"p01": [1, 0, 0, 1, 0, 0, 0], "p02": I7},
    }
    if key in final:
        final[key] = value
    with _scratch() as d:
        run = Path(d)
        (run / "trajectory.jsonl").write_text(text[: cut if cut < len(text) else len(text)])
        (run / "final.json").write_text(json.dumps(final))
        _read_all(run)


@FAST
@given(
    steps=st.lists(
        st.tuples(
            st.sampled_from(["get_state", "translate_objects", "start_episode"]),
            st.floats(0, 10, allow_nan=False),
            poses,
        ),
        min_size=0,
        max_size=8,
    ),
    end=st.sampled_from([None, "finished", "timeout", "error", "disconnect", "interrupted"]),
)
def test_written_recordings_read_back(steps, end):
    """What the writer writes, the reader reads back: calls, times, checkpoints, final state."""
    with _scratch() as d:
        _write_and_read(Path(d), steps, end)


def _write_and_read(run: Path, steps, end) -> None:
    w = TrajectoryWriter(run / "trajectory.jsonl", _header())
    state = {p: I7 for p in IDS}
    started, server_t, written = None, 0.0, []
    for seq, (tool, dt, pose) in enumerate(steps, start=1):
        server_t += dt
        if tool != "get_state" and started is None:
            started = server_t
        changed = ["p01"] if tool == "translate_objects" else []
        if changed:
            state = {**state, "p01": pose}
        t = None if started is None else server_t - started
        rec = TrajectoryCall(
            seq=seq,
            t=t,
            server_t=server_t,
            tool=tool,
            ok=True,
            changed=changed,
            poses=dict(state) if changed else None,
            episode_active=started is not None,
        )
        w.call(rec)
        written.append(rec)
    if end is not None:
        w.end(
            TrajectoryEnd(reason=end, t=None if started is None else server_t - started, server_t=server_t, poses=state)
        )
        write_final(run / "final.json", FinalState(task_id="t1", reason=end, poses=state))
    else:
        w.close()
    traj = read_trajectory(run / "trajectory.jsonl")
    assert [c.tool for c in traj.calls] == [c.tool for c in written]
    # times are real: increasing with the server clock, negative exactly before the clock start
    ts = [c.t for c in traj.calls]
    assert ts == sorted(ts)
    for c, rec in zip(traj.calls, written, strict=True):
        if rec.t is None:
            assert c.t <= 0 and c.t == round(c.server_t - (started if started is not None else server_t), 6)
        else:
            assert c.t == rec.t
    assert traj.final_poses() == state
    assert (traj.end is None) == (end is None)
    ep = read_episode(run, "t1", IDS, IDS, np.zeros((2, 3)), 1.0)
    assert np.allclose(ep.final_poses[0, :3], state["p01"][:3])
    assert ep.final_from == ("final.json" if end else "trajectory")
