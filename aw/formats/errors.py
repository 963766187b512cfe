"""The one error type raised by every format reader."""

from __future__ import annotations

from pathlib import Path


class FormatError(ValueError):
    """A file is missing, malformed, truncated or fails validation.

    The message always names the file and the problem.
    """

    def __init__(self, path: str | Path, problem: str):
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")
