"""Refiners as plug-ins: an external command through the JSON exchange (a real script run as a
subprocess), a Python entry point found by importlib.metadata, time limits and bad answers."""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from aw.formats import read_task
from aw.refine.base import RefinerError
from aw.refine.exchange import write_request
from aw.refine.plugins import RefinerSpec, available, command_label, resolve, run_refiner
from aw.refine.runs import build_request

SCRIPT = Path(__file__).with_name("scripted_refiner.py")


def _command() -> str:
    return f"{shlex.quote(sys.executable)} {shlex.quote(str(SCRIPT))} {{request}} {{result}}"


@pytest.fixture(scope="module")
def request_(fracture_suite):
    task = read_task(fracture_suite / "tasks" / "frac_cylinder_1")
    return build_request(task, fracture_suite, None)


def _with(request_, **options):
    request_.options = dict(options)
    return request_


def test_external_command_round_trip(request_, tmp_path):
    spec = resolve(None, _command())
    poses = run_refiner(spec, _with(request_, behaviour="shift", dx=0.5), tmp_path, 60)
    other = 1 - request_.anchor
    assert poses.shape == (2, 7)
    assert np.allclose(poses[other, :3], [0.5, 0, 0]) and np.allclose(poses[request_.anchor], [0, 0, 0, 1, 0, 0, 0])
    req = (tmp_path / "refine-request.json").read_text()
    assert '"points"' in req and "target" not in req  # the samples, never a target


def test_command_without_placeholders_gets_both_files_appended(request_, tmp_path):
    spec = RefinerSpec("scripted", (sys.executable, str(SCRIPT)))
    assert run_refiner(spec, _with(request_, behaviour="shift"), tmp_path, 60).shape == (2, 7)


R = "refiner scripted_refiner.py: "
RESULT = R + "result file refine-result.json: "


@pytest.mark.parametrize(
    "behaviour, start, end",
    [
        ("short", R + "returned 1 pose for 2 parts (missing fragment_", ")"),
        ("nan", RESULT + "not valid JSON: NaN at char ", " (NaN and Infinity are not JSON numbers)"),
        ("far", R + "pose of fragment_", ": pose position beyond +-1e+06 scene units"),
        ("huge", RESULT + "not valid JSON: a number beyond the range of a double (+-1.8e308) at char ", ""),
        ("deep", RESULT + "JSON nested deeper than 64 levels", ""),
        ("big", RESULT + "314572800 bytes, over the limit of 16777216 for a JSON file", ""),
        ("loud", R + "exited with code 3: scripted refiner: out of patience", ""),
        ("move_anchor", R + "moved the anchor fragment_", "it must keep its initial pose)"),
        ("fail", R + "exited with code 3: scripted refiner: model weights not found", ""),
        ("silent", R + "wrote no result file refine-result.json", ""),
    ],
)
def test_bad_external_answers_are_named(request_, tmp_path, behaviour, start, end):
    spec = RefinerSpec("scripted_refiner.py", (sys.executable, str(SCRIPT), "{request}", "{result}"))
    with pytest.raises(RefinerError) as err:
        run_refiner(spec, _with(request_, behaviour=behaviour), tmp_path, 60)
    assert str(err.value).startswith(start) and str(err.value).endswith(end), str(err.value)


PEAK = """
import sys, threading
from pathlib import Path
import psutil
from aw.refine.base import RefinerError
from aw.refine.exchange import read_request
from aw.refine.plugins import RefinerSpec, run_refiner
request_file, script, work = map(Path, sys.argv[1:4])
request = read_request(request_file)
spec = RefinerSpec("scripted", (sys.executable, str(script), "{request}", "{result}"))
me = psutil.Process()
base = peak = me.memory_info().rss
done = threading.Event()
def watch():
    global peak
    while not done.is_set():
        peak = max(peak, me.memory_info().rss)
        done.wait(0.002)
watcher = threading.Thread(target=watch)
watcher.start()
for behaviour in ("big", "loud"):
    request.options = {"behaviour": behaviour}
    try:
        run_refiner(spec, request, work / behaviour, 300)  # a loaded machine: time is not the point
    except RefinerError as exc:
        print(exc)
done.set()
watcher.join()
print((peak - base) >> 20)
"""


