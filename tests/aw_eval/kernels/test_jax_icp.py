"""The XLA ICP and part Chamfer kernels against the plain reference, on the CPU at small sizes."""

from __future__ import annotations

import numpy as np
import pytest

from aw_eval.kernels import jax_icp
from aw_eval.kernels.jax_icp import fit_tile, icp_batch, max_lanes, nearest_in_leaves, part_cd_batch
from aw_eval.kernels.leafbox import brute_first_min, build_part_leaves
from aw_eval.reference import chamfer as ref_chamfer
from aw_eval.reference import icp as ref_icp
from aw_eval.reference import pca_starts


def _clouds(seed: int, n: int = 40):
    rng = np.random.default_rng(seed)
    target = rng.normal(size=(n, 3)) * [1.0, 0.5, 0.2]
    q = rng.normal(size=3) * 0.4
    c, s = np.cos(q), np.sin(q)
    rot = np.array([[c[0], -s[0], 0], [s[0], c[0], 0], [0, 0, 1]]) @ np.array(
        [[1, 0, 0], [0, c[1], -s[1]], [0, s[1], c[1]]]
    )
    pred = (target - 0.3) @ rot + rng.normal(size=(n, 3)) * 0.02
    return pred, target


@pytest.mark.parametrize("candidates", [1, 8])
def test_icp_batch_equals_the_reference_from_every_start_of_every_cloud(candidates):
    """Two clouds x 24 starts in one call: every lane's best objective and transform equal the
    reference ICP's from that start, whether the leaves certify most queries (8 of them read)
    or send many to the brute-force path (1 read)."""
    clouds = [_clouds(0), _clouds(1)]
    starts = [pca_starts(p, t) for p, t in clouds]
    target = clouds[0][1]
    preds = np.stack([p for p, _ in clouds])
    r0 = np.array([[r for r, _ in s] for s in starts])
    t0 = np.array([[t for _, t in s] for s in starts])
    stats = {}
    obj, rot, trans = icp_batch(preds, target, r0, t0, max_iters=30, tol=1e-9, stats=stats, candidates=candidates)
    # rounds drop the lanes that stopped: far fewer lanes computed than 48 lanes x 30 iterations
    assert stats["lane_iterations"] <= stats["lanes_iterated"] < 48 * 30 and stats["rounds"] >= 2
    assert stats["brute_queries"] > 0 or candidates > 1
    assert obj.shape == (2, 24) and rot.shape == (2, 24, 3, 3) and trans.shape == (2, 24, 3)
    for c in range(2):
        for k in range(24):
            want, r, t = ref_icp(preds[c], target, r0[c, k], t0[c, k], 30, 1e-9)
            assert abs(obj[c, k] - want) <= 1e-9 * want + 1e-15, (c, k)
            assert np.allclose(rot[c, k], r, atol=1e-9) and np.allclose(trans[c, k], t, atol=1e-9), (c, k)


def test_part_cd_batch_equals_the_reference_chamfer_of_every_pair():
    rng = np.random.default_rng(2)
    moved = rng.normal(size=(2, 3, 20, 3))
    target = rng.normal(size=(3, 20, 3))
    got = part_cd_batch(moved, target, tile=8)
    want = np.array([[[ref_chamfer(moved[c, i], target[j]) for j in range(3)] for i in range(3)] for c in range(2)])
    assert np.allclose(got, want, rtol=1e-12, atol=0)
    some = part_cd_batch(moved, target, [(0, 0), (1, 2), (2, 1)], tile=8)
    listed = np.zeros((3, 3), bool)
    listed[[0, 1, 2], [0, 2, 1]] = True
    assert np.allclose(some[:, listed], want[:, listed], rtol=1e-12, atol=0) and np.all(np.isinf(some[:, ~listed]))


@pytest.mark.parametrize("candidates", [2, 8])
def test_leaf_lookup_with_its_fallback_is_the_brute_force_first_minimum(candidates):
    """Two parts (a sheet and a dense blob with duplicated points) and a third identical to the
    first, leaves of 4 points, queries near, across and far outside the clouds: every answer is
    the brute-force first minimum over the joined clouds (lowest index on exact ties), the
    uncertified queries by the fallback; queries far above the sheet, where the boxes' distances
    agree to float32's rounding, stay exact."""
    rng = np.random.default_rng(4)
    sheet = np.c_[rng.uniform(-1, 1, (60, 2)), np.zeros(60)]
    blob = rng.normal(size=(60, 3)) * 0.02 + 0.3
    blob[:10] = blob[10:20]  # exact duplicates within a part
    sheet[:5] = sheet[5:10]
    parts = np.stack([sheet, blob, sheet])  # part 2 identical to part 0
    ref = parts.reshape(-1, 3).copy()
    ref[65:70] = ref[:5]  # duplicates across parts: the lower index (part 0) must win
    parts = ref.reshape(3, 60, 3)
    leaves = build_part_leaves(parts, leaf=4)
    x = np.concatenate(
        [
            ref[rng.integers(180, size=150)] + rng.normal(size=(150, 3)) * 0.01,
            rng.uniform(-1.2, 1.2, (100, 3)),
            rng.normal(size=(6, 3)) * 30.0,
            ref[:10],
            # far above the sheet: many boxes within float32's rounding of each other
            np.c_[rng.uniform(-1, 1, (8, 2)), np.full(8, 1e3)],
        ]
    ).reshape(2, -1, 3)
    idx, brute = nearest_in_leaves(x, ref, leaves, candidates=candidates)
    want = brute_first_min(x.reshape(-1, 3), ref).reshape(idx.shape)
    assert np.array_equal(idx, want)
    assert np.all(idx < 120)  # never the identical third part's copy
    assert brute < idx.size / 2 and (brute > 0 or candidates > 2)  # with 2 leaves read, some take the fallback


