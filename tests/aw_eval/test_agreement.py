"""The fast paths against the plain reference (aw_eval.reference) on random checkpoints.

Acceptance (issue 3): on >= 200 random checkpoints with 2-20 parts, perturbations from tiny to
far-scattered, symmetric and identical parts, every PA and SR decision of ``exact`` equals the
reference's and SCD and per-part errors agree to 1e-5 relative (or 1e-9 absolute). Small clouds
(8 points per part, at most 8 ICP iterations) keep this fast; the protocol code is the same at
any size, and ``test_full_protocol_agrees`` runs the paper's numbers.
"""

from __future__ import annotations

import numpy as np
import pytest
from eval_helpers import close, small_task

import aw_eval
from aw_eval import reference as ref
from aw_eval.fixtures import random_checkpoints, swap_identical

# (parts, checkpoints): 200 checkpoints in all
CASES = [(2, 50), (3, 45), (5, 40), (8, 30), (12, 20), (20, 15)]


def _checkpoints(geom, obj, n, seed):
    cks = random_checkpoints(obj, n, seed=seed)
    legs = obj.identical[0] if obj.identical else []
    # every fifth checkpoint: two identical legs trade places (the matching must undo it)
    for k in range(0, n, 5):
        if len(legs) >= 2:
            cks[k] = swap_identical(geom, cks[k], legs[0], legs[-1])
    return cks


def _ref(geom, poses):
    return ref.score(geom.clouds, geom.target_poses, geom.divisor, geom.groups, poses, geom.settings)


@pytest.mark.parametrize("n_parts,n_ck", CASES)
def test_exact_equals_reference(n_parts, n_ck):
    geom, obj = small_task(n_parts, n_points=8, max_iters=8)
    cks = _checkpoints(geom, obj, n_ck, seed=100 + n_parts)
    batch = aw_eval.score_batch(geom, cks, mode="exact")
    for k in range(n_ck):
        r = _ref(geom, cks[k])
        assert batch.pa[k] == r.pa and batch.sr[k] == r.sr, f"checkpoint {k}"
        assert batch.sra[k] == r.sra
        assert close(batch.scd[k], r.scd), (k, batch.scd[k], r.scd)
        assert close(batch.part_errors[k], r.part_errors), (k, batch.part_errors[k], r.part_errors)


def test_full_resolution_icp_agrees():
    """The paper's numbers (4096 -> 1000 samples, 100 iterations, tol 1e-9) on a 3-part task:
    certified ICP from PCA and same-ID starts equals the reference ICP start by start."""
    from aw_eval.fixtures import make_points_geometry
    from aw_eval.kernels import ICPProblem
    from aw_eval.registration import checkpoint_starts

    geom, obj = make_points_geometry(3, 1000, seed=5, settings=aw_eval.ProtocolSettings())
    poses = random_checkpoints(obj, 1, seed=9, kinds=("small",))[0]
    target = geom.index().target
    ck = geom.checkpoint(poses)
    pred = ck.points
    r0, t0 = checkpoint_starts(geom, ck)
    ref_r0 = ref.pca_starts(pred, target) + ref.part_starts(poses, geom.target_poses, geom.divisor)
    prob = ICPProblem(pred, target)
    for k in (0, 5, 24, 26):
        assert np.array_equal(r0[k], ref_r0[k][0]) and np.array_equal(t0[k], ref_r0[k][1])
        got = prob.run(r0[k], t0[k], 100, 1e-9)
        want = ref.icp(pred, target, r0[k], t0[k], 100, 1e-9)
        assert abs(got.objective - want[0]) <= 1e-9 * want[0] + 1e-15
        assert np.allclose(got.rotation, want[1], atol=1e-9) and np.allclose(got.translation, want[2], atol=1e-9)


def test_fast_mode_agrees_on_easy_cases():
    """``fast`` prunes starts; on tiny-to-small perturbations its decisions match the reference."""
    geom, obj = small_task(5, n_points=40, seed=1)
    cks = random_checkpoints(obj, 8, seed=3, kinds=("exact", "tiny", "near", "small"))
    fast = aw_eval.score_batch(geom, cks, mode="fast")
    for k in range(len(cks)):
        r = _ref(geom, cks[k])
        assert fast.pa[k] == r.pa and fast.sr[k] == r.sr
        assert abs(fast.scd[k] - r.scd) <= 0.05 * r.scd + 1e-9
