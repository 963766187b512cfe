"""Targets stay hidden unless the experimenter asks. The viewer runs as its own process under an
audit hook that logs every file it opens; every response is scanned for the targets' numbers.

- Without ``--suite`` (the suite known to it through aw-run's batch plan, its public tasks
  shown): no response holds a target pose, and no file of the suite's hidden folders is opened.
- With ``--suite``: the target comes as a ghost in the scores alone; every state is scored
  (``fast``), the final one ``exact``, and kept in the run cache: a restarted viewer answers from
  it without scoring again. The episode page shows the ghost and the scores in Chromium.
"""

from __future__ import annotations

import io
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from view_helpers import ONE_TASK, fetch, get_json

from aw.formats import (
    FinalState,
    TrajectoryCall,
    TrajectoryEnd,
    TrajectoryHeader,
    read_manifest,
    read_targets,
    write_final,
)
from aw.formats.run import BATCH_FILE, BatchPlan, write_batch_plan
from aw.formats.trajectory import encode_record
from aw_eval.study.fixtures import box_suite, write_scripted_run

AUDITED = """
import os, sys
log = open(sys.argv[1], "a", buffering=1)
def hook(event, args):
    if event == "open" and isinstance(args[0], (str, bytes, os.PathLike)):
        log.write(os.fsdecode(args[0]) + "\\n")
sys.addaudithook(hook)
from aw_view.cli import main
sys.exit(main(sys.argv[2:]))
"""
HIDDEN = ("targets", "eval_points", "official")


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """A one-task suite; ``runs/mine/<task>``: an episode with made-up poses and a capture;
    ``runs/alpha/<task>``: a scripted episode that ends at the target."""
    root = tmp_path_factory.mktemp("hidden")
    suite = box_suite(root / "suite", objects_per_source=1, n_parts=3, blocks=ONE_TASK)
    (task_id,) = [t.task_id for t in read_manifest(suite).tasks]
    ids = ["p01", "p02", "p03"]
    rng = np.random.default_rng(7)
    poses = [{p: [*rng.uniform(-1, 1, 3).round(3), 1.0, 0.0, 0.0, 0.0] for p in ids} for _ in range(3)]
    run = root / "runs" / "mine" / task_id
    (run / "captures").mkdir(parents=True)
    buf = io.BytesIO()
    Image.new("RGB", (64, 48), (10, 120, 200)).save(buf, format="PNG")
    (run / "captures" / "000003.png").write_bytes(buf.getvalue())
    head = TrajectoryHeader(
        task_id=task_id, system="mine", started_at="2026-01-01T00:00:00Z", part_ids=ids, initial_poses=poses[0]
    )
    lines = [
        head,
        TrajectoryCall(seq=1, t=0.0, server_t=1.0, tool="start_episode", ok=True),
        TrajectoryCall(
            seq=2, t=1.0, server_t=2.0, tool="set_object_pose", ok=True, changed=ids, poses=poses[1], args={"id": "p01"}
        ),
        TrajectoryCall(seq=3, t=2.0, server_t=3.0, tool="capture_scene", ok=True, image="captures/000003.png"),
        TrajectoryCall(seq=4, t=3.0, server_t=4.0, tool="translate_objects", ok=True, changed=ids, poses=poses[2]),
        TrajectoryEnd(reason="finished", t=4.0, server_t=5.0, poses=poses[2]),
    ]
    (run / "trajectory.jsonl").write_bytes(b"".join(encode_record(r) + b"\n" for r in lines))
    write_final(run / "final.json", FinalState(task_id=task_id, reason="finished", poses=poses[2]))
    write_scripted_run(root / "runs" / "alpha" / task_id, suite, task_id, system="alpha", inspect_moves=False)
    # the viewer learns of the suite the way it does during an aw-run batch
    plan = BatchPlan(
        system="mine",
        suite_dir=str(suite),
        tasks=[task_id],
        pid=1,
        host=socket.gethostname(),
        started_unix=0.0,
        finished_unix=1.0,
    )
    write_batch_plan(root / "runs" / "mine" / BATCH_FILE, plan)
    targets = read_targets(suite / "targets" / f"{task_id}.json")
    return {"root": root, "suite": suite, "runs": root / "runs", "task": task_id, "targets": targets}


def _target_strings(targets) -> list[str]:
    """The ways a target pose number could appear in a response."""
    out = set()
    for t in targets.parts.values():
        for x in t.pose:
            if abs(x) > 1e-3 and abs(abs(x) - 1.0) > 1e-3:
                out |= {repr(x), repr(round(x, 6)), f"{x:.6f}", repr(float(np.float32(x)))}
    return sorted(out)