def test_a_300_mib_answer_or_log_is_never_read_whole(fracture_suite, tmp_path):
    """The result file is refused by its size and only the log's tail is read: while the refiner
    runs and answers, the parent's memory grows far less than the 300 MiB either file holds
    (reading either whole takes over 300 MB). Sampled every few milliseconds from the request
    read onwards, so that imports and compiled kernels do not count."""
    request_file = tmp_path / "request.json"
    write_request(
        request_file, build_request(read_task(fracture_suite / "tasks" / "frac_cylinder_1"), fracture_suite, None)
    )
    proc = subprocess.run(
        [sys.executable, "-c", PEAK, str(request_file), str(SCRIPT), str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert proc.returncode == 0, proc.stderr
    big, loud, growth_mb = proc.stdout.strip().splitlines()
    assert big.endswith("314572800 bytes, over the limit of 16777216 for a JSON file"), big
    assert loud == "refiner scripted: exited with code 3: scripted refiner: out of patience", loud
    assert int(growth_mb) < 100, f"grew by {growth_mb} MiB"


def test_a_refiner_past_its_time_limit_is_killed_and_named(request_, tmp_path):
    spec = RefinerSpec("slow", (sys.executable, str(SCRIPT), "{request}", "{result}"))
    with pytest.raises(RefinerError, match=r"refiner slow: timed out after 1.5 s \(killed\)"):
        run_refiner(spec, _with(request_, behaviour="sleep"), tmp_path, 1.5)


def _running(pid: int) -> bool:
    import psutil

    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


@pytest.mark.parametrize("behaviour", ["setsid", "setsid_answer"], ids=["timed-out", "answered"])
def test_nothing_a_refiner_started_outlives_it(request_, tmp_path, behaviour):
    """A process the refiner started in a session of its own (``os.setsid()``), orphaned out of its
    tree, ends at the refiner's time-out, or right after the refiner answered."""
    pid_file = tmp_path / "grandchild.pid"
    spec = RefinerSpec("slow", (sys.executable, str(SCRIPT), "{request}", "{result}"))
    request = _with(request_, behaviour=behaviour, pid_file=str(pid_file))
    try:
        if behaviour == "setsid":
            with pytest.raises(RefinerError, match=r"refiner slow: timed out after 10 s \(killed\)"):
                run_refiner(spec, request, tmp_path, 10)
        else:
            assert run_refiner(spec, request, tmp_path, 60).shape == (2, 7)
        pid = int(pid_file.read_text())
        for _ in range(100):  # killed by then; give the kernel a moment to tear it down
            if not _running(pid):
                break
            time.sleep(0.1)
        assert not _running(pid)
    finally:
        if pid_file.exists() and _running(int(pid_file.read_text())):
            os.kill(int(pid_file.read_text()), 9)


def test_a_command_is_labelled_by_its_program_without_a_script_extension():
    assert resolve(None, _command()).name == "scripted_refiner"  # python SCRIPT: the script
    assert resolve(None, "./refine.sh {request} {result}").name == "refine"
    assert resolve(None, "/opt/garf/bin/garf-infer").name == "garf-infer"
    assert resolve("mine", "./refine.py").name == "mine"  # --refiner NAME wins
    assert command_label("model.v2") == "model.v2" and command_label("R.EXE") == "R"


def test_unknown_refiner_and_bad_command_are_refused():
    with pytest.raises(RefinerError, match="unknown refiner 'nope'; available: classical"):
        resolve("nope")
    with pytest.raises(RefinerError, match="--refiner-command is empty"):
        resolve(None, "  ")


def test_missing_program_is_named(request_, tmp_path):
    with pytest.raises(RefinerError, match="refiner ghost: cannot start /nonexistent/ghost"):
        run_refiner(RefinerSpec("ghost", ("/nonexistent/ghost",)), _with(request_), tmp_path, 10)


def test_entry_point_plug_in_is_found_and_run_in_a_child_process(request_, tmp_path, monkeypatch):
    """A real distribution on the path: ``entry_points.txt`` registers ``shifty`` under
    ``assemblyworld.refiners``; the worker process finds it the same way."""
    site = tmp_path / "site"
    dist = site / "shifty_refiner-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: shifty-refiner\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[assemblyworld.refiners]\nshifty = shifty_refiner:refine\n")
    (site / "shifty_refiner.py").write_text(
        "import numpy as np\n"
        "def refine(request):\n"
        "    poses = np.array(request.initial_poses)\n"
        "    poses[1 - request.anchor, 2] += 0.125\n"
        "    return poses if request.options.get('count', 2) == 2 else poses[:1]\n"
    )
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]))
    assert "shifty" in available()
    spec = resolve("shifty")
    poses = run_refiner(spec, _with(request_), tmp_path / "ok", 120)
    assert np.isclose(poses[1 - request_.anchor, 2], 0.125)
    with pytest.raises(RefinerError, match="refiner shifty: returned 1 pose for 2 parts"):
        run_refiner(spec, _with(request_, count=1), tmp_path / "short", 120)
