"""Interrupts that stay interrupts: a process-wide record of the signal that asked a command to stop.

A signal handler that raises runs between two Python bytecodes, and that can be inside a call
into compiled code: numba hands the exception back as ``SystemError: CPUDispatcher(<function
_icp>) returned a result with an exception set``, and other libraries (trimesh, SciPy's Qhull,
JAX) can wrap it in their own errors. A broad ``except`` meant for one bad input would then record
the interrupt as that input's failure and go on. So:

- :func:`handled` installs handlers for SIGINT, SIGTERM and SIGHUP that first record the signal
  (:func:`requested`), then raise :class:`Interrupted`;
- code that classifies an exception as an input's failure calls :func:`reraise_if_interrupted`
  first: any exception while an interrupt is recorded is the interrupt;
- :func:`check` before anything lasting is written (a cache entry, an output), and
  :func:`deferred` around a commit that must not stop halfway: a signal inside it is recorded and
  raised when the commit is done;
- a signal that lands in a callback whose exceptions Python cannot raise (a garbage-collector
  callback such as JAX's, a ``__del__``, a weakref callback) is still recorded; inside
  :func:`handled` Python's "Exception ignored in" report of it is not printed, and the command
  stops at its next :func:`check` (or the next exception it classifies);
- :func:`ignore_in_worker` in worker processes: a terminal's Ctrl-C reaches the whole process
  group, and the parent, not each worker, decides (it ends its workers); workers are started
  inside :func:`blocked_for_children`, so that one signalled while it still imports does not
  die with a traceback.

The exit status of an interrupted command is ``128 + signal`` (:attr:`Interrupted.exit_status`):
130 for SIGINT, 143 for SIGTERM, 129 for SIGHUP.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = [
    "SIGNALS",
    "Interrupted",
    "blocked_for_children",
    "check",
    "deferred",
    "handled",
    "ignore_in_worker",
    "is_interrupt",
    "requested",
    "reraise_if_interrupted",
]

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)

_requested: int | None = None  # the first signal received while handled
_defer_depth = 0


class Interrupted(KeyboardInterrupt):
    """The command was asked to stop by signal ``signum`` (a KeyboardInterrupt, so that code which
    already stops cleanly on Ctrl-C stops on it too)."""

    def __init__(self, signum: int = signal.SIGINT) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = int(signum)

    @property
    def exit_status(self) -> int:
        return 128 + self.signum


def requested() -> int | None:
    """The signal that asked this process to stop, or None."""
    return _requested


def _on_signal(signum: int, frame: object) -> None:
    global _requested
    if _requested is None:
        _requested = signum
    if _defer_depth == 0:
        raise Interrupted(signum)


@contextmanager
def handled(signals: tuple[int, ...] = SIGNALS) -> Iterator[None]:
    """Within the block, ``signals`` raise :class:`Interrupted` after recording themselves. Only
    the main thread can install handlers: elsewhere the block runs as it is."""
    global _requested, _defer_depth
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _requested = None
    unraisable_hook = sys.unraisablehook

    def quiet_about_interrupts(unraisable: sys.UnraisableHookArgs) -> None:
        if unraisable.exc_value is None or not _carries_interrupt(unraisable.exc_value):
            unraisable_hook(unraisable)

    sys.unraisablehook = quiet_about_interrupts
    before = {s: signal.signal(s, _on_signal) for s in signals}
    try:
        yield
    finally:
        _defer_depth += 1  # a signal while the handlers are put back is recorded, not raised here
        try:
            for s, h in before.items():
                signal.signal(s, h)
        finally:
            _defer_depth -= 1
        sys.unraisablehook = unraisable_hook
        _requested = None


def is_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` is, or was raised while handling, an interrupt (a KeyboardInterrupt in its
    cause or context chain, as numba's SystemError carries it), or arrived while one is recorded."""
    return _requested is not None or _carries_interrupt(exc)


def _chain(exc: BaseException) -> Iterator[BaseException]:
    """``exc``, then what it was raised from or while handling, each exception once."""
    seen: set[int] = set()
    e: BaseException | None = exc
    while e is not None and id(e) not in seen:
        seen.add(id(e))
        yield e
        e = e.__cause__ or e.__context__


def _carries_interrupt(exc: BaseException) -> bool:
    return any(isinstance(e, KeyboardInterrupt) for e in _chain(exc))


def _signum_of(exc: BaseException) -> int:
    return next((e.signum for e in _chain(exc) if isinstance(e, Interrupted)), _requested or signal.SIGINT)


def reraise_if_interrupted(exc: BaseException) -> None:
    """Raise :class:`Interrupted` (from ``exc``) when ``exc`` is an interrupt in disguise; call it
    first in every ``except`` that would blame an input for ``exc``."""
    if is_interrupt(exc):
        if isinstance(exc, Interrupted):
            raise exc
        raise Interrupted(_signum_of(exc)) from exc


def check() -> None:
    """Raise :class:`Interrupted` if an interrupt is recorded (one that a library swallowed)."""
    if _requested is not None:
        raise Interrupted(_requested)


@contextmanager
def deferred() -> Iterator[None]:
    """A block that a signal does not cut short: one that arrives inside it is raised at its end."""
    global _defer_depth
    _defer_depth += 1
    try:
        yield
    finally:
        _defer_depth -= 1
    if _defer_depth == 0:
        check()


@contextmanager
def blocked_for_children() -> Iterator[None]:
    """Processes started inside the block start with SIGINT and SIGHUP blocked (a blocked mask
    survives fork and exec), until :func:`ignore_in_worker`; this process receives a signal that
    came meanwhile when the block ends."""
    held = {signal.SIGINT, signal.SIGHUP}
    before = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, before)


def ignore_in_worker() -> None:
    """In a worker process: SIGINT and SIGHUP are the parent's to act on (it ends its workers with
    SIGTERM, whose default action stops this process at once)."""
    for s in (signal.SIGINT, signal.SIGHUP):
        signal.signal(s, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGHUP})  # ignored now: pending ones are dropped