class Viewer:
    """``aw-view`` as a process under the audit hook; ``url``, ``opened()`` (paths it opened)."""

    def __init__(self, root: Path, *args: str):
        self.log = root / f"opened-{time.monotonic_ns()}.log"
        self.proc = subprocess.Popen(
            [sys.executable, "-c", AUDITED, str(self.log), *args, "--port", "0"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        line = self.proc.stdout.readline()
        assert " at http://127.0.0.1:" in line, (line, self.proc.stderr.read() if self.proc.poll() else "")
        self.url = line.split(" at ")[1].strip()

    def opened(self) -> list[str]:
        return self.log.read_text().splitlines()

    def stop(self) -> None:
        self.proc.send_signal(signal.SIGTERM)
        self.proc.wait(timeout=30)
        self.proc.stdout.close()
        self.proc.stderr.close()


def _every_response(url: str, ids: list[str], refs: int) -> dict[str, bytes]:
    """Every page, API answer and image the pages would load, for every episode."""
    out = {}
    for path in ["", "api/runs"] + [f"assets/{n}" for n in ("runs.js", "episode.js", "view.css", "viewer.js")]:
        out[path] = fetch(url + path)[1]
    for rid in ids:
        episode = get_json(f"{url}api/episode?id={rid}&from=0")
        for path in (f"episode/{rid}", f"api/episode?id={rid}&from=0", f"api/scene?id={rid}", f"api/score?id={rid}"):
            out[path] = fetch(url + path)[1]
        for c in episode["calls"]:
            if "image" in c:
                for thumb in ("", "&thumb=1"):
                    path = f"capture?id={rid}&name={c['image']}{thumb}"
                    status, out[path], _ = fetch(url + path)
                    assert status == 200
        for k in range(refs):
            path = f"reference?id={rid}&k={k}"
            status, out[path], _ = fetch(url + path)
            assert status == 200
    return out


def test_without_suite_no_target_byte_is_read_or_served(study):
    v = Viewer(study["root"], str(study["runs"]))
    try:
        ids = [r["id"] for r in get_json(v.url + "api/runs")["rows"]]
        assert sorted(ids) == sorted([f"alpha/{study['task']}", f"mine/{study['task']}"])
        scene = get_json(f"{v.url}api/scene?id=mine/{study['task']}")
        assert [p["id"] for p in scene["parts"]] == ["p01", "p02", "p03"]  # public task files found via the plan
        assert get_json(f"{v.url}api/score?id=mine/{study['task']}")["enabled"] is False
        responses = _every_response(v.url, [f"mine/{study['task']}"], refs=1)
        needles = _target_strings(study["targets"])
        for path, body in responses.items():
            text = body.decode("utf-8", "replace")
            assert "assemblyworld.targets" not in text, path
            assert not [n for n in needles if n in text], path
        opened = v.opened()
        assert any(p.endswith("task.json") for p in opened)  # it did read the public files
        hidden = [p for p in opened if any(f"{os.sep}{h}{os.sep}" in p for h in HIDDEN) and str(study["suite"]) in p]
        assert hidden == []
    finally:
        v.stop()


def _score_when_done(url: str, rid: str, want: int = -1, timeout: float = 600.0) -> dict:
    t0 = time.monotonic()
    while True:
        d = get_json(f"{url}api/score?id={rid}&want={want}")
        if "final" in d and not d["pending"]:
            return d
        assert "error" not in d, d
        assert time.monotonic() - t0 < timeout, d
        time.sleep(0.5)


def test_with_suite_the_ghost_and_the_scores_computed_once(study, browser):
    cache = study["root"] / "cache"
    rid = f"alpha/{study['task']}"
    v = Viewer(study["root"], str(study["runs"]), "--suite", str(study["suite"]), "--cache", str(cache))
    try:
        d = _score_when_done(v.url, rid)
        assert d["final"]["pa"] == pytest.approx(1.0) and d["final"]["sr"] and d["final"]["mode"] == "exact"
        n = len(get_json(f"{v.url}api/episode?id={rid}&from=0")["calls"])
        assert n and len(d["states"]) >= 2 and all(s["mode"] == "fast" for s in d["states"].values())
        # the ghost: the target brought onto the final state by its registration (here: where the parts are)
        detail = get_json(f"{v.url}api/episode?id={rid}&from=0")
        last = [c["poses"] for c in detail["calls"] if "poses" in c][-1]
        ghost = np.asarray(d["ghost"])
        assert np.abs(ghost[:, :3] - np.asarray(last)[:, :3]).max() < 1e-3
        # the scores alone carry target data; nothing else does (alpha's own recording holds the
        # target poses it placed its parts at, so the made-up episode is the one to scan)
        responses = _every_response(v.url, [f"mine/{study['task']}"], refs=1)
        needles = _target_strings(study["targets"])
        for path, body in responses.items():
            if not path.startswith("api/score"):
                assert not [n for n in needles if n in body.decode("utf-8", "replace")], path
        (entry,) = (cache / "runs" / "alpha" / study["task"]).glob("*.npz")
        stamp = entry.stat().st_mtime_ns

        page = browser.new_page(viewport={"width": 1300, "height": 900})
        errors: list[str] = []
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(f"{v.url}episode/{rid}")
        page.wait_for_function("() => document.getElementById('plot').dataset.ghost", timeout=120_000)
        assert "final: PA 100.0%" in page.locator("#score").text_content()
        ghost_traces = page.evaluate(
            "() => document.getElementById('plot').data.filter(t => t.visible === true).length"
        )
        assert ghost_traces == 3
        assert errors == []
        page.close()
    finally:
        v.stop()
    # a restarted viewer answers from the cache: the entry is not written again
    again = Viewer(study["root"], str(study["runs"]), "--suite", str(study["suite"]), "--cache", str(cache))
    try:
        d2 = _score_when_done(again.url, rid)
        assert d2["final"] == d["final"] and d2["states"] == d["states"]
        assert entry.stat().st_mtime_ns == stamp
    finally:
        again.stop()
