"""Study discovery and the local process pool (results identical to in-process scoring)."""

from __future__ import annotations

import numpy as np

from aw_eval.study import ScoreSettings, discover_runs, score_study
from aw_eval.study.fixtures import box_suite, write_scripted_run

SMALL = (("n_fps", 48), ("n_surface", 192))


def test_discover_runs(tmp_path):
    (tmp_path / "A" / "t1").mkdir(parents=True)
    (tmp_path / "A" / "zzz").mkdir()
    (tmp_path / "A" / "zzz" / "final.json").write_text("{}")
    (tmp_path / "A" / "empty-unknown").mkdir()
    (tmp_path / ".hidden" / "t1").mkdir(parents=True)
    (tmp_path / "B").mkdir()
    systems, found, unknown = discover_runs(tmp_path, {"t1", "t2"})
    assert systems == ["A", "B"]
    assert list(found) == [("A", "t1")]
    assert [u["task_id"] for u in unknown] == ["zzz"]  # directories without run files are not runs


def test_process_pool_matches_in_process(tmp_path):
    blocks = (("fantastic_breaks", ("none",)),)
    suite = box_suite(tmp_path / "suite", objects_per_source=2, n_parts=2, blocks=blocks)
    for i, t in enumerate(["fantastic_breaks-box000-none", "fantastic_breaks-box001-none"]):
        write_scripted_run(
            tmp_path / "runs" / "S" / t, suite, t, system="S", correct=["p01"] if i else None, inspect_moves=False
        )
    settings = ScoreSettings(final_only=True, protocol=SMALL)
    geo = tmp_path / "geometry"
    a, sa = score_study(
        suite, tmp_path / "runs", tmp_path / "o1", settings, n_jobs=1, progress=False, geometry_cache=geo
    )
    b, sb = score_study(
        suite, tmp_path / "runs", tmp_path / "o2", settings, n_jobs=2, progress=False, geometry_cache=geo
    )
    assert sa.executor == "in-process" and sb.executor == "processes:2"
    assert sa.scored == sb.scored == 2
    for key, rec in a.runs.items():
        x, y = rec.score, b.runs[key].score
        assert x.status == y.status == "scored"
        assert (x.pa, x.sr, x.sra) == (y.pa, y.sr, y.sra)
        assert x.scd == y.scd
        assert np.array_equal(x.part_errors, y.part_errors) and np.array_equal(x.assignment, y.assignment)
    assert a.runs[("S", "fantastic_breaks-box000-none")].score.sr == 1.0


def test_schedule_jobs_largest_first_and_repeated_meshes_last(tmp_path):
    from aw_eval.study.job import ScoreSettings, TaskJob
    from aw_eval.study.runner import schedule_jobs

    def task(name, meshes):
        d = tmp_path / name / "parts"
        d.mkdir(parents=True)
        for k, text in enumerate(meshes):
            (d / f"p{k:02d}.obj").write_text(text)
        return TaskJob(name, str(d.parent), str(tmp_path / f"{name}.json"), (), ScoreSettings())

    jobs = [task("a-none", ["x", "y"]), task("a-image", ["x", "y"]), task("b", ["u", "v", "w"]), task("c", ["z"])]
    order = [j.task_id for j in schedule_jobs(jobs, {"a-none": 2, "a-image": 2, "b": 3, "c": 1})]
    assert order == ["b", "a-image", "c", "a-none"]


def test_jax_backend_scores_a_study_as_numba_does(tmp_path):
    """``ScoreSettings(backend="jax")`` (``aw-score --backend jax``) scores exact final states with
    the numba backend's PA/SR and SCD within 1e-9 relative; a backend that does not exist is refused."""
    import pytest

    from aw_eval.registration import BACKENDS
    from aw_eval.study import evaluator

    assert evaluator.BACKENDS == BACKENDS
    with pytest.raises(ValueError, match="backend must be one of"):
        ScoreSettings(backend="gpu")
    blocks = (("fantastic_breaks", ("none",)),)
    suite = box_suite(tmp_path / "suite", objects_per_source=1, n_parts=2, blocks=blocks)
    write_scripted_run(
        tmp_path / "runs" / "S" / "fantastic_breaks-box000-none",
        suite,
        "fantastic_breaks-box000-none",
        system="S",
        correct=["p01"],
        inspect_moves=False,
    )
    geo = tmp_path / "geometry"
    out = {}
    for backend in ("numba", "jax"):
        settings = ScoreSettings(final_only=True, protocol=SMALL, backend=backend)
        out[backend] = score_study(
            suite, tmp_path / "runs", tmp_path / backend, settings, n_jobs=1, progress=False, geometry_cache=geo
        )[0]
    ((key, a),) = out["numba"].runs.items()
    b = out["jax"].runs[key]
    assert a.score.status == b.score.status == "scored"
    assert (a.score.pa, a.score.sr, a.score.sra) == (b.score.pa, b.score.sr, b.score.sra)
    assert abs(a.score.scd - b.score.scd) <= 1e-9 * abs(a.score.scd) + 1e-20


def test_jax_backend_scores_every_exact_checkpoint_of_a_task_in_one_batch(tmp_path, monkeypatch):
    """``aw-score --checkpoint-mode exact --backend jax``: the checkpoints and final states of
    every run of a task (two systems here) are scored in one ``score_batch`` call, with the
    numba backend's decisions on every checkpoint."""
    import aw_eval

    blocks = (("fantastic_breaks", ("none",)),)
    suite = box_suite(tmp_path / "suite", objects_per_source=1, n_parts=2, blocks=blocks)
    task = "fantastic_breaks-box000-none"
    for system, correct in (("S", ["p01"]), ("T", None)):
        write_scripted_run(
            tmp_path / "runs" / system / task, suite, task, system=system, correct=correct, inspect_moves=False
        )
    geo = tmp_path / "geometry"
    real = aw_eval.score_batch
    calls = []

    def counted(geom, poses, *a, **kw):
        calls.append((len(poses), kw.get("backend")))
        return real(geom, poses, *a, **kw)

    monkeypatch.setattr(aw_eval, "score_batch", counted)
    out = {}
    for backend in ("numba", "jax"):
        calls.clear()
        settings = ScoreSettings(checkpoint_mode="exact", protocol=SMALL, backend=backend)
        out[backend] = score_study(
            suite, tmp_path / "runs", tmp_path / backend, settings, n_jobs=1, progress=False, geometry_cache=geo
        )[0]
        out[backend + "_calls"] = list(calls)
    assert len(out["jax_calls"]) == 1 and out["jax_calls"][0][1] == "jax"  # both runs' states, one batch
    assert len(out["numba_calls"]) >= 2  # numba: per run
    assert out["jax_calls"][0][0] >= 4
    for key, a in out["numba"].runs.items():
        b = out["jax"].runs[key].score
        a = a.score
        assert a.status == b.status == "scored"
        assert (
            np.array_equal(a.ck_pa, b.ck_pa) and np.array_equal(a.ck_sr, b.ck_sr) and np.array_equal(a.ck_sra, b.ck_sra)
        )
        assert np.all(np.abs(a.ck_scd - b.ck_scd) <= 1e-9 * np.abs(a.ck_scd) + 1e-20)
        assert (a.pa, a.sr, a.sra) == (b.pa, b.sr, b.sra)
