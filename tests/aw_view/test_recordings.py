"""What the viewer makes of the recordings it finds: a recording written line by line (its cut
last line waited for, never an error), hostile and unreadable ones (a named line on the page
while the others keep updating), a stuck episode, aw-run's queued episodes, and requests for
files outside an episode."""

from __future__ import annotations

import os
import socket
import time
from datetime import UTC, datetime

import pytest
from view_helpers import ONE_TASK, fetch, get_json, viewer

from aw.formats import TrajectoryCall, TrajectoryHeader, read_manifest
from aw.formats.run import BATCH_FILE, BatchPlan, write_batch_plan
from aw.formats.trajectory import encode_record
from aw.runlock import RunDirLock
from aw_eval.study.fixtures import box_suite

WAIT = 120_000
I7 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]


@pytest.fixture
def suite(tmp_path):
    return box_suite(tmp_path / "suite", objects_per_source=1, n_parts=3, blocks=ONE_TASK)


def _header(task_id: str, started: float) -> bytes:
    iso = datetime.fromtimestamp(started, UTC).isoformat().replace("+00:00", "Z")
    h = TrajectoryHeader(
        task_id=task_id,
        system="mine",
        started_at=iso,
        part_ids=["p01", "p02", "p03"],
        initial_poses={p: I7 for p in ("p01", "p02", "p03")},
    )
    return encode_record(h) + b"\n"


def _call(seq: int, server_t: float, **kw) -> bytes:
    return encode_record(TrajectoryCall(seq=seq, t=server_t - 1.0, server_t=server_t, ok=True, **kw)) + b"\n"


def test_recordings_as_they_are_written_damaged_hostile_stuck_and_queued(suite, tmp_path, browser):
    (task_id,) = [t.task_id for t in read_manifest(suite).tasks]
    runs = tmp_path / "runs"
    mine = runs / "mine" / task_id
    mine.mkdir(parents=True)
    lock = RunDirLock(mine, command="test recorder").acquire()  # a live recorder, as aw-serve holds it
    started = time.time() - 600.0
    traj = mine / "trajectory.jsonl"
    traj.write_bytes(_header(task_id, started) + _call(1, 1.0, tool="start_episode"))
    # unreadable: a damaged second line; hostile: a trajectory that links to the hidden targets,
    # and one whose capture names a file outside the run directory
    (runs / "bad" / task_id).mkdir(parents=True)
    (runs / "bad" / task_id / "trajectory.jsonl").write_bytes(_header(task_id, started) + b'{"type": "call", nope}\n')
    (runs / "link" / task_id).mkdir(parents=True)
    (runs / "link" / task_id / "trajectory.jsonl").symlink_to(suite / "targets" / f"{task_id}.json")
    (runs / "escape" / task_id).mkdir(parents=True)
    (runs / "escape" / task_id / "trajectory.jsonl").write_bytes(
        _header(task_id, started)
        + _call(1, 1.0, tool="capture_scene", image=f"../../../../suite/targets/{task_id}.json")
    )
    # aw-run's plan of a live batch: its tasks without a run directory yet are queued
    plan = BatchPlan(
        system="later",
        suite_dir=str(suite),
        tasks=[task_id, "another-task"],
        pid=os.getpid(),
        host=socket.gethostname(),
        started_unix=time.time(),
    )
    (runs / "later").mkdir()
    write_batch_plan(runs / "later" / BATCH_FILE, plan)

    with viewer(runs.resolve(), stuck=60.0) as url:
        rows = {r["id"]: r for r in get_json(url + "api/runs")["rows"]}
        assert rows[f"mine/{task_id}"]["status"] == "running" and rows[f"mine/{task_id}"]["calls"] == 1
        bad = rows[f"bad/{task_id}"]
        assert bad["status"] == "unreadable" and "trajectory.jsonl: line 2: not valid JSON" in bad["detail"]
        assert rows[f"link/{task_id}"]["status"] == "unreadable"
        assert "outside the watched folder" in rows[f"link/{task_id}"]["detail"]
        assert {rows[f"later/{t}"]["status"] for t in plan.tasks} == {"queued"}
        assert fetch(f"{url}capture?id=escape/{task_id}&name=../../../../suite/targets/{task_id}.json")[0] == 404
        assert fetch(f"{url}capture?id=mine/{task_id}&name=captures/../../../bad/{task_id}/trajectory.jsonl")[0] == 404
        assert fetch(f"{url}api/episode?id=../suite")[0] == 404
        assert fetch(f"{url}reference?id=mine/{task_id}&k=-1")[0] == 404  # no task files given: none at all

        page = browser.new_page(viewport={"width": 1300, "height": 900})
        errors: list[str] = []
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(url)
        page.wait_for_selector(f'#runs tr[data-id="mine/{task_id}"].stuck', timeout=WAIT)  # no call for 10 minutes
        assert "line 2: not valid JSON" in page.locator(f'#runs tr[data-id="bad/{task_id}"] td.status').text_content()
        assert page.locator("#runs tr[data-status='queued']").count() == 2

        # a call line written in three pieces (the cut inside a multi-byte character): nothing is
        # reported until it is whole, then it counts; the other episodes go on being shown
        line = _call(2, 599.0, tool="translate_objects", args={"ids": ["p01"], "note": "\u00e9t\u00e9"})
        cut = line.index("\u00e9".encode()) + 1
        for piece in (line[:cut], line[cut:-3], line[-3:]):
            with open(traj, "ab") as fh:
                fh.write(piece)
            for _ in range(3):
                row = next(r for r in get_json(url + "api/runs")["rows"] if r["id"] == f"mine/{task_id}")
                detail = get_json(f"{url}api/episode?id=mine/{task_id}&from=0")
                assert row["status"] == "running" and detail["problem"] is None, (row, detail["problem"])
                time.sleep(0.1)
        assert row["calls"] == 2 and [c["tool"] for c in detail["calls"]] == ["start_episode", "translate_objects"]
        page.wait_for_selector(f'#runs tr[data-id="mine/{task_id}"]:not(.stuck)', timeout=WAIT)
        page.wait_for_function(
            f"""() => document.querySelector('#runs tr[data-id="mine/{task_id}"] td.calls').textContent === '2'""",
            timeout=WAIT,
        )
        lock.release()  # the recorder went away without an end record
        page.wait_for_selector(f'#runs tr[data-id="mine/{task_id}"][data-status="interrupted"]', timeout=WAIT)
        assert errors == []
        page.close()
