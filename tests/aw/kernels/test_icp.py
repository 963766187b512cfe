"""Certified warm-started nearest neighbours and the ICP building blocks."""

from __future__ import annotations

import numpy as np

from aw.kernels.icp import CertifiedNN, ICPProblem, build_tree
from aw_eval.reference import icp as ref_icp
from aw_eval.reference import kabsch


def _brute(x, ref):
    d = ((x[:, None, :] - ref[None, :, :]) ** 2).sum(-1)
    return d.argmin(1)


def test_certified_nn_equals_brute_force_along_a_path():
    rng = np.random.default_rng(0)
    ref = rng.normal(size=(600, 3))
    ref[:200] *= 0.05  # a dense cluster next to a sparse cloud
    x = rng.normal(size=(400, 3)) * 1.5
    x[:50] += 8.0  # far queries: almost tied neighbours
    nn = CertifiedNN(ref, build_tree(ref))
    step = rng.normal(size=(400, 3))
    searched = []
    for it in range(25):
        scale = 0.3 if it < 5 else 1e-3  # big moves first, then creeping like ICP
        x = x + scale * step * rng.random((400, 1))
        before = nn.n_searched
        got = nn.query(x)
        assert np.array_equal(got, _brute(x, ref)), f"iteration {it}"
        searched.append(nn.n_searched - before)
    assert searched[-1] < 400  # the certificate spared searches once moves got small


def test_kabsch_is_proper_and_exact():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(50, 3))
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    from aw.pose import quat_to_matrix

    r = quat_to_matrix(q)
    t = np.array([0.3, -2.0, 5.0])
    r_fit, t_fit = kabsch(src, src @ r.T + t)
    assert np.allclose(r_fit, r, atol=1e-12) and np.allclose(t_fit, t, atol=1e-12)
    # a mirrored target is fitted by a proper rotation, never a reflection
    mirror = src * np.array([1.0, 1.0, -1.0])
    r_m, _ = kabsch(src, mirror)
    assert np.isclose(np.linalg.det(r_m), 1.0)


def test_icp_problem_equals_reference_icp():
    rng = np.random.default_rng(2)
    t_pts = rng.normal(size=(300, 3)) * [1.0, 0.5, 0.2]
    p = t_pts[rng.permutation(300)[:250]] + rng.normal(size=(250, 3)) * 0.01
    ang = 0.4
    r0 = np.array([[np.cos(ang), -np.sin(ang), 0], [np.sin(ang), np.cos(ang), 0], [0, 0, 1.0]])
    t0 = np.array([0.1, 0.0, -0.05])
    want = ref_icp(p, t_pts, r0, t0, 60, 1e-9)
    got = ICPProblem(p, t_pts).run(r0, t0, 60, 1e-9)
    assert abs(got.objective - want[0]) <= 1e-12 * max(want[0], 1.0)
    assert np.allclose(got.rotation, want[1], atol=1e-12)
