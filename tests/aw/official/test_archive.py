"""Episode archives: layout, records, and a named error for each kind of damage."""

from __future__ import annotations

import hashlib
import json
import stat
import zipfile

import numpy as np
import pytest

from aw.official.archive import ArchiveLimits, archive_bytes, check_member_name, read_archive
from aw.official.errors import (
    ArchiveTooLargeError,
    HashInventoryError,
    InconsistentEpisodeError,
    NotAnArchiveError,
    UnsafeMemberError,
    UnsupportedEpisodeError,
)
from tests.aw.official.builders import PART_IDS, write_active, write_setup


@pytest.fixture
def setup(tmp_path):
    return write_setup(tmp_path / "sample.episode.zip")


@pytest.fixture
def active(setup, tmp_path):
    return write_active(setup, tmp_path / "final.episode.zip")


def members(path):
    with zipfile.ZipFile(path) as zf:
        return {i.filename: zf.read(i) for i in zf.infolist()}


def rezip(path, out, files, rehash=True, extra=()):
    """Write ``files`` (name -> bytes) to ``out``; with ``rehash`` the manifest's hashes are made
    to match, so the damage reaches the record checks."""
    files = dict(files)
    if rehash:
        manifest = json.loads(files["manifest.json"])
        manifest["hashes"] = {n: hashlib.sha256(d).hexdigest() for n, d in files.items() if n != "manifest.json"}
        files["manifest.json"] = json.dumps(manifest).encode()
    with zipfile.ZipFile(out, "w") as zf:
        for name, data in [*files.items(), *extra]:
            zf.writestr(name, data)
    return out


def edit_manifest(files, **changes):
    manifest = json.loads(files["manifest.json"])
    for key, value in changes.items():
        if value is None:
            manifest.pop(key, None)
        else:
            manifest[key] = value
    return {**files, "manifest.json": json.dumps(manifest).encode()}


def edit_jsonl(files, name, edit):
    rows = [json.loads(line) for line in files[name].splitlines()]
    edit(rows)
    return {**files, name: "\n".join(json.dumps(r) for r in rows).encode()}


def test_setup_archive_layout(setup):
    files = members(setup.path)
    assert set(files) == {
        "manifest.json",
        "frames.jsonl",
        "frames.bin",
        "calls.jsonl",
        "events.jsonl",
        "world/model.xml",
        "world/meshes/part-0001.obj",
        "world/meshes/part-0002.obj",
        "world/meshes/part-0003.obj",
    }
    manifest = json.loads(files["manifest.json"])
    assert manifest["hashes"] == {n: hashlib.sha256(d).hexdigest() for n, d in files.items() if n != "manifest.json"}
    assert manifest["lifecycle"] == "setup" and manifest["engine"] == "3.12.0" and manifest["stateSpec"] == 16383
    assert manifest["stateSize"] == 7 + 31 * len(PART_IDS)  # mjSTATE_INTEGRATION of N free bodies under MuJoCo 3.12.0
    assert [o["name"] for o in manifest["objects"]] == ["Part 0", "Part 1", "Part 2"]
    assert files["calls.jsonl"] == files["events.jsonl"] == b""
    assert json.loads(files["frames.jsonl"])["kind"] == "initial"
    assert setup.final_state() is setup.initial and setup.states == []


def test_active_archive_records(active):
    files = members(active.path)
    rows = [json.loads(line) for line in files["frames.jsonl"].split(b"\n")]
    kinds = [r["kind"] for r in rows]
    assert kinds == ["initial", "state", "state", "state"] + ["trace"] * 7
    assert not files["frames.jsonl"].endswith(b"\n")
    assert active.final_state().index == 3 and active.final_state() is active.states[-1]
    assert [c["state_index"] for c in active.calls] == [0, 0, 1, 2, 3, 3, 3]
    assert [c["before_index"] for c in active.calls] == [0, 0, 0, 1, 2, 3, 3]
    assert active.calls[5]["status"] == "error" and active.calls[5]["error_code"] == "invalid_argument"
    assert active.calls[0]["timestamp"] == "2026-01-02T03:04:07.178Z"
    assert [e["kind"] for e in active.events[:2]] == ["request", "complete"] and len(active.events) == 14
    assert active.lifecycle == "active" and active.end is None


