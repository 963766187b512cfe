"""Episode archives are checked member by member (names, types, sizes, hashes) before use."""

from __future__ import annotations

import hashlib
import json
import stat
import zipfile

import numpy as np
import pytest

from aw.formats import FormatError
from aw.official.archive import check_member_name, read_archive

from official_fixtures import episode_members, episode_poses, write_archive

IDS = ["p01", "p02"]
SIZES = [(0.1, 0.05, 0.02), (0.05, 0.05, 0.05)]


def _members():
    targets = np.array([[0.1, 0.2, 0.3, 1, 0, 0, 0], [0.0, -0.2, 0.1, 0, 1, 0, 0]], float)
    return episode_members(IDS, SIZES, episode_poses(targets, 4))


def test_valid_archive(tmp_path):
    arc = write_archive(tmp_path / "final.episode.zip", _members(), {"sample_id": "s"})
    contents = read_archive(arc)
    assert contents.manifest["sample_id"] == "s"
    assert set(contents.files) == {"frames.jsonl", "frames.bin", "calls.jsonl", "events.jsonl", "world/model.xml"}


@pytest.mark.parametrize("name, why", [
    ("/etc/passwd", "absolute"), ("C:/x", "absolute"), ("../x", "'..'"), ("world/../../x", "'..'"),
    ("a\\b", "backslash"), ("a//b", "empty"), ("./a", "'.'"), ("", "empty"),
])
def test_member_names(name, why):
    assert why in check_member_name(name)


def test_good_names():
    assert check_member_name("world/meshes/a.obj") is None and check_member_name("frames.bin") is None


@pytest.mark.parametrize("bad", ["/abs.txt", "../escape.txt", "world/../../escape.txt"])
def test_bad_member_rejected_before_reading(tmp_path, bad):
    m = _members()
    arc = write_archive(tmp_path / "e.zip", m, {"sample_id": "s"}, extra_members={bad: b"x"})
    with pytest.raises(FormatError, match="member .*(absolute|'\\.\\.')") as exc:
        read_archive(arc)
    assert str(arc) in str(exc.value)


def test_hash_mismatch_and_listing(tmp_path):
    m = _members()
    arc = write_archive(tmp_path / "a.zip", m, {"sample_id": "s"}, hash_overrides={"frames.bin": "0" * 64})
    with pytest.raises(FormatError, match="member 'frames.bin': sha256 .* does not match manifest.json"):
        read_archive(arc)
    arc = write_archive(tmp_path / "b.zip", m, {"sample_id": "s"}, unlisted=("calls.jsonl",))
    with pytest.raises(FormatError, match=r"members not listed in manifest.json: \['calls.jsonl'\]"):
        read_archive(arc)
    arc = write_archive(tmp_path / "c.zip", m, {"sample_id": "s"}, hash_overrides={"extra.bin": "a" * 64})
    with pytest.raises(FormatError, match=r"lists files the archive lacks: \['extra.bin'\]"):
        read_archive(arc)
    m2 = dict(m)
    del m2["events.jsonl"]
    arc = write_archive(tmp_path / "d.zip", m2, {"sample_id": "s"})
    with pytest.raises(FormatError, match=r"members missing: \['events.jsonl'\]"):
        read_archive(arc)
    arc = write_archive(tmp_path / "e.zip", m, {"sample_id": "s"}, hash_overrides={"frames.bin": "xyz"})
    with pytest.raises(FormatError, match=r"files\['frames.bin'\]: sha256 missing or not 64 hex digits"):
        read_archive(arc)


def test_size_mismatch_symlink_duplicate_and_junk(tmp_path):
    m = _members()
    arc = tmp_path / "s.zip"
    files = {n: {"sha256": hashlib.sha256(d).hexdigest(), "size": len(d) + 1} for n, d in m.items()}
    with zipfile.ZipFile(arc, "w") as zf:
        zf.writestr("manifest.json", json.dumps({"sample_id": "s", "files": files}))
        for n, d in m.items():
            zf.writestr(n, d)
    with pytest.raises(FormatError, match="bytes, manifest.json says"):
        read_archive(arc)
    link = tmp_path / "l.zip"
    with zipfile.ZipFile(link, "w") as zf:
        zf.writestr("manifest.json", "{}")
        info = zipfile.ZipInfo("frames.bin")
        info.external_attr = (stat.S_IFLNK | 0o777) << 16
        zf.writestr(info, "/etc/passwd")
    with pytest.raises(FormatError, match="member 'frames.bin': not a regular file or folder"):
        read_archive(link)
    dup = tmp_path / "dup.zip"
    with zipfile.ZipFile(dup, "w") as zf:
        zf.writestr("manifest.json", "{}")
        zf.writestr("frames.bin", b"a")
        with pytest.warns(UserWarning):
            zf.writestr("frames.bin", b"b")
    with pytest.raises(FormatError, match="appears twice"):
        read_archive(dup)
    junk = tmp_path / "junk.zip"
    junk.write_bytes(b"not a zip")
    with pytest.raises(FormatError, match="not a zip archive"):
        read_archive(junk)
    with pytest.raises(FormatError, match="episode archive not found"):
        read_archive(tmp_path / "missing.zip")
