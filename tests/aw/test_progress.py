"""Progress display: a bar on a terminal, occasional plain lines in a log."""

from __future__ import annotations

import io

from aw.progress import LineProgress, progress


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_log_gets_plain_lines_not_a_redrawn_bar():
    log = io.StringIO()
    with progress(4, "scoring", "task", file=log, interval=0.0) as bar:
        assert isinstance(bar, LineProgress)
        for _ in range(4):
            bar.update(1)
        bar.set_postfix_str("finished=4")
    lines = log.getvalue().splitlines()
    assert "\r" not in log.getvalue()
    assert lines[0].startswith("scoring: 1/4 task (25%)") and lines[-1].startswith("scoring: 4/4 task (100%)")
    assert "finished=4" in lines[-1]


def test_lines_are_rate_limited_with_a_last_one_at_the_end():
    log = io.StringIO()
    bar = progress(100, "episodes", "task", file=log, interval=3600.0)
    for _ in range(100):
        bar.update(1)
    assert log.getvalue() == ""
    bar.close()
    bar.close()
    assert log.getvalue().splitlines() == [log.getvalue().splitlines()[0]] and "100/100" in log.getvalue()


def test_a_terminal_gets_tqdm_and_disabled_prints_nothing():
    tty = _Tty()
    bar = progress(2, "objects", "obj", file=tty)
    assert type(bar).__name__ == "tqdm"
    bar.update(2)
    bar.close()
    assert "objects" in tty.getvalue()
    quiet = io.StringIO()
    off = progress(2, "objects", "obj", file=quiet, enabled=False)
    off.update(2)
    off.close()
    assert quiet.getvalue() == ""


def test_warnings_read_as_one_line_of_the_command(capsys):
    import warnings

    from aw.progress import LongWorkWarning, warnings_in_one_line

    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = warnings_in_one_line("aw-score")
        warnings.warn(
            "scoring 9 states of a 300-part task (exact, numba): 8 left, about 40 min", LongWorkWarning, stacklevel=1
        )
    assert (
        capsys.readouterr().err
        == "aw-score: warning: scoring 9 states of a 300-part task (exact, numba): 8 left, about 40 min\n"
    )
