"""Fracture protocol (source-level comparisons) against hand-computed cases."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from aw.pose import compose_poses, matrix_from_euler_xyz, matrix_to_quat
from aw_eval.fracture import (
    allocate_samples,
    fracture_divisor,
    fracture_metrics,
    fracture_metrics_from_samples,
    wrapped_euler_error,
)


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
    # 20 each, then the area share of 5000 - 60 = 4940 (truncated), remainder to the largest
    n = allocate_samples([1.0, 1.0, 0.001])
    assert n.tolist() == [2490, 2488, 22] and n.sum() == 5000
    n = allocate_samples([3.0, 1.0])
    assert n.tolist() == [3740, 1260]
    with pytest.raises(ValueError):
        allocate_samples([1.0] * 300)
    with pytest.raises(ValueError):
        allocate_samples([1.0, 0.0])


def _box(size, centre=(0, 0, 0)):
    m = trimesh.creation.box(extents=size)
    return np.asarray(m.vertices) + np.asarray(centre, float), [tuple(f) for f in np.asarray(m.faces).tolist()]


def test_fracture_metrics_from_meshes_scale_and_determinism():
    a, b = _box([2.0, 0.5, 0.5]), _box([0.5, 0.5, 0.5])
    targets = np.stack([_pose([0, 0, 0]), _pose([1.25, 0, 0])])
    pred = targets.copy()
    pred[1] = _pose([1.25, 0.2, 0])
    divisor = fracture_divisor([a[0], b[0]], np.eye(4))  # largest source extent 2, task scale 1
    m1 = fracture_metrics([a, b], ["a", "b"], pred, targets, "d", "s", divisor)
    m2 = fracture_metrics([a, b], ["a", "b"], pred, targets, "d", "s", divisor)
    assert divisor == 2.0 and m1.scale == 2.0 and m1.counts.sum() == 5000 and m1.anchor == 0
    assert m1.te == m2.te and m1.cd == m2.cd
    assert m1.part_te[1] == pytest.approx(np.sqrt(0.1**2 / 3), rel=1e-9)  # 0.2 / divisor 2
    assert fracture_divisor([a[0] / 4, b[0] / 4], np.diag([0.5, 0.5, 0.5, 1.0])) == 0.5  # extent below 1 counts as 1


# ---------------------------------------------------------------- the official procedure, written out


def _stream(seed, *names):
    digest = hashlib.sha256(json.dumps([seed, *names], separators=(",", ":")).encode()).digest()
    return np.random.Generator(np.random.PCG64(int.from_bytes(digest[:16], "little")))


def _quat_matrix(q):
    return Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()


def _restored(pred):
    """``(xmat (P, 3, 3), xpos (P, 3))`` of a MuJoCo world's free bodies whose joints hold the
    poses ``pred (P, 7)``, after ``mj_forward``: what the official ``final_poses`` reads."""
    import mujoco

    bodies = "".join(
        f'<body name="part-{k + 1:04d}"><freejoint/><geom type="box" size="0.1 0.1 0.1"/></body>'
        for k in range(len(pred))
    )
    model = mujoco.MjModel.from_xml_string(f"<mujoco><worldbody>{bodies}</worldbody></mujoco>")
    data = mujoco.MjData(model)
    data.qpos[:] = np.asarray(pred, dtype=np.float64).reshape(-1)
    mujoco.mj_forward(model, data)
    return data.xmat[1:].reshape(-1, 3, 3).copy(), data.xpos[1:].copy()


def _by_hand(meshes, ids, pred, target, dataset, sample_id, divisor):
    areas = []
    for v, f in meshes:
        xyz = v[np.array(f)]
        total = np.linalg.norm(np.cross(xyz[:, 1] - xyz[:, 0], xyz[:, 2] - xyz[:, 0]), axis=1).sum() / 2
        areas.append(total)
    share = 5000 - 20 * len(meshes)
    counts = [20 + int(share * a / sum(areas)) for a in areas]
    counts[int(np.argmax(counts))] += 5000 - sum(counts)
    pts, pp, tp = [], [], []
    for (v, f), pid, n, (xmat, xpos), qt in zip(
        meshes, ids, counts, zip(*_restored(pred), strict=True), target, strict=True
    ):
        rng = _stream(42, dataset, sample_id, pid, "garf-evaluation")
        xyz = v[np.array(f)]
        area = np.linalg.norm(np.cross(xyz[:, 1] - xyz[:, 0], xyz[:, 2] - xyz[:, 0]), axis=1)
        tri = rng.choice(len(xyz), size=n, p=area / area.sum())
        u = rng.random((n, 2))
        r = np.sqrt(u[:, 0])
        w = np.column_stack((1 - r, r * (1 - u[:, 1]), r * u[:, 1]))
        cloud = np.einsum("ni,nij->nj", w, xyz[tri])
        c = cloud.mean(0)
        pts.append((cloud - c) / divisor)
        pp.append((xmat, (xmat @ c + xpos) / divisor))
        tp.append((_quat_matrix(qt[3:]), (c @ _quat_matrix(qt[3:]).T + qt[:3]) / divisor))
    k = int(np.argmax(counts))
    g = tp[k][0] @ pp[k][0].T
    h = tp[k][1] - g @ pp[k][1]
    al = [(g @ r, g @ t + h) for r, t in pp]
    P = [x @ r.T + t for x, (r, t) in zip(pts, al, strict=True)]
    T = [x @ r.T + t for x, (r, t) in zip(pts, tp, strict=True)]
    allp, allt = np.concatenate(P), np.concatenate(T)
    rows = []
    for x, y, (ra, ta), (rt, tt) in zip(P, T, al, tp, strict=True):
        d = np.abs(
            Rotation.from_matrix(ra).as_euler("XYZ", degrees=True)
            - Rotation.from_matrix(rt).as_euler("XYZ", degrees=True)
        )
        d = np.minimum(d, 360 - d)
        xy, yx = cKDTree(y).query(x)[0], cKDTree(x).query(y)[0]
        cd = float(np.mean(xy * xy) + np.mean(yx * yx))
        rows.append(
            (
                np.sqrt(np.mean(d**2)),
                np.sqrt(np.mean((ta - tt) ** 2)),
                float(cd < 0.01),
                np.mean(cKDTree(allt).query(x)[0] ** 2) + np.mean(cKDTree(allp).query(y)[0] ** 2),
            )
        )
    return counts, [float(np.mean([row[k] for row in rows])) for k in range(4)]


def test_fracture_metrics_equal_the_official_procedure_number_for_number():
    """Predicted rotations as the official evaluation reads them (MuJoCo's ``xmat`` of the
    restored state), target rotations from SciPy: RE, TE, PA and CD to the last bit."""
    rng = np.random.default_rng(5)
    big = _box([0.9, 0.5, 0.3], (0, 0, 0.15))
    mid = _box([0.4, 0.5, 0.2], (0.65, 0, 0.1))
    small = _box([0.2, 0.2, 0.1], (0, 0.4, 0.35))
    meshes, ids = [big, mid, small], ["f0", "f1", "f2"]
    target = np.stack(
        [_pose([0.1, 0, 0], (10, 20, 30)), _pose([0, 0.2, 0], (-5, 0, 90)), _pose([0, 0, 0.3], (170, -30, 5))]
    )
    pred = np.stack([_pose(rng.normal(size=3), rng.uniform(-180, 180, 3)) for _ in range(3)])
    pred[2] = target[2] + [0.001, 0, 0, 0, 0, 0, 0]
    pred[1, 3:] *= 1 + 4e-16  # a stored quaternion a few bits off unit length, as states hold them
    divisor = fracture_divisor([v for v, _ in meshes], np.diag([1.7, 1.7, 1.7, 1.0]))
    got = fracture_metrics(meshes, ids, pred, target, "AssemblyWorld/fantastic-breaks", "mug_3", divisor)
    counts, (re, te, pa, cd) = _by_hand(meshes, ids, pred, target, "AssemblyWorld/fantastic-breaks", "mug_3", divisor)
    assert got.counts.tolist() == counts and sum(counts) == 5000 and got.anchor == 0
    assert (got.re, got.te, got.pa, got.cd) == (re, te, pa, cd)
    assert 0 < got.pa < 1
