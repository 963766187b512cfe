"""Safe reading of 3DWebAgent episode archives (``final.episode.zip``).

Nothing in an archive is used before every member has been checked:

1. member names: relative POSIX paths without ``..``, empty or ``.`` components, backslashes,
   drive letters or control characters; no duplicates; no symlinks or other special files;
2. sizes: every member and the total below limits, and no member that inflates more than
   :data:`MAX_RATIO` times (zip bombs);
3. ``manifest.json`` lists every other file with its SHA-256 (``files``: ``{name: {"sha256":
   ..., "size": ...}}`` or a list of ``{"path", "sha256", "size"}``); each is read once and its
   hash (and size, when given) checked; unlisted members and listed-but-absent files are errors.

Errors are :class:`aw.formats.FormatError` naming the archive and the member.
"""

from __future__ import annotations

import hashlib
import json
import re
import stat
import zipfile
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

from aw.formats import FormatError

__all__ = ["MAX_MEMBER_BYTES", "MAX_TOTAL_BYTES", "MAX_RATIO", "REQUIRED_MEMBERS", "ArchiveContents", "check_member_name", "read_archive"]

MAX_MEMBER_BYTES = 1 << 30
MAX_TOTAL_BYTES = 2 << 30
MAX_RATIO = 1000
REQUIRED_MEMBERS = ("manifest.json", "frames.jsonl", "frames.bin", "calls.jsonl", "events.jsonl", "world/model.xml")
_BAD_CHARS = re.compile(r"[\x00-\x1f\x7f\\]")


@dataclass
class ArchiveContents:
    """The verified members of an archive: ``manifest`` (parsed) and ``files`` (bytes by name)."""

    path: Path
    manifest: dict[str, Any]
    files: dict[str, bytes]

    def text(self, name: str) -> str:
        try:
            return self.files[name].decode("utf-8")
        except KeyError:
            raise FormatError(self.path, f"{name}: member missing") from None
        except UnicodeDecodeError:
            raise FormatError(self.path, f"{name}: not UTF-8 text") from None


def check_member_name(name: str) -> str | None:
    """Why ``name`` is not an acceptable member path, or None when it is."""
    if not name or _BAD_CHARS.search(name):
        return "contains a backslash or control character" if name else "empty name"
    if name.startswith("/") or re.match(r"^[A-Za-z]:", name):
        return "is an absolute path"
    parts = PurePosixPath(name.rstrip("/")).parts if name != "/" else ()
    raw_parts = name.rstrip("/").split("/")
    if ".." in raw_parts:
        return "contains '..'"
    if any(p in ("", ".") for p in raw_parts) or not parts:
        return "contains an empty or '.' path component"
    return None


def _manifest_files(manifest: Any, path: Path) -> dict[str, dict[str, Any]]:
    if not isinstance(manifest, dict):
        raise FormatError(path, "manifest.json: expected a JSON object")
    files = manifest.get("files")
    out: dict[str, dict[str, Any]] = {}
    if isinstance(files, dict):
        items = list(files.items())
    elif isinstance(files, list):
        items = []
        for k, f in enumerate(files):
            if not isinstance(f, dict) or not isinstance(f.get("path", f.get("name")), str):
                raise FormatError(path, f"manifest.json: files[{k}]: expected {{path, sha256}}")
            items.append((f.get("path", f.get("name")), f))
    else:
        raise FormatError(path, "manifest.json: files: missing (every member must be listed with its sha256)")
    for name, info in items:
        if isinstance(info, str):
            info = {"sha256": info}
        if not isinstance(info, dict) or not isinstance(info.get("sha256"), str) or not re.fullmatch(r"[0-9a-fA-F]{64}", info["sha256"]):
            raise FormatError(path, f"manifest.json: files[{name!r}]: sha256 missing or not 64 hex digits")
        why = check_member_name(name)
        if why:
            raise FormatError(path, f"manifest.json: files[{name!r}]: {why}")
        if name in out:
            raise FormatError(path, f"manifest.json: files: {name!r} listed twice")
        out[name] = {"sha256": info["sha256"].lower(), "size": info.get("size", info.get("bytes"))}
    return out


def read_archive(path: str | Path, required: tuple[str, ...] = REQUIRED_MEMBERS) -> ArchiveContents:
    """Check every member of the archive, then return the verified contents."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(path, "episode archive not found")
    try:
        zf = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise FormatError(path, f"not a zip archive ({exc})") from None
    with zf:
        infos = zf.infolist()
        names: dict[str, zipfile.ZipInfo] = {}
        total = 0
        for info in infos:
            why = check_member_name(info.filename)
            if why:
                raise FormatError(path, f"member {info.filename!r}: {why}")
            ftype = stat.S_IFMT(info.external_attr >> 16)  # 0 when the writer recorded no file type
            if ftype and ftype not in (stat.S_IFREG, stat.S_IFDIR):
                raise FormatError(path, f"member {info.filename!r}: not a regular file or folder")
            if info.is_dir():
                continue
            if info.filename in names:
                raise FormatError(path, f"member {info.filename!r}: appears twice")
            if info.file_size > MAX_MEMBER_BYTES:
                raise FormatError(path, f"member {info.filename!r}: {info.file_size} bytes exceeds the limit")
            if info.file_size > MAX_RATIO * max(info.compress_size, 1) and info.file_size > (1 << 20):
                raise FormatError(path, f"member {info.filename!r}: compression ratio too high")
            total += info.file_size
            names[info.filename] = info
        if total > MAX_TOTAL_BYTES:
            raise FormatError(path, f"archive inflates to {total} bytes, over the limit")
        missing = [m for m in required if m not in names]
        if missing:
            raise FormatError(path, f"members missing: {missing}")
        if "manifest.json" not in names:
            raise FormatError(path, "manifest.json: member missing")

        def read(name: str) -> bytes:
            info = names[name]
            with zf.open(info) as fh:
                data = fh.read(MAX_MEMBER_BYTES + 1)
            if len(data) != info.file_size:
                raise FormatError(path, f"member {name!r}: size differs from its zip header")
            return data

        try:
            manifest = json.loads(read("manifest.json").decode("utf-8"))
        except (ValueError, UnicodeDecodeError) as exc:
            raise FormatError(path, f"manifest.json: not valid JSON ({exc})") from None
        listed = _manifest_files(manifest, path)
        unlisted = sorted(set(names) - set(listed) - {"manifest.json"})
        if unlisted:
            raise FormatError(path, f"members not listed in manifest.json: {unlisted}")
        absent = sorted(set(listed) - set(names))
        if absent:
            raise FormatError(path, f"manifest.json lists files the archive lacks: {absent}")
        files: dict[str, bytes] = {}
        for name, info in listed.items():
            try:
                data = read(name)
            except zipfile.BadZipFile as exc:
                raise FormatError(path, f"member {name!r}: corrupt ({exc})") from None
            if info["size"] is not None and info["size"] != len(data):
                raise FormatError(path, f"member {name!r}: {len(data)} bytes, manifest.json says {info['size']}")
            digest = hashlib.sha256(data).hexdigest()
            if digest != info["sha256"]:
                raise FormatError(path, f"member {name!r}: sha256 {digest} does not match manifest.json ({info['sha256']})")
            files[name] = data
    return ArchiveContents(path, manifest, files)
