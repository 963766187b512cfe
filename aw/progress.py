"""Progress display: a tqdm bar on a terminal, a plain line every few seconds otherwise.

A bar redrawn with carriage returns floods a log file or a CI console; a non-terminal gets
``desc: 12/40 task (30%), 41 s`` lines instead, at most one per ``interval`` seconds plus a
last one when the work ends.
"""

from __future__ import annotations

import sys
import time
from typing import IO, Any

__all__ = ["progress", "LineProgress", "DEFAULT_INTERVAL_S", "LongWorkWarning", "WARN_AFTER_S", "warnings_in_one_line"]

DEFAULT_INTERVAL_S = 15.0
WARN_AFTER_S = 300.0  # an estimate of the work left above this (seconds) is worth a warning


class LongWorkWarning(UserWarning):
    """Per-task work that will take long on this machine (the message gives the estimate)."""


def warnings_in_one_line(prog: str):
    """A ``warnings.showwarning`` that prints ``PROG: warning: MESSAGE`` on stderr: what a
    command-line user reads, without the source line and file name."""

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        print(f"{prog}: warning: {message}", file=sys.stderr, flush=True)

    return show


class LineProgress:
    """The tqdm subset the project uses (``update``, ``set_postfix_str``, ``close``, context
    manager), printed as occasional lines."""

    def __init__(self, total: int, desc: str, unit: str, file: IO[str], interval: float) -> None:
        self.total, self.desc, self.unit, self.file, self.interval = total, desc, unit, file, interval
        self.n = 0
        self.postfix = ""
        self._start = self._last = time.monotonic()
        self._closed = False

    def update(self, n: int = 1) -> None:
        self.n += n
        now = time.monotonic()
        if now - self._last >= self.interval:
            self._last = now
            self._print(now)

    def set_postfix_str(self, text: str, refresh: bool = True) -> None:  # tqdm's signature
        self.postfix = text

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            if self.n:
                self._print(time.monotonic())

    def _print(self, now: float) -> None:
        pct = f" ({100 * self.n / self.total:.0f}%)" if self.total else ""
        extra = f", {self.postfix}" if self.postfix else ""
        print(
            f"{self.desc}: {self.n}/{self.total} {self.unit}{pct}, {now - self._start:.0f} s{extra}",
            file=self.file,
            flush=True,
        )

    def __enter__(self) -> LineProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def progress(
    total: int,
    desc: str,
    unit: str = "it",
    *,
    enabled: bool = True,
    file: IO[str] | None = None,
    interval: float = DEFAULT_INTERVAL_S,
    leave: bool = True,
) -> Any:
    """A progress display of ``total`` steps on ``file`` (default stderr): tqdm when ``file`` is a
    terminal, :class:`LineProgress` when not, a silent tqdm when ``enabled`` is false."""
    from tqdm import tqdm

    out = file if file is not None else sys.stderr
    if not enabled:
        return tqdm(total=total, disable=True)
    isatty = getattr(out, "isatty", None)
    if isatty is not None and isatty():
        return tqdm(total=total, desc=desc, unit=unit, file=out, dynamic_ncols=True, leave=leave)
    return LineProgress(total, desc, unit, out, interval)
