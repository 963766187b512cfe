"""TrajectoryFollower: a trajectory read while it is written: complete lines only (a cut last
line is waited for), the reader's rules on every line, a damaged line named on every poll, a
replaced or deleted file read again from its start, memory bounded by the line limit."""

from __future__ import annotations

import os

import pytest

from aw.formats import FormatError, TrajectoryCall, TrajectoryEnd, TrajectoryFollower, TrajectoryHeader, read_trajectory
from aw.formats.trajectory import encode_record

IDS = ["p01", "p02"]
I7 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]


def _lines() -> list[bytes]:
    header = TrajectoryHeader(
        task_id="t", system="s", started_at="2026-01-01T00:00:00Z", part_ids=IDS, initial_poses={p: I7 for p in IDS}
    )
    calls = [
        TrajectoryCall(seq=1, server_t=0.5, tool="list_objects", ok=True),
        TrajectoryCall(seq=2, t=0.0, server_t=1.0, tool="start_episode", ok=True),
        TrajectoryCall(
            seq=3,
            t=1.5,
            server_t=2.5,
            tool="translate_objects",
            args={"ids": ["p01"], "note": "\u00e9\u00e9\u00e9"},
            ok=True,
            changed=["p01"],
            poses={"p01": [0.5, 0, 0, 1, 0, 0, 0], "p02": I7},
        ),
        TrajectoryCall(seq=4, t=2.0, server_t=3.0, tool="capture_scene", ok=True, image="captures/000004.png"),
    ]
    end = TrajectoryEnd(reason="finished", t=3.0, server_t=4.0, poses={"p01": [0.5, 0, 0, 1, 0, 0, 0], "p02": I7})
    return [encode_record(r) + b"\n" for r in (header, *calls, end)]


def test_growing_file_byte_by_byte_gives_what_the_reader_gives(tmp_path):
    path = tmp_path / "trajectory.jsonl"
    data = b"".join(_lines())
    path.write_bytes(b"")
    full = TrajectoryFollower(path)
    summary = TrajectoryFollower(path, keep_calls=False)
    seen = []
    with open(path, "ab") as fh:
        for i in range(len(data)):  # every cut, inside multi-byte characters too
            fh.write(data[i : i + 1])
            fh.flush()
            full.poll()
            summary.poll()
            seen.append(full.n_calls)
            assert full.waiting == (not data[: i + 1].endswith(b"\n"))
    assert seen == sorted(seen) and seen[-1] == 4
    reread = read_trajectory(path)
    traj = full.trajectory
    assert traj.header == reread.header and traj.end == reread.end
    assert [c.seq for c in traj.calls] == [c.seq for c in reread.calls]
    assert traj.calls[0].t is None  # as recorded: before the clock started
    assert summary.trajectory.calls == [] and summary.n_calls == 4 and summary.last_call.seq == 4
    assert summary.last_image == "captures/000004.png" and summary.clock_offset == pytest.approx(1.0)
    assert full.generation == 0 and not full.poll()  # nothing new


def test_a_damaged_line_is_named_on_every_poll_until_the_file_is_replaced(tmp_path):
    path = tmp_path / "trajectory.jsonl"
    lines = _lines()
    path.write_bytes(lines[0] + b'{"type": "call", "seq": 1, "ok": tru\n' + lines[2])
    f = TrajectoryFollower(path)
    for _ in range(2):
        with pytest.raises(FormatError, match=r"trajectory.jsonl: line 2: not valid JSON"):
            f.poll()
    path.write_bytes(lines[0])  # rewritten shorter in place: read again from the start
    assert f.poll() and f.generation == 1 and f.n_calls == 0
    with open(path, "ab") as fh:
        fh.write(lines[1] + lines[1])
    with pytest.raises(FormatError, match=r"line 3: sequence number 1 is not increasing"):
        f.poll()


def test_a_replaced_and_a_deleted_file_start_over(tmp_path):
    path = tmp_path / "trajectory.jsonl"
    lines = _lines()
    path.write_bytes(b"".join(lines[:3]))
    f = TrajectoryFollower(path)
    f.poll()
    assert f.n_calls == 2
    other = tmp_path / "new.jsonl"
    other.write_bytes(b"".join(lines[:5]))  # a longer new recording under the same name (another inode)
    os.replace(other, path)
    assert f.poll() and f.generation == 1 and f.n_calls == 4
    path.unlink()
    with pytest.raises(FormatError, match="file not found"):
        f.poll()
    assert f.trajectory is None and f.n_calls == 0 and f.generation == 2


def test_a_line_beyond_the_limit_is_refused_without_reading_on(tmp_path):
    path = tmp_path / "trajectory.jsonl"
    path.write_bytes(_lines()[0] + b'{"type": "call", "args": "' + b"x" * 5000)  # no newline yet
    f = TrajectoryFollower(path, max_line_bytes=4096)
    with pytest.raises(FormatError, match=r"line 2: longer than 4096 bytes"):
        f.poll()
