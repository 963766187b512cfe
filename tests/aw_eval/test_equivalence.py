"""Equivalence groups: fast path against the reference, symmetric and identical parts."""

from __future__ import annotations

import numpy as np
import pytest
from eval_helpers import small_task

from aw.pose import quat_to_matrix
from aw_eval import reference as ref
from aw_eval.equivalence import equivalence_groups
from aw_eval.fixtures import random_rotation_quat
from aw_eval.settings import ProtocolSettings


def test_groups_equal_reference_and_join_identical_legs():
    geom, obj = small_task(6, n_points=16, seed=2, max_iters=25)
    want = ref.equivalence_groups(geom.clouds, geom.divisor, geom.settings)
    assert [list(g) for g in geom.groups] == want
    assert list(obj.identical[0]) in want


def test_rotated_copies_join_scaled_copies_do_not():
    rng = np.random.default_rng(3)
    base = rng.normal(size=(40, 3)) * [0.5, 0.2, 0.1]
    rot = quat_to_matrix(random_rotation_quat(rng))
    clouds = np.stack([base, base @ rot.T + [2.0, 0, 0], base * 1.5, base[::-1] @ rot + [0, 3.0, 0]])
    st = ProtocolSettings(n_surface=40, n_fps=40, max_iters=40)
    got = equivalence_groups(clouds, 1.0, st)
    assert got == [[0, 1, 3], [2]]
    assert got == ref.equivalence_groups(clouds, 1.0, st)


def _pair_cd(x, y, st):
    from aw.pose import cube_rotations, pca_frame

    qs = []
    for c in (x, y):
        mu, ax = pca_frame(c)
        qs.append((c - mu) @ ax)
    return ref.register(qs[0], qs[1], [(s, np.zeros(3)) for s in cube_rotations()], st).scd


def _chain():
    """Clouds a, b, c where b moves one point of a by 0.034 and c one more: a~b and b~c within
    1e-4, a and c not; and the generator, for more clouds."""
    rng = np.random.default_rng(4)
    a = rng.normal(size=(30, 3)) * [1.0, 0.5, 0.25]
    b = a.copy()
    b[0, 0] += 0.034
    c = b.copy()
    c[1, 0] += 0.034
    return a, b, c, rng


def test_groups_are_transitive_closures():
    # b moves one point of a by eps, c moves one more: a~b and b~c within 1e-4, a and c not
    a, b, c, rng = _chain()
    st = ProtocolSettings(n_surface=30, n_fps=30, max_iters=30, equiv_cd=1e-4)
    assert _pair_cd(a, b, st) <= 1e-4 and _pair_cd(b, c, st) <= 1e-4 and _pair_cd(a, c, st) > 1e-4
    groups = equivalence_groups(np.stack([a, b, c]), 1.0, st)
    assert groups == [[0, 1, 2]] == ref.equivalence_groups(np.stack([a, b, c]), 1.0, st)


def _box_cloud(extents, n, seed):
    import trimesh

    pts, _ = trimesh.sample.sample_surface(trimesh.creation.box(extents=extents), n, seed=seed)
    return np.asarray(pts, dtype=np.float64)


def _in_frame(c):
    from aw.pose import pca_frame

    mu, ax = pca_frame(c)
    return (c - mu) @ ax


def test_cd_lower_bound_holds_for_every_rigid_motion_and_the_registration():
    from aw.shape_bounds import cloud_bounds, lower_bounds
    from aw_eval.chamfer import chamfer as cd

    rng = np.random.default_rng(11)
    st = ProtocolSettings(n_surface=200, n_fps=200, max_iters=30)
    shapes = [
        (0.6, 0.1, 0.05),
        (0.6, 0.1, 0.08),
        (0.5, 0.12, 0.05),
        (0.3, 0.3, 0.02),
        (0.2, 0.2, 0.2),
        (0.62, 0.1, 0.05),
    ]
    clouds = [_in_frame(_box_cloud(e, 200, k)) for k, e in enumerate(shapes)]
    bound = lower_bounds(cloud_bounds(np.stack(clouds)))
    excluded = 0
    for i in range(len(clouds)):
        for j in range(len(clouds)):
            if i == j:
                continue
            lb = bound[i, j]
            best = _pair_cd(clouds[i], clouds[j], st)
            assert lb <= best * (1 + 1e-12) + 1e-15, (i, j, lb, best)
            for _ in range(20):
                r = quat_to_matrix(random_rotation_quat(rng))
                t = rng.normal(scale=0.05, size=3)
                assert lb <= float(cd(clouds[i] @ r.T + t, clouds[j])) + 1e-15
            excluded += lb > 1e-4
    # the bound does real work: a plate against a stick or a cube is excluded without registration
    assert bound[3, 0] > 1e-4 and bound[4, 0] > 1e-4
    assert excluded >= 10


