"""One CLI language across the aw-* commands (aw.cli.common): plain help with a line for every
flag, one replace-existing flag, one --jobs default, exit 2 for usage errors and 1 for failures,
one-line errors (never a traceback) for path mistakes."""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

import pytest

from aw.cores import available_cores

COMMANDS = ["aw-prepare", "aw-serve", "aw-score", "aw-run", "aw-demo"]


def _parsers() -> dict[str, argparse.ArgumentParser]:
    from aw.cli.prepare import build_parser as prepare
    from aw.demo import build_parser as demo
    from aw.runner.cli import build_parser as run
    from aw_eval.cli import build_parser as score
    from aw_server.cli import build_parser as serve

    out = {"aw-serve": serve(), "aw-score": score(), "aw-run": run(), "aw-demo": demo()}
    top = prepare()
    out["aw-prepare"] = top
    for action in top._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out[f"aw-prepare {name}"] = sub
    return out


PARSERS = _parsers()
MARKUP = re.compile(r"``|:(class|func|data|mod|meth):`|^\s*\.\. ", re.M)


def _flags(p: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in p._actions if a.option_strings and a.help != argparse.SUPPRESS]


@pytest.mark.parametrize("name", sorted(PARSERS))
def test_help_is_plain_and_every_flag_says_what_it_does(name):
    p = PARSERS[name]
    text = p.format_help()
    assert not MARKUP.search(text), text
    for action in p._actions:
        if action.help == argparse.SUPPRESS:
            continue
        assert action.help and action.help.strip(), f"{name}: {action.option_strings or action.dest} has no help"
    visible = {s for a in _flags(p) for s in a.option_strings}
    # One name per meaning: the old spellings are accepted but never shown.
    assert not visible & {"--force", "--fresh", "--final", "--mode"}, visible
    if name == "aw-score":
        assert "--protocol" not in visible  # aw-prepare's --protocol picks the preparation; here: --protocol-setting
    if "--jobs" in visible:
        jobs = next(a for a in p._actions if "--jobs" in a.option_strings)
        assert jobs.default == available_cores() and "number of CPU cores" in jobs.help


def test_replace_existing_is_overwrite_everywhere_with_the_old_names_as_aliases():
    with_overwrite = [n for n, p in PARSERS.items() if any("--overwrite" in a.option_strings for a in p._actions)]
    assert set(with_overwrite) >= {
        "aw-serve",
        "aw-run",
        "aw-demo",
        "aw-prepare synthetic",
        "aw-prepare folder",
        "aw-prepare compose",
        "aw-prepare official",
    }
    for name in with_overwrite:
        hidden = [a for a in PARSERS[name]._actions if a.dest == "overwrite" and a.help == argparse.SUPPRESS]
        assert [s for a in hidden for s in a.option_strings] == ["--force", "--fresh"], name
    args = PARSERS["aw-demo"].parse_args(["--fresh"])
    assert args.overwrite is True


def test_score_mode_names_and_their_old_aliases():
    p = PARSERS["aw-score"]
    a = p.parse_args(["S", "R", "--out", "O"])
    assert (a.final_mode, a.checkpoint_mode) == ("exact", "fast")
    a = p.parse_args(["S", "R", "--out", "O", "--final", "fast", "--mode", "exact"])
    assert (a.final_mode, a.checkpoint_mode) == ("fast", "exact")
    from aw_eval.cli import protocol_note

    assert protocol_note("exact") == ""
    assert "not the protocol's numbers" in protocol_note("fast") and "fast" in protocol_note("fast")
    assert "n_fps=64" in protocol_note("exact", [("n_fps", 64.0)])


def _run(cmd: str, *args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).with_name(cmd)
    return subprocess.run(
        [str(exe), *args], capture_output=True, text=True, timeout=120, cwd=cwd, stdin=subprocess.DEVNULL
    )


@pytest.mark.parametrize("cmd", COMMANDS)
def test_entry_points_print_help_and_refuse_unknown_flags_with_2(cmd):
    ok = _run(cmd, "--help")
    assert ok.returncode == 0 and ok.stdout.startswith("usage: " + cmd)
    bad = _run(cmd, "--no-such-flag")
    assert bad.returncode == 2 and "unrecognized arguments" in bad.stderr or "required" in bad.stderr


@pytest.mark.parametrize(
    "cmd, args",
    [
        ("aw-prepare", ["synthetic", "--per-source", "1", "--blocks", "fantastic_breaks", "--out"]),
        ("aw-run", ["SUITE", "--agent", "idle", "--out"]),
        ("aw-score", ["SUITE", "SUITE", "--out"]),
        ("aw-demo", ["--out"]),
    ],
)
def test_an_out_that_is_a_file_is_a_one_line_usage_error(cmd, args, tmp_path):
    (tmp_path / "SUITE").mkdir()
    (tmp_path / "a-file").write_text("x")
    for out, words in (("a-file", "exists and is not a directory"), ("a-file/sub", "is a file")):
        proc = _run(cmd, *args, out, cwd=tmp_path)
        err = proc.stderr.strip().splitlines()
        assert proc.returncode == 2, proc.stderr
        assert err[-1].startswith(f"{cmd}: error: --out {out}") and words in err[-1] and "Traceback" not in proc.stderr


def test_missing_inputs_are_one_line_usage_errors(tmp_path):
    for cmd, args in (
        ("aw-run", [str(tmp_path / "nope"), "--agent", "idle", "--out", str(tmp_path / "o")]),
        ("aw-score", [str(tmp_path / "nope"), str(tmp_path), "--out", str(tmp_path / "o")]),
        ("aw-serve", [str(tmp_path / "nope"), "--record", str(tmp_path / "r")]),
        ("aw-prepare", ["folder", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]),
    ):
        proc = _run(cmd, *args)
        assert proc.returncode == 2, (cmd, proc.stderr)
        assert proc.stderr.startswith(f"{cmd}: error: ") and "nope" in proc.stderr and "Traceback" not in proc.stderr
