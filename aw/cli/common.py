"""The one CLI language of every ``aw-*`` command.

- Help is plain text (no markup); every flag has a help line.
- ``--overwrite`` is the only replace-existing flag (``--force`` / ``--fresh`` are accepted,
  hidden, for old scripts).
- ``--jobs J`` defaults to the number of CPU cores this process may use (:func:`aw.cores.available_cores`).
- Exit status 2: a usage error (bad flag or value, a path that cannot be used), said before any
  work starts; 1: a failure while working (including a run in which every episode failed);
  130: interrupted. Errors are one line, ``PROG: error: ...``, never a traceback.
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path

from aw.cores import available_cores

__all__ = [
    "EXIT_OK",
    "EXIT_FAILURE",
    "EXIT_USAGE",
    "EXIT_INTERRUPTED",
    "CliError",
    "UsageError",
    "new_parser",
    "add_commands",
    "add_overwrite",
    "add_hidden_alias",
    "add_jobs",
    "add_no_progress",
    "positive_int",
    "positive_float",
    "nonnegative_float",
    "check_out_dir",
    "check_in_dir",
    "run_main",
    "plural",
]

EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


class CliError(Exception):
    """A failure while working, reported in one line (exit status 1)."""


class UsageError(Exception):
    """A wrong argument, reported in one line before any work starts (exit status 2)."""


class _Formatter(argparse.HelpFormatter):
    """Plain-text descriptions and epilogs: paragraphs (separated by blank lines) are wrapped,
    a paragraph with an indented line (a usage example, a list) is printed as written."""

    def __init__(self, prog: str) -> None:
        super().__init__(prog, max_help_position=32, width=min(100, _terminal_width()))

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        paragraphs = textwrap.dedent(text).strip("\n").split("\n\n")
        out = []
        for para in paragraphs:
            lines = para.split("\n")
            if any(line[:1].isspace() for line in lines):
                out.append("\n".join(indent + line for line in lines))
            else:
                out.append(textwrap.fill(" ".join(lines), width, initial_indent=indent, subsequent_indent=indent))
        return "\n\n".join(out)


def _terminal_width() -> int:
    try:
        return os.get_terminal_size().columns
    except OSError:
        return 100


def new_parser(prog: str, description: str, epilog: str | None = None) -> argparse.ArgumentParser:
    """A parser that prints plain-text help and exits 2 on a usage error."""
    return argparse.ArgumentParser(prog=prog, description=description, epilog=epilog, formatter_class=_Formatter)


def add_commands(p: argparse.ArgumentParser) -> argparse._SubParsersAction:
    """Subcommands (``args.command``, required) whose parsers speak the same plain help."""
    return p.add_subparsers(
        dest="command",
        metavar="COMMAND",
        required=True,
        help="one of:",
        parser_class=functools.partial(argparse.ArgumentParser, formatter_class=_Formatter),
    )


def add_hidden_alias(p: argparse.ArgumentParser, *names: str, dest: str, **kwargs) -> None:
    """Old flag ``names`` still accepted for ``dest``, without a line in ``--help``."""
    p.add_argument(*names, dest=dest, default=argparse.SUPPRESS, help=argparse.SUPPRESS, **kwargs)


def plural(n: int, noun: str, nouns: str | None = None) -> str:
    """``"1 task"``, ``"3 tasks"``: a count with its noun in the right number (``nouns``: an
    irregular plural)."""
    return f"{n:,} {noun if n == 1 else (nouns or noun + 's')}"


def add_overwrite(p: argparse.ArgumentParser, what: str) -> None:
    """``--overwrite`` (``args.overwrite``): replace ``what``; ``--force``/``--fresh`` are hidden aliases."""
    p.add_argument("--overwrite", action="store_true", help=f"replace {what}")
    add_hidden_alias(p, "--force", "--fresh", dest="overwrite", action="store_true")


def positive_int(name: str) -> Callable[[str], int]:
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be an integer, got {text!r}") from None
        if v < 1:
            raise argparse.ArgumentTypeError(f"{name} must be >= 1, got {v}")
        return v

    return parse


def _float_checked(name: str, ok: Callable[[float], bool], rule: str) -> Callable[[str], float]:
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if not (v == v and v != float("inf") and ok(v)):
            raise argparse.ArgumentTypeError(f"{name} must be {rule}, got {text}")
        return v

    return parse


def positive_float(name: str) -> Callable[[str], float]:
    return _float_checked(name, lambda v: v > 0, "a finite number > 0")


def nonnegative_float(name: str) -> Callable[[str], float]:
    return _float_checked(name, lambda v: v >= 0, "a finite number >= 0")


def add_jobs(p: argparse.ArgumentParser, what: str) -> None:
    """``--jobs J`` (``args.jobs``, an int >= 1): ``what`` in parallel, default the core count."""
    p.add_argument(
        "--jobs",
        type=positive_int("--jobs"),
        default=available_cores(),
        metavar="J",
        help=f"{what} in parallel (default: the number of CPU cores, here {available_cores()})",
    )


def add_no_progress(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress display (on a non-terminal it is a line every few seconds)",
    )


def check_out_dir(path: str | os.PathLike, flag: str = "--out") -> Path:
    """``path`` usable as an output directory: absent (its nearest existing parent writable) or a
    writable directory. Raises :class:`UsageError` naming ``flag`` otherwise."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise UsageError(f"{flag} {p}: exists and is not a directory")
    probe = p
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        raise UsageError(f"{flag} {p}: {probe} is a file, not a directory")
    if probe.exists() and not os.access(probe, os.W_OK | os.X_OK):
        raise UsageError(f"{flag} {p}: {probe} is not writable")
    return p


def check_in_dir(path: str | os.PathLike, what: str) -> Path:
    """``path`` an existing directory; :class:`UsageError` naming ``what`` otherwise."""
    p = Path(path)
    if not p.exists():
        raise UsageError(f"{what} {p}: no such directory")
    if not p.is_dir():
        raise UsageError(f"{what} {p}: not a directory")
    return p


def run_main(prog: str, body: Callable[[], int]) -> int:
    """Run a command's ``body``, turning expected errors into one line and an exit status."""
    try:
        return body()
    except UsageError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except CliError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except (FileNotFoundError, NotADirectoryError, IsADirectoryError, PermissionError, FileExistsError) as exc:
        # A path mistake discovered while working: the OS message names the file.
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        print(f"{prog}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print(f"\n{prog}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except OSError as exc:  # e.g. a full disk (ENOSPC) or a file too large: one line, never a traceback
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        print(f"{prog}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_FAILURE