def test_bounded_groups_equal_reference_on_near_identical_boxes():
    # boxes close in size: the bound must not cut a true edge (0 ~ 5), and the groups equal the reference
    clouds = np.stack(
        [
            _box_cloud(e, 64, 0)
            for e in [(0.6, 0.1, 0.05), (0.6, 0.1, 0.08), (0.3, 0.3, 0.02), (0.2, 0.2, 0.2), (0.6, 0.1, 0.05)]
        ]
    )
    st = ProtocolSettings(n_surface=64, n_fps=64, max_iters=30)
    got = equivalence_groups(clouds, 1.0, st)
    assert got == ref.equivalence_groups(clouds, 1.0, st)
    assert [0, 4] in got


def _boxes_object(extents, n_points, seed=0):
    """Clouds ``(P, n_points, 3)`` of boxes placed apart and turned, each sampled with its own seed."""
    rng = np.random.default_rng(seed)
    out = []
    for k, e in enumerate(extents):
        rot = quat_to_matrix(random_rotation_quat(rng))
        out.append(_box_cloud(e, n_points, 100 + k) @ rot.T + [2.0 * k, 0, 0])
    return np.stack(out)


def _objects():
    rng = np.random.default_rng(5)
    # a base and many identical small parts (small next to the base: two samplings of one are
    # within 1e-4), then boxes a few percent apart next to a base (pairs on both sides of 1e-4)
    pegs = [(3.0, 3.0, 0.05)] + [(0.1, 0.1, 0.3)] * 14
    near = [(4.0, 4.0, 0.05)] + [
        (0.6, 0.2, 0.1),
        (0.63, 0.2, 0.1),
        (0.66, 0.21, 0.1),
        (0.7, 0.2, 0.1),
        (0.6, 0.2, 0.14),
        (0.75, 0.25, 0.1),
    ]
    distinct = [tuple(sorted(rng.uniform(0.05, 1.0, 3), reverse=True)) for _ in range(14)]
    mixed = pegs[:6] + near[:4] + distinct[:4] + [(0.1, 0.1, 0.3)] * 3
    return {"pegs": pegs, "near": near, "distinct": distinct, "mixed": mixed}


def test_candidate_search_equals_registering_every_pair(monkeypatch):
    import aw_eval.equivalence as eq

    st = ProtocolSettings(n_surface=96, n_fps=96, max_iters=30)
    calls = []
    real = eq.pair_cd

    def counted(*args, **kwargs):
        calls.append(kwargs.get("decide", False))
        return real(*args, **kwargs)

    monkeypatch.setattr(eq, "pair_cd", counted)
    seen_sizes = set()
    for name, extents in _objects().items():
        clouds = _boxes_object(extents, 96, seed=len(name))
        divisor = max(float(np.linalg.norm(e)) for e in extents)
        calls.clear()
        fast = eq.equivalence_groups(clouds, divisor, st, show_progress=False, workers=2)  # threads: the same groups
        n_fast = len(calls)
        assert fast == eq.equivalence_groups_all_pairs(clouds, divisor, st), name
        assert n_fast < len(calls) - n_fast, name  # fewer registrations than the all-pairs path's
        seen_sizes |= {len(g) for g in fast}
        if name == "near":  # pair CDs from 0.7e-4 to 1.5e-4: joined by a chain of edges under 1e-4
            assert fast == [[0], [1, 2, 3, 4, 5, 6]]
    assert max(seen_sizes) >= 10 and 1 in seen_sizes  # a big group of identical parts, and loners


@pytest.mark.parametrize("workers", [1, 2])
def test_near_threshold_chain_is_joined_as_by_every_pair(workers):
    # a ~ b and b ~ c within 1e-4, a and c not: the candidate order must not split the chain
    a, b, c, rng = _chain()
    far = rng.normal(size=(30, 3)) * [0.3, 0.3, 0.3]
    st = ProtocolSettings(n_surface=30, n_fps=30, max_iters=30)
    clouds = np.stack([c, far, a, b])
    from aw_eval.equivalence import equivalence_groups_all_pairs

    assert (
        equivalence_groups(clouds, 1.0, st, show_progress=False, workers=workers)
        == [[0, 2, 3], [1]]
        == equivalence_groups_all_pairs(clouds, 1.0, st)
    )
