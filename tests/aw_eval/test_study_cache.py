"""Cache entries: round trip, keys that follow the inputs, stale and damaged entries."""

from __future__ import annotations

import numpy as np
import pytest

from aw_eval.study.cache import Cache, geometry_key, run_key
from aw_eval.study.model import RunScore, TaskFacts, load_npz, save_npz


def _score() -> RunScore:
    r = RunScore(
        system="S",
        task_id="t.1",
        status="scored",
        problems=["a note"],
        final_from="final.json",
        pa=0.5,
        sr=0.0,
        sra=1.0,
        scd=0.0123,
        part_errors=np.array([0.001, 0.2]),
        assignment=np.array([1, 0]),
        ck_t=np.array([0.0, 1.5]),
        ck_part_errors=np.array([[0.5, 0.5], [0.001, 0.2]]),
        call_kind=np.array([0, 2], np.int8),
        edit_revisit=np.array([False]),
    )
    return r


def test_round_trip(tmp_path):
    r = _score()
    save_npz(tmp_path / "x.npz", r)
    back = load_npz(tmp_path / "x.npz")
    assert isinstance(back, RunScore)
    assert back.problems == ["a note"] and back.scd == 0.0123 and back.final_from == "final.json"
    for name in ("part_errors", "assignment", "ck_t", "ck_part_errors", "call_kind", "edit_revisit"):
        a, b = getattr(r, name), getattr(back, name)
        assert a.dtype == b.dtype and np.array_equal(a, b)
    u = RunScore.unscored("S", "t", "missing", ["no run"])
    save_npz(tmp_path / "u.npz", u)
    assert np.isnan(load_npz(tmp_path / "u.npz").scd)
    f = TaskFacts("t", 3, 2.5, 1.2, ["p01", "p02", "p03"])
    save_npz(tmp_path / "f.npz", f)
    assert load_npz(tmp_path / "f.npz") == f


def test_damaged_entry_is_reported(tmp_path):
    (tmp_path / "bad.npz").write_bytes(b"garbage")
    with pytest.raises(ValueError, match="damaged cache entry"):
        load_npz(tmp_path / "bad.npz")


def _task(tmp_path):
    task = tmp_path / "suite" / "tasks" / "t"
    (task / "parts").mkdir(parents=True)
    (task / "task.json").write_text("{}")
    (task / "parts" / "p01.obj").write_text("v 0 0 0\n")
    targets = tmp_path / "suite" / "targets" / "t.json"
    targets.parent.mkdir(parents=True)
    targets.write_text("{}")
    run = tmp_path / "runs" / "S" / "t"
    run.mkdir(parents=True)
    (run / "trajectory.jsonl").write_text("line\n")
    return task, targets, run


def test_keys_follow_every_input(tmp_path):
    task, targets, run = _task(tmp_path)
    g = geometry_key(task, targets)
    k = run_key(g, run, "s", "v")
    assert run_key(g, run, "s", "v") == k
    assert run_key(g, run, "s2", "v") != k and run_key(g, run, "s", "v2") != k
    (run / "trajectory.jsonl").write_text("line\nmore\n")
    k2 = run_key(g, run, "s", "v")
    assert k2 != k
    (run / "final.json").write_text("{}")
    assert run_key(g, run, "s", "v") != k2
    (task / "parts" / "p01.obj").write_text("v 0 0 1\n")
    assert geometry_key(task, targets) != g
    g2 = geometry_key(task, targets)
    targets.write_text('{"x": 1}')
    assert geometry_key(task, targets) != g2


def test_cache_hits_misses_and_stale_entries(tmp_path):
    c = Cache(tmp_path / "cache")
    r = _score()
    assert c.get_run("S", "t.1", "k1") is None
    c.put_run(r, "k1")
    assert c.get_run("S", "t.1", "k1").pa == 0.5
    assert c.get_run("S", "t.1", "k2") is None
    c.put_run(r, "k2")
    files = sorted(p.name for p in (tmp_path / "cache" / "runs" / "S" / "t.1").iterdir())
    assert files == ["k2.npz"]  # the stale entry is gone
    (tmp_path / "cache" / "runs" / "S" / "t.1" / "k2.npz").write_bytes(b"junk")
    assert c.get_run("S", "t.1", "k2") is None  # damaged: recomputed, never an exception
