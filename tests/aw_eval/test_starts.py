"""The registration starts: the reference's numbers exactly, in the protocol's order."""

from __future__ import annotations

import numpy as np

from aw.pose import quat_to_matrix
from aw_eval import reference as ref
from aw_eval.starts import pca_starts, same_id_starts, start_frame


def test_starts_equal_the_reference_bitwise():
    """The batched starts (24 PCA starts, then one same-ID start per part) are the reference's
    numbers exactly: exact mode's registration starts where the protocol's does."""
    for seed in range(5):
        rng = np.random.default_rng(seed)
        pred, target = rng.normal(size=(200, 3)) * [3, 2, 1], rng.normal(size=(200, 3)) * [1, 2, 3]
        poses = np.concatenate([rng.normal(size=(4, 3)), rng.normal(size=(4, 4))], axis=1)
        target_poses = np.concatenate([rng.normal(size=(4, 3)), rng.normal(size=(4, 4))], axis=1)
        r_pca, t_pca = pca_starts(start_frame(pred), start_frame(target))
        r_part, t_part = same_id_starts(quat_to_matrix(poses[:, 3:]), poses, quat_to_matrix(target_poses[:, 3:]),
                                        target_poses, 1.7)
        r0, t0 = np.concatenate([r_pca, r_part]), np.concatenate([t_pca, t_part])
        want = ref.pca_starts(pred, target) + ref.part_starts(poses, target_poses, 1.7)
        assert len(r0) == len(want) == 28
        for k, (r, t) in enumerate(want):
            assert np.array_equal(r0[k], r) and np.array_equal(t0[k], t)
