"""Fracture protocol (source-level comparisons) against hand-computed cases."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from aw.pose import compose_poses, matrix_from_euler_xyz, matrix_to_quat
from aw_eval.fracture import allocate_samples, fracture_metrics, fracture_metrics_from_samples, wrapped_euler_error


def _pose(pos, euler_deg=(0.0, 0.0, 0.0)):
    q = matrix_to_quat(matrix_from_euler_xyz(np.radians(euler_deg)))
    return np.concatenate([np.asarray(pos, dtype=float), q])


def _samples(rng, counts):
    out = []
    for n in counts:
        s = rng.random((n, 3)) * 0.2
        out.append(s - s.mean(axis=0))  # centroid at the part origin: rotations keep it fixed
    return out


@pytest.fixture()
def parts():
    rng = np.random.default_rng(0)
    samples = _samples(rng, [300, 120, 80])  # part 0 is the anchor (most samples)
    targets = np.stack([_pose([0, 0, 0]), _pose([0.5, 0, 0]), _pose([0, 0.5, 0])])
    return samples, targets


def test_perfect_and_globally_moved_predictions_are_exact(parts):
    samples, targets = parts
    m = fracture_metrics_from_samples(samples, targets, targets)
    assert m.re == 0 and m.te < 1e-15 and m.pa == 1.0 and m.cd < 1e-25 and m.anchor == 0
    g = _pose([3.0, -1.0, 2.0], (40.0, -25.0, 70.0))
    moved = compose_poses(np.broadcast_to(g, targets.shape), targets)
    m2 = fracture_metrics_from_samples(samples, moved, targets)
    assert m2.re < 1e-9 and m2.te < 1e-12 and m2.pa == 1.0 and m2.cd < 1e-20


def test_known_rotation_error(parts):
    samples, targets = parts
    pred = targets.copy()
    pred[1] = _pose([0.5, 0, 0], (30.0, 0.0, 0.0))  # 30 deg about X, about the part's centroid
    m = fracture_metrics_from_samples(samples, pred, targets)
    assert m.part_re[0] == 0 and m.part_re[2] == 0
    assert m.part_re[1] == pytest.approx(np.sqrt(30.0**2 / 3))
    assert m.re == pytest.approx(np.sqrt(300.0) / 3)  # anchor included in the mean
    assert m.te < 1e-12  # the sampled centroid did not move


def test_euler_differences_wrap_across_180():
    a = matrix_from_euler_xyz(np.radians([[179.0, 10.0, -179.5]]))
    b = matrix_from_euler_xyz(np.radians([[-179.0, 10.0, 179.5]]))
    # X: |179 - (-179)| = 358 -> 2; Y: 0; Z: 359 -> 1
    assert wrapped_euler_error(a, b)[0] == pytest.approx(np.sqrt((4.0 + 0.0 + 1.0) / 3))
    assert wrapped_euler_error(b, a)[0] == pytest.approx(np.sqrt(5.0 / 3))


def test_wrapped_rotation_error_in_the_metrics(parts):
    samples, targets = parts
    targets = targets.copy()
    targets[2] = _pose([0, 0.5, 0], (179.0, 0.0, 0.0))
    pred = targets.copy()
    pred[2] = _pose([0, 0.5, 0], (-179.0, 0.0, 0.0))
    m = fracture_metrics_from_samples(samples, pred, targets)
    assert m.part_re[2] == pytest.approx(np.sqrt(4.0 / 3))


def test_known_translation_error_and_strict_pa(parts):
    samples, targets = parts
    pred = targets.copy()
    pred[2] = _pose([0.3, 0.5 - 0.4, 0.0])  # moved by (0.3, -0.4, 0): |d| = 0.5
    m = fracture_metrics_from_samples(samples, pred, targets)
    assert m.part_te[2] == pytest.approx(np.sqrt(0.25 / 3))
    assert m.te == pytest.approx(np.sqrt(0.25 / 3) / 3)
    assert m.pa == pytest.approx(2 / 3)
    assert m.part_cd[2] > 0.01 and m.shape_cd[0] >= 0
    # strict: a part CD exactly at the threshold is not correct
    at = fracture_metrics_from_samples(samples, pred, targets, pa_threshold=float(m.part_cd[2]))
    assert at.pa == pytest.approx(2 / 3)


def test_shape_cd_uses_global_neighbours(parts):
    samples, targets = parts
    pred = targets.copy()
    # two parts trade poses; compare with a plain brute-force statement of the definition
    pred[1], pred[2] = targets[2], targets[1]
    m = fracture_metrics_from_samples(samples, pred, targets)
    from aw.pose import apply_pose

    P = [apply_pose(pred[i], samples[i]) for i in range(3)]
    T = [apply_pose(targets[i], samples[i]) for i in range(3)]
    allp, allt = np.concatenate(P), np.concatenate(T)
    want = []
    for i in range(3):
        f = ((P[i][:, None] - allt[None]) ** 2).sum(-1).min(1).mean()
        b = ((T[i][:, None] - allp[None]) ** 2).sum(-1).min(1).mean()
        want.append(f + b)
    assert np.allclose(m.shape_cd, want) and m.cd == pytest.approx(np.mean(want))


def test_allocation_minimum_and_remainder():
    n = allocate_samples([1.0, 1.0, 0.001])
    assert n.tolist() == [2482, 2498, 20] and n.sum() == 5000
    n = allocate_samples([3.0, 1.0])
    assert n.tolist() == [3750, 1250]
    with pytest.raises(ValueError):
        allocate_samples([1.0] * 300)


def test_fracture_metrics_from_meshes_scale_and_determinism():
    a = trimesh.creation.box(extents=[2.0, 0.5, 0.5])  # e_max = 2 -> scale 2
    b = trimesh.creation.box(extents=[0.5, 0.5, 0.5])
    targets = np.stack([_pose([0, 0, 0]), _pose([1.25, 0, 0])])
    pred = targets.copy()
    pred[1] = _pose([1.25, 0.2, 0])
    m1 = fracture_metrics([a, b], pred, targets)
    m2 = fracture_metrics([a, b], pred, targets)
    assert m1.scale == 2.0 and m1.counts.sum() == 5000 and m1.anchor == 0
    assert m1.te == m2.te and m1.cd == m2.cd
    assert m1.part_te[1] == pytest.approx(np.sqrt(0.1**2 / 3), rel=1e-9)  # 0.2 / scale 2
