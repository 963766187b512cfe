"""trajectory.jsonl: writer, reader, checkpoints, and every malformed or truncated file."""

import json

import pytest

from aw.formats import (
    FormatError,
    TrajectoryCall,
    TrajectoryEnd,
    TrajectoryHeader,
    TrajectoryWriter,
    read_trajectory,
)
from aw.formats.trajectory import CameraState

IDS = ["p01", "p02"]
I7 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]


def pose(x):
    return [x, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]


def header():
    return TrajectoryHeader(
        task_id="demo-0001",
        system="test",
        started_at="2026-01-01T00:00:00.000Z",
        part_ids=IDS,
        initial_poses={"p01": I7, "p02": I7},
        camera=CameraState(target=[0, 0, 0], yaw=-60, pitch=35, distance=3),
    )


CALLS = [
    TrajectoryCall(seq=1, t=0.0, tool="start_episode", ok=True),
    TrajectoryCall(
        seq=2,
        t=1.5,
        tool="translate_objects",
        args={"ids": ["p01"], "delta": [0.5, 0, 0]},
        ok=True,
        changed=["p01"],
        poses={"p01": pose(0.5), "p02": I7},
    ),
    TrajectoryCall(
        seq=3,
        t=2.0,
        tool="translate_objects",
        args={"ids": ["zz"], "delta": [1, 0, 0]},
        ok=False,
        error="unknown id 'zz'",
    ),
    TrajectoryCall(
        seq=5, t=3.25, tool="capture_scene", args={"note": "caf\u00e9"}, ok=True, image="captures/000005.png"
    ),
    TrajectoryCall(
        seq=6,
        t=4.0,
        tool="set_object_pose",
        args={"id": "p02", "position": [0, 1, 0]},
        ok=True,
        changed=["p02"],
        poses={"p01": pose(0.5), "p02": [0, 1, 0, 1, 0, 0, 0]},
    ),
]
END = TrajectoryEnd(reason="finished", t=5.0, message="done", poses={"p01": pose(0.5), "p02": [0, 1, 0, 1, 0, 0, 0]})


@pytest.fixture
def traj_path(tmp_path):
    path = tmp_path / "run" / "trajectory.jsonl"
    w = TrajectoryWriter(path, header())
    for c in CALLS:
        w.call(c)
    w.end(END)
    assert w.closed
    return path


def test_round_trip_and_checkpoints(traj_path):
    t = read_trajectory(traj_path)
    assert t.header == header()
    assert t.calls == CALLS and t.end == END
    assert not t.truncated and t.problems == []
    cps = t.checkpoints()
    assert [c.seq for c in cps] == [0, 2, 6]
    assert cps[0].t == 0.0 and cps[0].poses == {"p01": I7, "p02": I7}
    assert cps[1].poses["p01"] == pose(0.5) and cps[2].t == 4.0
    assert t.final_poses() == END.poses
    # One JSON object per line, no nulls written for absent fields.
    lines = traj_path.read_text(encoding="utf-8").splitlines()
    assert len(lines) == 1 + len(CALLS) + 1
    assert [json.loads(x)["type"] for x in lines] == ["header"] + ["call"] * len(CALLS) + ["end"]
    assert "null" not in traj_path.read_text()


def test_writer_flushes_each_line_and_refuses_reuse(tmp_path, traj_path):
    path = tmp_path / "live.jsonl"
    w = TrajectoryWriter(path, header())
    w.call(CALLS[0])
    # Readable while the episode runs: no end record yet.
    t = read_trajectory(path)
    assert len(t.calls) == 1 and t.end is None and t.truncated
    assert "no end record" in t.problems[0]
    assert t.final_poses() == {"p01": I7, "p02": I7}
    w.close()
    w.close()  # idempotent
    with pytest.raises(RuntimeError):
        w.call(CALLS[1])
    # A second episode must not be appended to an existing recording.
    with pytest.raises(FormatError, match="already holds a recording"):
        TrajectoryWriter(traj_path, header())


def test_last_line_cut_mid_write_keeps_every_complete_line(traj_path):
    data = traj_path.read_bytes()
    last_start = data.rstrip(b"\n").rfind(b"\n") + 1
    # Cut the end record at every byte: all calls survive, the cut line is dropped.
    for cut in range(last_start, len(data) - 1):
        traj_path.write_bytes(data[:cut])
        t = read_trajectory(traj_path)
        assert t.calls == CALLS, cut
        assert t.end is None and t.truncated
        if cut > last_start:
            assert "cut mid-write" in t.problems[0]
    # Only the newline missing: the record is complete and kept.
    traj_path.write_bytes(data[:-1])
    assert read_trajectory(traj_path).end == END


def test_cut_inside_a_multibyte_character(traj_path):
    lines = traj_path.read_bytes().splitlines(keepends=True)
    capture = 1 + 3  # the capture_scene call holds "café"
    cut_line = lines[capture][: lines[capture].index("\u00e9".encode()) + 1]
    traj_path.write_bytes(b"".join(lines[:capture]) + cut_line)
    t = read_trajectory(traj_path)
    assert [c.seq for c in t.calls] == [1, 2, 3] and t.truncated


