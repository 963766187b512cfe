"""The ``jax`` backend scores the protocol (``exact``) with the numbers of the ``numba`` backend:
identical PA/SR, SCD within 1e-9 relative, on the CPU at small sizes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from eval_helpers import small_settings, small_task

import aw_eval
from aw_eval.fixtures import make_points_geometry, random_checkpoints, swap_identical
from aw_eval.kernels import accelerator_present, jax_icp
from aw_eval.registration import resolve_backend


def _agree(a, b):
    assert np.array_equal(a.pa, b.pa) and np.array_equal(a.sr, b.sr) and np.array_equal(a.sra, b.sra)
    # SCDs of exact registrations are rounding noise (~1e-32): relative error above an absolute floor
    assert np.all(np.abs(a.scd - b.scd) <= 1e-9 * np.maximum(a.scd, b.scd) + 1e-20)
    assert np.allclose(a.part_errors, b.part_errors, rtol=1e-9, atol=1e-20)


@pytest.mark.parametrize("candidates", [1, 8])
def test_jax_batch_equals_numba_exact_with_swapped_identical_parts(monkeypatch, candidates):
    """Far, near and exact checkpoints of a 3-part table with identical legs (two of them with
    the legs' poses exchanged), one jax call of 8 checkpoints padded from 7; neighbours by
    leaf certificates with their brute-force fallback (1 leaf read of 2-3) or by brute force
    (8: every leaf read)."""
    monkeypatch.setattr(jax_icp, "CANDIDATES", candidates)
    geom, obj = small_task(3, 16)
    cks = random_checkpoints(obj, 5, seed=3)
    legs = next(g for g in geom.groups if len(g) > 1)
    cks = np.concatenate([cks, [swap_identical(geom, c, legs[0], legs[1]) for c in cks[1:3]]])
    numba = aw_eval.score_batch(geom, cks, mode="exact", backend="numba")
    jax = aw_eval.score_batch(geom, cks, mode="exact", backend="jax")
    _agree(numba, jax)
    assert {0.0, 1.0} <= set(numba.pa.tolist())  # failed and solved checkpoints both
    one = aw_eval.score(geom, cks[3], mode="exact", backend="jax")
    assert (one.pa, one.sr) == (jax.pa[3], jax.sr[3])


def test_backend_choice_and_bad_input():
    assert resolve_backend("numba", "fast") == "numba"
    assert resolve_backend("jax", "exact") == "jax"
    # auto: jax for exact where JAX sees a GPU or TPU, else the compiled CPU kernels
    assert resolve_backend("auto", "exact") == ("jax" if accelerator_present() else "numba")
    assert resolve_backend("auto", "fast") == "numba"
    with pytest.raises(ValueError, match="backend 'jax' runs mode 'exact' only"):
        resolve_backend("jax", "fast")
    with pytest.raises(ValueError, match="backend must be one of"):
        resolve_backend("gpu", "exact")


def test_knife_edge_thresholds_decide_alike(monkeypatch):
    """Thresholds set 1e-7 relative above and below a part error and an SCD the numba backend
    measured: the decisions there (PA, SR, SR^a) are the same on both backends (neighbours by
    leaf certificates, one leaf read of 2-3, with the brute-force fallback)."""
    monkeypatch.setattr(jax_icp, "CANDIDATES", 1)
    geom, obj = small_task(3, 16)
    cks = random_checkpoints(obj, 4, seed=11)
    base = aw_eval.score_batch(geom, cks, mode="exact", backend="numba")
    errors = base.part_errors[base.part_errors > 1e-12]
    scds = base.scd[base.scd > 1e-12]
    assert len(errors) and len(scds)
    for sign in (-1.0, 1.0):
        st = dataclasses.replace(
            small_settings(16),
            threshold=float(np.sort(errors)[len(errors) // 2]) * (1 + sign * 1e-7),
            sra_threshold=float(np.sort(scds)[len(scds) // 2]) * (1 + sign * 1e-7),
        )
        g, _ = make_points_geometry(3, 16, 0, st)
        numba = aw_eval.score_batch(g, cks, mode="exact", backend="numba")
        jax = aw_eval.score_batch(g, cks, mode="exact", backend="jax")
        assert np.any(np.abs(numba.part_errors / st.threshold - 1) < 1e-6)  # a knife edge is scored
        _agree(numba, jax)
        stats = jax.stats["jax"]
        assert stats["lanes_iterated"] >= stats["lane_iterations"] > 0
        assert 0 < stats["brute_queries"] < stats["queries"]  # the leaves certified some, the fallback did the rest
