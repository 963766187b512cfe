"""A signal that lands where Python cannot raise (a garbage-collector callback, as JAX registers
one) is recorded without Python's "Exception ignored" report, and stops the command at its next
check; other exceptions raised there are reported as before."""

from __future__ import annotations

import gc
import os
import signal
import sys

import pytest

from aw import interrupts


class _Callback:
    """A gc callback that runs ``action`` once, at the start of the next collection."""

    def __init__(self, action) -> None:
        self.action = action
        self.done = False

    def __call__(self, phase: str, info: dict) -> None:
        if phase == "start" and not self.done:
            self.done = True
            self.action()


def _collect_with(action) -> None:
    callback = _Callback(action)
    gc.callbacks.append(callback)
    try:
        gc.collect()
    finally:
        gc.callbacks.remove(callback)
    assert callback.done


@pytest.fixture
def reported(monkeypatch) -> list[BaseException]:
    """What reaches the unraisable hook that was in place before :func:`interrupts.handled`."""
    seen: list[BaseException] = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: seen.append(u.exc_value))
    return seen


def _signal_self() -> None:
    os.kill(os.getpid(), signal.SIGINT)  # the handler runs as this call returns, inside the callback


def test_a_signal_inside_a_gc_callback_is_recorded_quietly_and_stops_at_the_next_check(reported):
    with interrupts.handled():
        _collect_with(_signal_self)
        assert interrupts.requested() == signal.SIGINT
        with pytest.raises(interrupts.Interrupted) as stopped:
            interrupts.check()
    assert stopped.value.exit_status == 130
    assert reported == []


def test_other_exceptions_in_a_gc_callback_are_still_reported(reported):
    def fail() -> None:
        raise ValueError("a real bug in a callback")

    with interrupts.handled():
        _collect_with(fail)
        assert interrupts.requested() is None
    assert [type(e) for e in reported] == [ValueError]


def test_the_unraisable_hook_is_put_back(reported):
    hook = sys.unraisablehook
    with interrupts.handled():
        assert sys.unraisablehook is not hook
    assert sys.unraisablehook is hook