def test_header_cut_or_empty(tmp_path, traj_path):
    data = traj_path.read_bytes()
    traj_path.write_bytes(data[:40])
    with pytest.raises(FormatError, match="truncated before the header"):
        read_trajectory(traj_path)
    traj_path.write_bytes(b"")
    with pytest.raises(FormatError, match="empty or truncated"):
        read_trajectory(traj_path)
    with pytest.raises(FormatError, match="file not found"):
        read_trajectory(tmp_path / "nope.jsonl")
    with pytest.raises(FormatError, match="is a directory"):
        read_trajectory(tmp_path)


def replace_line(path, index, text):
    lines = path.read_bytes().split(b"\n")
    lines[index] = text.encode() if isinstance(text, str) else text
    path.write_bytes(b"\n".join(lines))


def edit_line(path, index, mutate):
    lines = path.read_bytes().split(b"\n")
    obj = json.loads(lines[index])
    mutate(obj)
    lines[index] = json.dumps(obj).encode()
    path.write_bytes(b"\n".join(lines))


def expect(path, problem):
    with pytest.raises(FormatError) as info:
        read_trajectory(path)
    assert info.value.path == path
    assert problem in info.value.problem, info.value.problem


def test_corrupt_middle_line_names_file_and_line(traj_path):
    replace_line(traj_path, 2, '{"type": "call", "seq": 2,')
    expect(traj_path, "line 3: not valid JSON")


@pytest.mark.parametrize(
    "index,mutate,problem",
    [
        (2, lambda o: o.update(seq=1), "line 3: sequence number 1 is not increasing"),
        (2, lambda o: o.update(seq=0), "line 3: seq"),
        (2, lambda o: o.pop("ok"), "line 3: ok"),
        (2, lambda o: o.update(ok="yes"), "line 3: ok"),
        (2, lambda o: o.update(type="cal"), "line 3: unknown record type 'cal'"),
        (2, lambda o: o.update(type=["call"]), "line 3: not a trajectory record"),
        (2, lambda o: o.pop("type"), "line 3: not a trajectory record"),
        (2, lambda o: o.update(poses={"p01": I7}), "line 3: poses do not match"),
        (2, lambda o: o.update(poses={"p01": I7, "p02": I7, "p03": I7}), "unknown ['p03']"),
        (2, lambda o: o.update(poses={"p01": [0, 0, 0, 0, 0, 0, 0], "p02": I7}), "line 3: poses.p01"),
        (2, lambda o: o.pop("poses"), "line 3: parts changed but the poses after the call are missing"),
        (2, lambda o: o.update(changed=["p09"]), "line 3: changed names unknown part ids ['p09']"),
        (2, lambda o: o.update(extra=1), "line 3: extra"),
        (0, lambda o: o.update(format_version=2), "line 1: unsupported format_version 2"),
        (0, lambda o: o.update(part_ids=["p01", "p01"]), "line 1: duplicate part ids"),
        (0, lambda o: o.update(initial_poses={"p01": I7}), "line 1: poses do not match"),
        (0, lambda o: o.update(type="call"), "line 1"),
        (6, lambda o: o.update(reason="bored"), "line 7: reason"),
        (6, lambda o: o.update(poses={"p02": I7}), "line 7: poses do not match"),
    ],
)
def test_invalid_records(traj_path, index, mutate, problem):
    edit_line(traj_path, index, mutate)
    expect(traj_path, problem)


def test_structure_errors(traj_path):
    data = traj_path.read_bytes()
    lines = data.split(b"\n")
    # A record after the end record.
    traj_path.write_bytes(data + lines[1] + b"\n")
    expect(traj_path, "line 8: record after the end record")
    # A second header.
    traj_path.write_bytes(b"\n".join([lines[0], lines[1], lines[0]] + lines[2:]))
    expect(traj_path, "line 3: a second header")
    # First record not a header.
    traj_path.write_bytes(b"\n".join(lines[1:]))
    expect(traj_path, "line 1: the first record must be the header")
    # A JSON value that is not an object.
    traj_path.write_bytes(b"\n".join([lines[0], b"[1, 2]"] + lines[1:]))
    expect(traj_path, "line 2: not a trajectory record")
    # A duplicate key inside a record.
    traj_path.write_bytes(b"\n".join([lines[0], lines[1].replace(b'"seq":1', b'"seq":1,"seq":9')] + lines[2:]))
    expect(traj_path, "line 2: duplicate key 'seq'")


def test_blank_lines_are_ignored(traj_path):
    lines = traj_path.read_bytes().split(b"\n")
    traj_path.write_bytes(b"\n".join(lines[:3] + [b"", b"   "] + lines[3:]))
    t = read_trajectory(traj_path)
    assert t.calls == CALLS and t.end == END
