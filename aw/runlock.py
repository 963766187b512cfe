"""An exclusive lock on a run directory, held for the life of the process that records into it.

A second server (or runner) pointed at a run directory that a live process is still recording
into must not delete or interleave with that recording, ``--overwrite`` or not. The lock is an
``fcntl.flock`` on ``RUN_DIR/.aw-lock``: the kernel drops it when the holder exits, however it
exits (kill -9 included), so a stale lock file never blocks a later run. The file holds the
holder's pid, host and command line (and still names the last holder after it ended), so that a
refusal can say who holds it.
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
import sys
from pathlib import Path

from aw.formats.io import pid_alive

LOCK_FILE = ".aw-lock"

__all__ = ["LOCK_FILE", "RunDirBusy", "RunDirLock", "holder_of", "kernel_flocks", "live_holder"]


class RunDirBusy(Exception):
    """Another live process holds the run directory's lock."""


def _describe(holder: dict | None) -> str:
    if not holder:
        return "another process"
    cmd = holder.get("command", "")
    cmd = cmd if len(cmd) <= 200 else cmd[:197] + "..."
    return f"pid {holder.get('pid', '?')} on {holder.get('host', '?')} ({cmd})"


def _read_holder(fd: int) -> dict | None:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        data = os.read(fd, 65536)
        holder = json.loads(data.decode("utf-8")) if data else None
        return holder if isinstance(holder, dict) else None
    except (OSError, ValueError):
        return None


class RunDirLock:
    """``RunDirLock(run_dir).acquire()`` or ``with RunDirLock(run_dir):``. Creates ``run_dir``."""

    def __init__(self, run_dir: str | Path, command: str | None = None):
        self.run_dir = Path(run_dir)
        self.path = self.run_dir / LOCK_FILE
        self.command = command if command is not None else " ".join(sys.argv)
        self._fd: int | None = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def acquire(self) -> RunDirLock:
        """Take the lock or raise :class:`RunDirBusy` naming the holder (``OSError`` if the
        directory cannot be created)."""
        if self._fd is not None:
            return self
        self.run_dir.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_holder(fd)
            os.close(fd)
            raise RunDirBusy(
                f"{self.run_dir} is being recorded by {_describe(holder)}; wait for it to end, "
                "or stop it, before reusing this run directory"
            ) from None
        record = {"pid": os.getpid(), "host": socket.gethostname(), "command": self.command}
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(record).encode("utf-8"), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        """Drop the lock (idempotent). The file stays, naming its last holder (removing it could
        race a new holder); only the flock says whether it is held (:func:`holder_of`)."""
        fd, self._fd = self._fd, None
        if fd is not None:
            os.close(fd)  # closing the descriptor releases the flock

    def __enter__(self) -> RunDirLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


def holder_of(run_dir: str | Path) -> str | None:
    """Who holds ``run_dir``'s lock now (a description), or None if nobody does."""
    path = Path(run_dir) / LOCK_FILE
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return _describe(_read_holder(fd))
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


def kernel_flocks() -> frozenset[str] | None:
    """The files the kernel lists as flocked, as ``"<major>:<minor>:<inode>"`` (``/proc/locks``,
    Linux); None where that list cannot be read. Read once for many :func:`live_holder` calls."""
    try:
        with open("/proc/locks", encoding="ascii", errors="replace") as fh:
            rows = fh.read().splitlines()
    except OSError:
        return None
    # "1: FLOCK  ADVISORY  WRITE 1234 fe:00:5439975 0 EOF" (a waiter's row has "->" after the number)
    return frozenset(f for row in rows if "FLOCK" in row for f in row.split() if f.count(":") == 2)


_READ = object()


def live_holder(run_dir: str | Path, flocks: frozenset[str] | None | object = _READ) -> str | None:
    """Who holds ``run_dir``'s lock now, or None, found without touching the lock: unlike
    :func:`holder_of`, whose brief shared lock makes a recorder that starts at that moment refuse
    the directory, this looks the lock file up in the kernel's list of locks (``flocks``, default
    :func:`kernel_flocks` read now); where there is no such list, a holder on this host whose pid
    is alive counts as live. For watchers (``aw-view``)."""
    path = Path(run_dir) / LOCK_FILE
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        holder = _read_holder(fd)
        st = os.fstat(fd)
    finally:
        os.close(fd)
    listed = kernel_flocks() if flocks is _READ else flocks
    if isinstance(listed, frozenset):
        held = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}" in listed
    else:
        pid = holder.get("pid") if holder else None
        held = bool(holder and holder.get("host") == socket.gethostname() and isinstance(pid, int) and pid_alive(pid))
    return _describe(holder) if held else None