def test_writer_is_deterministic(active):
    assert archive_bytes(active) == archive_bytes(read_archive(active.path)) == active.path.read_bytes()


@pytest.mark.parametrize("name", ["../x", "/abs", "a/../b", "a\\b", "C:/x", "a//b", "./a", "a/./b", "a\x00b", "x:y"])
def test_member_names_refused(name):
    assert check_member_name(name) is not None


def test_good_member_names():
    assert check_member_name("world/meshes/part-0001.obj") is None


def test_not_an_archive(tmp_path):
    (tmp_path / "x.episode.zip").write_bytes(b"not a zip")
    with pytest.raises(NotAnArchiveError, match="not a zip"):
        read_archive(tmp_path / "x.episode.zip")
    with pytest.raises(NotAnArchiveError, match="not found"):
        read_archive(tmp_path / "missing.episode.zip")


@pytest.mark.parametrize("bad", ["../evil.txt", "/etc/evil", "world\\evil"])
def test_zip_slip_refused(setup, tmp_path, bad):
    out = rezip(setup.path, tmp_path / "bad.zip", members(setup.path), extra=[(bad, b"x")])
    with pytest.raises(UnsafeMemberError, match="member"):
        read_archive(out)


def test_duplicate_and_symlink_members_refused(setup, tmp_path):
    files = members(setup.path)
    with pytest.warns(UserWarning):  # zipfile itself warns about the duplicate name
        out = rezip(setup.path, tmp_path / "dup.zip", files, extra=[("calls.jsonl", b"")])
    with pytest.raises(UnsafeMemberError, match="twice"):
        read_archive(out)
    link = zipfile.ZipInfo("world/link")
    link.external_attr = (stat.S_IFLNK | 0o777) << 16
    with zipfile.ZipFile(tmp_path / "link.zip", "w") as zf:
        for name, data in files.items():
            zf.writestr(name, data)
        zf.writestr(link, "/etc/passwd")
    with pytest.raises(UnsafeMemberError, match="regular file"):
        read_archive(tmp_path / "link.zip")