def test_tiles_shrink_to_fit_the_distance_budget():
    assert fit_tile(1, 1000) == 256
    assert fit_tile(3200, 8000) == 8  # never below 8 rows
    t = fit_tile(64, 8000)
    assert t < 256 and 64 * t * 8000 <= 1 << 26 < 64 * 2 * t * 8000


def test_lanes_past_the_budget_run_in_several_calls_with_the_same_results(monkeypatch):
    """48 lanes (2 clouds x 24 starts) with a lane budget of 8 lanes a call: every call (the
    starts' and each round's) holds at most 8 lanes, and every lane ends as in one call (to rounding)."""
    clouds = [_clouds(0), _clouds(1)]
    starts = [pca_starts(p, t) for p, t in clouds]
    target, preds = clouds[0][1], np.stack([p for p, _ in clouds])
    r0 = np.array([[r for r, _ in s] for s in starts])
    t0 = np.array([[t for _, t in s] for s in starts])
    whole = icp_batch(preds, target, r0, t0, max_iters=30, tol=1e-9)
    monkeypatch.setattr(jax_icp, "LANE_ELEMENTS", 8 * jax_icp.LANE_FLOATS * (40 + 40))
    assert max_lanes(40, 40) == 8
    sizes = []
    real_pad = jax_icp._pad
    monkeypatch.setattr(jax_icp, "_pad", lambda ids: sizes.append(len(real_pad(ids))) or real_pad(ids))
    split = icp_batch(preds, target, r0, t0, max_iters=30, tol=1e-9)
    assert max(sizes) == 8 and len(sizes) > 6  # 6 calls for the starts alone
    for a, b in zip(whole, split, strict=True):
        assert np.allclose(a, b, rtol=1e-12, atol=1e-15)  # (other shapes compile to other roundings)


def test_lane_budget_is_a_power_of_two_within_the_elements():
    assert max_lanes(10, 10) == 1 << 19  # tiny clouds: many lanes a call
    for n, m in ((1000, 8000), (20_000, 20_000), (10**9, 10**9)):
        lanes = max_lanes(n, m)
        assert lanes & (lanes - 1) == 0 and lanes >= jax_icp.MIN_LANES
        assert lanes == jax_icp.MIN_LANES or lanes * jax_icp.LANE_FLOATS * (n + m) <= jax_icp.LANE_ELEMENTS
        assert 2 * lanes * jax_icp.LANE_FLOATS * (n + m) > jax_icp.LANE_ELEMENTS


def test_a_call_holds_memory_in_proportion_to_its_lanes_points(monkeypatch):
    """The compiled ICP of 64 lanes of a 32-part task (1,600 points a side, backward lookups in
    every part's leaves) needs at most LANE_FLOATS float64 per lane and point of either cloud
    (the small leaf budget set here aside): no buffer of every lane's target in every part's
    frame, which grows with the parts squared (it ran a 20-part task out of a GPU's memory)."""
    from aw_eval.fixtures import make_points_geometry
    from aw_eval.settings import ProtocolSettings

    monkeypatch.setattr(jax_icp, "LEAF_ELEMENTS", 1 << 16)
    monkeypatch.setattr(jax_icp, "accelerator_present", lambda: False)
    jax, jnp = jax_icp.jax_modules()
    parts, n, lanes = 32, 50, 64
    geom, _ = make_points_geometry(parts, n, seed=parts, settings=ProtocolSettings(n_fps=n, n_surface=4096))
    index = geom.index()
    target_leaves, part_leaves = index.part_leaves(geom.divisor)
    target = index.target
    init, round_ = jax_icp._compiled_round.__wrapped__(100, 1e-9, 8, True)
    dev = jnp.asarray
    common = (
        dev(target[None]),
        dev(target),
        tuple(map(dev, target_leaves)),
        tuple(map(dev, part_leaves)),
        dev(np.zeros((1, parts, 3, 4))),
        dev(np.zeros(lanes, np.int32)),
    )
    rot, trans = dev(np.tile(np.eye(3), (lanes, 1, 1))), dev(np.zeros((lanes, 3)))
    m = len(target)
    state = (
        dev(np.ones(lanes, bool)),
        dev(np.zeros(lanes, np.int64)),
        dev(np.zeros(lanes)),
        dev(np.zeros((lanes, m), np.int32)),
        dev(np.zeros((lanes, m), np.int32)),
        dev(np.zeros(lanes)),
        rot,
        trans,
    )
    allowed = lanes * jax_icp.LANE_FLOATS * (m + m) * 8 + 8 * 4 * (1 << 16)
    for compiled in (init.lower(*common, rot, trans).compile(), round_.lower(*common, state).compile()):
        used = compiled.memory_analysis()
        if used is None:
            pytest.skip("this JAX build reports no compiled memory")
        assert used.temp_size_in_bytes <= allowed
