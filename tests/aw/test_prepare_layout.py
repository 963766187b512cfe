"""The XY scatter: shelf packing, free spots for added parts, box separation."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from aw.prepare.layout import box_gap, free_spot, shelf_pack


def test_shelf_pack_hand_computed():
    # two unit squares, gap 0.1: row width = sqrt(2 * 1.1^2 * 4/3) = 1.796 < 1 + 0.1 + 1, so two rows
    corners = shelf_pack([[1.0, 1.0], [1.0, 1.0]], [0, 1], gap=0.1)
    np.testing.assert_allclose(corners, [[-0.5, -1.05], [-0.5, 0.05]])
    # three boxes, the order decides the rows; a short box is centred in its row's depth
    corners = shelf_pack([[1.0, 2.0], [1.0, 1.0], [3.0, 0.5]], [1, 0, 2], gap=0.0)
    # row width = max(3, sqrt((2 + 1 + 1.5) * 4/3)) = 3: row 1 = parts 1, 0 (depth 2), row 2 = part 2
    lo = np.array([-1.5, -1.25])
    np.testing.assert_allclose(corners[1], lo + [0.0, 0.5])
    np.testing.assert_allclose(corners[0], lo + [1.0, 0.0])
    np.testing.assert_allclose(corners[2], lo + [0.0, 2.0])


def test_shelf_pack_separates_random_boxes():
    rng = np.random.default_rng(3)
    for _ in range(20):
        n = int(rng.integers(1, 25))
        sizes = rng.uniform(0.01, 1.0, size=(n, 2)) ** 2
        corners = shelf_pack(sizes, rng.permutation(n), gap=0.02)
        for i, j in itertools.combinations(range(n), 2):
            assert box_gap(corners[i], corners[i] + sizes[i], corners[j], corners[j] + sizes[j]) >= 0.02 - 1e-12
        lo, hi = corners.min(axis=0), (corners + sizes).max(axis=0)
        np.testing.assert_allclose(lo + hi, 0.0, atol=1e-12)  # centred on the origin


def test_free_spot_is_clear_of_every_box():
    rng = np.random.default_rng(0)
    sizes = rng.uniform(0.05, 0.5, size=(8, 2))
    corners = shelf_pack(sizes, range(8), gap=0.02)
    for seed in range(12):
        new = rng.uniform(0.05, 0.8, size=2)
        c = free_spot(corners, corners + sizes, new, np.random.default_rng(seed), gap=0.02)
        for lo, size in zip(corners, sizes, strict=True):
            assert box_gap(c, c + new, lo, lo + size) >= 0.02 - 1e-12


def test_box_gap_hand_computed():
    assert box_gap([0, 0, 0], [1, 1, 1], [1.5, 0, 0], [2, 1, 1]) == pytest.approx(0.5)
    assert box_gap([0, 0, 0], [1, 1, 1], [0.2, 3, 0], [2, 4, 1]) == pytest.approx(2.0)
    assert box_gap([0, 0, 0], [1, 1, 1], [0.5, 0.5, 0.5], [2, 2, 2]) < 0


def test_shelf_pack_rejects_bad_input():
    with pytest.raises(ValueError, match="permutation"):
        shelf_pack([[1, 1], [1, 1]], [0, 0])
    with pytest.raises(ValueError, match="shape"):
        shelf_pack([[1, 1, 1]], [0])
    with pytest.raises(ValueError, match="finite"):
        shelf_pack([[np.nan, 1]], [0])
