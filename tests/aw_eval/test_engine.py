"""Engine pieces that must match the reference bit for bit."""

from __future__ import annotations

import numpy as np

from aw.pose import pca_frame
from aw_eval import reference as ref
from aw_eval.engine import starts_for


def test_starts_equal_the_reference_bitwise():
    """The batched starts (24 PCA starts, then one same-ID start per part) are the reference's
    numbers exactly: exact mode's registration starts where the protocol's does."""
    for seed in range(5):
        rng = np.random.default_rng(seed)
        pred, target = rng.normal(size=(200, 3)) * [3, 2, 1], rng.normal(size=(200, 3)) * [1, 2, 3]
        poses = np.concatenate([rng.normal(size=(4, 3)), rng.normal(size=(4, 4))], axis=1)
        target_poses = np.concatenate([rng.normal(size=(4, 3)), rng.normal(size=(4, 4))], axis=1)
        r0, t0 = starts_for(pred, pca_frame(target), poses, target_poses, 1.7)
        want = ref.pca_starts(pred, target) + ref.part_starts(poses, target_poses, 1.7)
        assert len(r0) == len(want) == 28
        for k, (r, t) in enumerate(want):
            assert np.array_equal(r0[k], r) and np.array_equal(t0[k], t)
    r0, t0 = starts_for(pred, pca_frame(target), np.zeros((0, 7)), np.zeros((0, 7)), 1.0)
    assert r0.shape == (24, 3, 3) and t0.shape == (24, 3)
