"""Hostile official files (tests/aw/official/hostile.py): ``aw-score PKG RUNS`` and
``aw-prepare official`` both name the problem in one line (or, for a bad archive, in the
sample's error row), never a traceback, and a failed conversion or evaluation leaves nothing
that looks complete: the same command runs again once the file is fixed."""

from __future__ import annotations

import json
import shutil

import pytest

from aw.cli.prepare import main as prepare
from aw.official import errors
from aw.official.evaluation_output import read_metrics
from aw.official.package import OfficialPackage
from aw_eval.cli import main as score
from tests.aw.official.builders import write_package
from tests.aw.official.hostile import SAMPLE, VARIANTS, good_run, sample_dir

NAMED = set(errors.__all__) | {"FormatError"}


@pytest.fixture(scope="module")
def package(tmp_path_factory):
    return OfficialPackage(write_package(tmp_path_factory.mktemp("pkg"), {SAMPLE[0]: [SAMPLE[1]]}), strict=False)


@pytest.fixture(scope="module")
def pristine(package, tmp_path_factory):
    return good_run(package, tmp_path_factory.mktemp("good") / "logs")


def _one_line_error(err: str, prog: str) -> str:
    lines = [line for line in err.splitlines() if line.startswith(f"{prog}: error:")]
    assert "Traceback" not in err and len(lines) == 1, err
    return lines[0]


@pytest.mark.parametrize("variant", VARIANTS, ids=[v.name for v in VARIANTS])
def test_both_commands_name_the_problem(variant, package, pristine, tmp_path, capsys):
    logs = tmp_path / "logs"
    shutil.copytree(pristine.parent, logs, symlinks=True)
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    variant.damage(logs / pristine.name, scratch)

    out = tmp_path / "out"
    code = score([str(package.root), str(logs), "--out", str(out), "--jobs", "1"])
    err = capsys.readouterr().err
    if variant.archive:  # the attempt counts as an error, as in the official evaluation
        assert code == 1 and "Traceback" not in err, err
        (row,) = read_metrics(next((out / "official").iterdir()) / "metrics.jsonl")
        kind = row["error"].split(":")[0]
        assert row["status"] == "error" and kind in NAMED and variant.message in row["error"], row["error"]
    else:
        assert code == 2 and variant.message in _one_line_error(err, "aw-score")
        assert not (out / "official").exists() and not list(out.glob(".official*"))

    suite, runs = tmp_path / "suite", tmp_path / "runs"
    code = prepare(["official", str(package.root), "--episodes", str(logs), "--out", str(suite), "--runs", str(runs)])
    assert code == 1 and variant.message in _one_line_error(capsys.readouterr().err, "aw-prepare")
    assert not (suite / "manifest.json").exists() and not list(suite.glob(".aw-staging*"))
    assert not runs.exists() or [p.name for p in runs.iterdir()] == []


def test_a_failed_evaluation_or_conversion_can_be_rerun(package, pristine, tmp_path, capsys):
    """NaN in result.json: refused by name, nothing written; fixed, the same commands succeed."""
    logs = tmp_path / "logs"
    shutil.copytree(pristine.parent, logs)
    result = sample_dir(logs / pristine.name) / "result.json"
    good = result.read_text()
    result.write_text(good.replace('"status": "completed"', '"duration_seconds": NaN, "status": "completed"', 1))
    out, suite, runs = tmp_path / "out", tmp_path / "suite", tmp_path / "runs"
    score_cmd = [str(package.root), str(logs), "--out", str(out), "--jobs", "1"]
    prepare_cmd = ["official", str(package.root), "--episodes", str(logs), "--out", str(suite), "--runs", str(runs)]
    assert score(score_cmd) == 2 and prepare(prepare_cmd) == 1
    err = capsys.readouterr().err
    assert err.count("NaN and Infinity are not JSON numbers") == 2 and "Traceback" not in err
    result.write_text(good)
    assert score(score_cmd) == 0 and prepare(prepare_cmd) == 0
    (row,) = read_metrics(out / "official" / "fixture-m" / "metrics.jsonl")
    assert row["status"] == "scored" and json.loads((suite / "manifest.json").read_text())["tasks"]
    assert [p.name for p in runs.iterdir()] == ["fixture-m"]


def test_a_conversion_that_fails_late_leaves_no_suite_and_no_runs(package, tmp_path, capsys):
    """Two samples, the second archive corrupt: before, the suite and the first run were written."""
    from tests.aw.official.builders import FINAL, write_run_log
    from tests.aw.official.hostile import VARIANTS as ALL

    pkg = OfficialPackage(write_package(tmp_path / "pkg2", {"partnet-none": ["21905", "743"]}), strict=False)
    run = write_run_log(tmp_path / "logs", pkg, {("partnet-none", "21905"): FINAL, SAMPLE: FINAL}, "run-1")
    next(v for v in ALL if v.name == "corrupt-deflate").damage(run, tmp_path)
    suite, runs = tmp_path / "suite", tmp_path / "runs"
    assert (
        prepare(
            ["official", str(pkg.root), "--episodes", str(tmp_path / "logs"), "--out", str(suite), "--runs", str(runs)]
        )
        == 1
    )
    assert "cannot be inflated" in capsys.readouterr().err
    assert [p.name for p in suite.iterdir()] == [] and [p.name for p in runs.iterdir()] == []


def test_a_full_disk_while_writing_the_evaluation_is_one_line_and_leaves_nothing(package, pristine, tmp_path):
    """A file size limit stands in for a full disk: metrics.jsonl cannot be written."""
    import os
    import resource
    import signal
    import subprocess
    import sys

    def limit() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (600, 600))

    out = tmp_path / "out"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "aw_eval.cli",
            str(package.root),
            str(pristine.parent),
            "--out",
            str(out),
            "--jobs",
            "1",
        ],
        preexec_fn=limit,
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path), "PYTHONDONTWRITEBYTECODE": "1"},
    )
    # (no bytecode written: under the limit CPython would install .pyc files cut short)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert _one_line_error(proc.stderr, "aw-score").endswith("metrics.jsonl: File too large")
    assert [p.name for p in out.iterdir()] == [".aw-lock"]