def test_oversized_archives_refused(setup, tmp_path):
    with pytest.raises(ArchiveTooLargeError, match="over the limit"):
        read_archive(setup.path, limits=ArchiveLimits(max_member_bytes=100))
    with pytest.raises(ArchiveTooLargeError, match="inflates"):
        read_archive(setup.path, limits=ArchiveLimits(max_total_bytes=1000))
    files = {**members(setup.path), "observations/bomb.png": bytes(8 << 20)}
    with zipfile.ZipFile(tmp_path / "bomb.zip", "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in files.items():
            zf.writestr(name, data)
    with pytest.raises(ArchiveTooLargeError, match="compresses"):
        read_archive(tmp_path / "bomb.zip")


def test_hash_inventory(setup, tmp_path):
    files = members(setup.path)
    changed = rezip(
        setup.path, tmp_path / "a.zip", {**files, "world/model.xml": files["world/model.xml"] + b" "}, rehash=False
    )
    with pytest.raises(HashInventoryError, match="world/model.xml.*SHA-256"):
        read_archive(changed)
    assert read_archive(changed, verify_hashes=False).manifest["id"] == setup.manifest["id"]
    unlisted = rezip(setup.path, tmp_path / "b.zip", files, rehash=False, extra=[("observations/x.png", b"x")])
    with pytest.raises(HashInventoryError, match="not in hashes"):
        read_archive(unlisted)
    absent = rezip(setup.path, tmp_path / "c.zip", {n: d for n, d in files.items() if n != "calls.jsonl"}, rehash=False)
    with pytest.raises(HashInventoryError, match="absent"):
        read_archive(absent)


@pytest.mark.parametrize("key,value", [("format", "other"), ("version", 2), ("engine", "3.3.0"), ("contract", "x")])
def test_unsupported_episodes(setup, tmp_path, key, value):
    out = rezip(setup.path, tmp_path / "u.zip", edit_manifest(members(setup.path), **{key: value}))
    with pytest.raises(UnsupportedEpisodeError, match=key):
        read_archive(out)


def _frames_bin_short(files):
    return {**files, "frames.bin": files["frames.bin"][:-8]}


def _frames_bin_nan(files):
    data = bytearray(files["frames.bin"])
    data[8:16] = np.array([np.nan]).tobytes()
    return {**files, "frames.bin": bytes(data)}


def _state_gap(files):
    return edit_jsonl(files, "frames.jsonl", lambda rows: rows[2].update(index=5))


def _call_beyond_states(files):
    return edit_jsonl(files, "calls.jsonl", lambda rows: rows[-1].update(state_index=9))


def _bad_timestamp(files):
    return edit_jsonl(files, "calls.jsonl", lambda rows: rows[0].update(timestamp="yesterday"))


def _event_kind_unknown(files):
    return edit_jsonl(files, "events.jsonl", lambda rows: rows[0].update(kind="cancel"))


def _trace_outside_call(files):
    return edit_jsonl(files, "frames.jsonl", lambda rows: rows[-1].update(call_id="call-0"))


def _ended_without_end(files):
    return edit_manifest(files, lifecycle="ended")


def _unknown_manifest_key(files):
    return edit_manifest(files, sample_id="x")


def _error_without_message(files):
    return edit_jsonl(files, "calls.jsonl", lambda rows: rows[5].pop("error"))


def _setup_with_history(files):
    return edit_manifest(files, lifecycle="setup")


def _stray_member(files):
    return {**files, "notes.txt": b"hello"}


def _bad_group(files):
    return edit_jsonl(
        files,
        "frames.jsonl",
        lambda rows: rows[1].update(groups=[{"id": "g", "name": "g", "members": ["part-0001", "zzz"]}]),
    )


def _mjb_declared_missing(files):
    return edit_manifest(files, model={"format": "mjb", "path": "model.mjb"})


@pytest.mark.parametrize(
    "damage,message",
    [
        (_frames_bin_short, "frames.bin"),
        (_frames_bin_nan, "non-finite"),
        (_state_gap, "state indices"),
        (_call_beyond_states, "state_index"),
        (_bad_timestamp, "ISO-8601"),
        (_event_kind_unknown, "kind request or complete"),
        (_trace_outside_call, "trace range"),
        (_ended_without_end, "end is present"),
        (_unknown_manifest_key, "unknown keys"),
        (_error_without_message, "error message"),
        (_setup_with_history, "setup"),
        (_stray_member, "notes.txt"),
        (_bad_group, "group member"),
        (_mjb_declared_missing, "model.mjb"),
    ],
)
def test_inconsistent_episodes(active, tmp_path, damage, message):
    out = rezip(active.path, tmp_path / "bad.zip", damage(members(active.path)))
    with pytest.raises(InconsistentEpisodeError, match=message) as info:
        read_archive(out)
    assert str(out) in str(info.value)


def _drop_events_of(call_id):
    return lambda rows: rows.__setitem__(slice(None), [r for r in rows if r["call_id"] != call_id])


@pytest.mark.parametrize(
    "edit",
    [
        _drop_events_of("call-6"),  # the last call has none (cancelled at export)
        lambda rows: rows.pop(),  # request only
        lambda rows: rows.reverse(),  # complete before request, indices out of order
        lambda rows: rows.append({**rows[0], "index": 99, "call_id": "call-77"}),  # a call the archive lacks
    ],
)
def test_events_are_checked_as_the_official_scorer_checks_them(active, tmp_path, edit):
    """assembly-world-bench ``episode_io.py`` applies only the episode schema to events, so
    no sequence of schema-valid events makes an episode unreadable."""
    out = rezip(active.path, tmp_path / "events.zip", edit_jsonl(members(active.path), "events.jsonl", edit))
    assert read_archive(out).final_state().index == 3


def test_the_json_members_are_bounded_before_inflating(active):
    """The parsed size is bounded by the JSON text (zip headers), not only by each compressed member."""
    text = sum(len(d) for n, d in members(active.path).items() if n.endswith((".json", ".jsonl")))
    assert read_archive(active.path, limits=ArchiveLimits(max_json_bytes=text)).calls
    with pytest.raises(
        ArchiveTooLargeError, match=f"the JSON members inflate to {text} bytes, over the limit of {text - 1}"
    ):
        read_archive(active.path, limits=ArchiveLimits(max_json_bytes=text - 1))
