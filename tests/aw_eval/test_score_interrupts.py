"""Interrupts stay interrupts: a seeded handful of SIGINT / SIGTERM / SIGHUP at moments of a real
``aw-score`` (``--jobs 1`` and ``--jobs 2``; some while scoring runs, inside the compiled ICP) never
record a run as failed or replace a report with partial numbers: the previous outputs stay byte
for byte, the exit status is 128 + the signal, no traceback, no leaked-semaphore warning, nothing
temporary left, no worker left. The wider sweep is ``benchmarks/interrupt_sweep.py``."""

from __future__ import annotations

import signal
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import interrupt_sweep  # noqa: E402

from aw import interrupts  # noqa: E402

OPTIONS = tuple([*interrupt_sweep.FAST, "--no-html"])


@pytest.fixture(scope="module")
def sweep(tmp_path_factory) -> interrupt_sweep.Sweep:
    work = tmp_path_factory.mktemp("interrupts")
    suite, runs = interrupt_sweep.make_study(work / "study")
    s = interrupt_sweep.Sweep(suite, runs, work, OPTIONS)
    s.prepare()
    return s


# Seeded points (interrupt_sweep.plan with seed 0 draws the delays): two in the scoring of
# runs, the other two anywhere in a call (starting up, the analyses, writing the outputs); and
# Ctrl-C to the process group just as the scoring workers start (they are still importing).
POINTS = interrupt_sweep.plan(4, seed=0, variants=[["--jobs", "1"], ["--jobs", "2"]]) + [
    interrupt_sweep.Point(signal.SIGINT, 0.01, ("--jobs", "2"), True, interrupt_sweep.SCORING_LINE)
]


@pytest.mark.parametrize("index", range(len(POINTS)))
def test_an_interrupt_leaves_the_previous_report_as_it_was(sweep, index):
    point = POINTS[index]
    row = sweep.trial(index, point)
    print(row)  # shown whole when the test fails (an assertion message is cut short)
    assert row["ok"], row
    assert row["exit"] in (0, 128 + point.signal, -point.signal), row  # -signal: a shell sees 128 + signal


def test_the_exit_status_is_128_plus_the_signal():
    for sig, status in ((signal.SIGINT, 130), (signal.SIGTERM, 143), (signal.SIGHUP, 129)):
        assert interrupts.Interrupted(sig).exit_status == status


def test_an_exception_while_an_interrupt_is_recorded_is_the_interrupt():
    """numba hands a Ctrl-C back as a SystemError whose context is the KeyboardInterrupt."""
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as inner:
            raise SystemError("CPUDispatcher(<function _icp>) returned a result with an exception set") from inner
    except SystemError as exc:
        with pytest.raises(interrupts.Interrupted):
            interrupts.reraise_if_interrupted(exc)
    interrupts.reraise_if_interrupted(ValueError("a bad run"))  # a plain failure stays the run's
