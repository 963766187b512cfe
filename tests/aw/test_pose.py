"""Rigid-pose math of aw.pose against hand-computed values (issue 2, point 1)."""

import itertools
import math

import numpy as np
import pytest

from aw.pose import (
    IDENTITY_POSE,
    Pose,
    apply_pose,
    as_finite,
    compose_poses,
    cube_rotations,
    euler_xyz_from_matrix,
    invert_pose,
    matrices_to_poses,
    matrix_from_euler_xyz,
    matrix_from_xyz_sequence,
    matrix_to_quat,
    normalize_quaternion,
    pca_frame,
    poses_to_matrices,
    quat_from_axis_angle,
    quat_multiply,
    quat_to_axis_angle,
    quat_to_matrix,
    rotation_about_axis,
    rotation_angle_deg,
)

S = math.sqrt(0.5)
# 90 degrees about Z: x -> y, y -> -x.
QZ90 = np.array([S, 0.0, 0.0, S])
RZ90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
# 90 degrees about X: y -> z, z -> -y.
QX90 = np.array([S, S, 0.0, 0.0])
RX90 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def random_quats(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def random_rotations(rng, n):
    return quat_to_matrix(random_quats(rng, n))


# ---------------------------------------------------------------- quaternions and matrices
def test_quat_to_matrix_is_the_textbook_formula_bitwise():
    """The matrices are the unit-quaternion formula evaluated entry by entry, bit for bit (every
    score's arithmetic builds on them), for any batch shape and any quaternion scale."""
    rng = np.random.default_rng(5)
    for shape in [(4,), (1, 4), (6, 4), (3, 5, 4), (0, 4)]:
        q = rng.normal(size=shape) * 10.0 ** rng.uniform(-4, 4, size=shape[:-1] + (1,))
        u = q / np.linalg.norm(q, axis=-1, keepdims=True)
        w, x, y, z = np.moveaxis(u, -1, 0)
        want = np.stack(
            [
                np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
            ],
            axis=-2,
        )
        got = quat_to_matrix(q)
        assert got.shape == shape[:-1] + (3, 3) and np.array_equal(got, want)


def test_quat_to_matrix_hand_values():
    np.testing.assert_allclose(quat_to_matrix(QZ90), RZ90, atol=1e-15)
    np.testing.assert_allclose(quat_to_matrix(QX90), RX90, atol=1e-15)
    np.testing.assert_allclose(quat_to_matrix([1, 0, 0, 0]), np.eye(3), atol=0)
    # 180 degrees about Y: x -> -x, z -> -z.
    np.testing.assert_allclose(quat_to_matrix([0, 0, 1, 0]), np.diag([-1.0, 1.0, -1.0]), atol=0)
    # Non-unit input is normalized first.
    np.testing.assert_allclose(quat_to_matrix(3.0 * QZ90), RZ90, atol=1e-15)


def test_quat_to_matrix_is_batched():
    rng = np.random.default_rng(0)
    q = random_quats(rng, 24).reshape(2, 3, 4, 4)
    m = quat_to_matrix(q)
    assert m.shape == (2, 3, 4, 3, 3)
    np.testing.assert_allclose(m[1, 2, 3], quat_to_matrix(q[1, 2, 3]), atol=0)
    np.testing.assert_allclose(np.einsum("...ji,...jk->...ik", m, m), np.broadcast_to(np.eye(3), m.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(m), 1.0, atol=1e-14)


def test_matrix_to_quat_hand_values_and_sign_convention():
    np.testing.assert_allclose(matrix_to_quat(RZ90), QZ90, atol=1e-15)
    np.testing.assert_allclose(matrix_to_quat(RX90), QX90, atol=1e-15)
    np.testing.assert_allclose(matrix_to_quat(np.eye(3)), [1, 0, 0, 0], atol=0)
    # 180 degrees about X: w = 0, the vector part points along +X.
    np.testing.assert_allclose(matrix_to_quat(np.diag([1.0, -1.0, -1.0])), [0, 1, 0, 0], atol=1e-15)
    # -q and q are the same rotation; the result always has w >= 0.
    rng = np.random.default_rng(1)
    q = random_quats(rng, 200)
    back = matrix_to_quat(quat_to_matrix(q))
    assert np.all(back[:, 0] >= 0)
    np.testing.assert_allclose(back, np.where(q[:, :1] < 0, -q, q), atol=1e-12)


def test_matrix_quat_round_trip_batched_and_near_pi():
    rng = np.random.default_rng(2)
    m = random_rotations(rng, 60).reshape(3, 20, 3, 3)
    np.testing.assert_allclose(quat_to_matrix(matrix_to_quat(m)), m, atol=1e-12)
    # Rotations by almost 180 degrees exercise every branch of Shepperd's method.
    for axis in np.eye(3):
        for angle in (math.pi, math.pi - 1e-9, math.pi - 1e-3):
            r = quat_to_matrix(quat_from_axis_angle(axis, angle))
            np.testing.assert_allclose(quat_to_matrix(matrix_to_quat(r)), r, atol=1e-12)


def test_quat_multiply_composes_rotations():
    # b first, then a: matrix of a*b is Ra @ Rb.
    np.testing.assert_allclose(quat_to_matrix(quat_multiply(QZ90, QX90)), RZ90 @ RX90, atol=1e-15)
    rng = np.random.default_rng(3)
    a, b = random_quats(rng, 10), random_quats(rng, 10)
    np.testing.assert_allclose(quat_to_matrix(quat_multiply(a, b)), quat_to_matrix(a) @ quat_to_matrix(b), atol=1e-13)


def test_axis_angle_both_ways():
    np.testing.assert_allclose(quat_from_axis_angle([0, 0, 2.0], math.pi / 2), QZ90, atol=1e-15)
    axis, angle = quat_to_axis_angle(QZ90)
    np.testing.assert_allclose(axis, [0, 0, 1], atol=1e-15)
    assert angle == pytest.approx(math.pi / 2, abs=1e-15)
    # -q is the same rotation: same axis and angle (angle within [0, pi]).
    axis, angle = quat_to_axis_angle(-QZ90)
    np.testing.assert_allclose(axis, [0, 0, 1], atol=1e-15)
    assert angle == pytest.approx(math.pi / 2, abs=1e-15)
    # No rotation: angle 0, axis +X by convention.
    axis, angle = quat_to_axis_angle([1, 0, 0, 0])
    np.testing.assert_array_equal(axis, [1, 0, 0])
    assert angle == 0.0
    assert rotation_angle_deg(QX90) == pytest.approx(90.0, abs=1e-12)
    # One angle for many axes, and many angles for one axis.
    q = quat_from_axis_angle(np.eye(3), math.pi / 2)
    np.testing.assert_allclose(q[2], QZ90, atol=1e-15)
    q = quat_from_axis_angle([0, 0, 1], [0.0, math.pi / 2])
    np.testing.assert_allclose(q, [[1, 0, 0, 0], QZ90], atol=1e-15)
    # Batched round trip.
    rng = np.random.default_rng(4)
    axes = rng.normal(size=(50, 3))
    angles = rng.uniform(0, math.pi, size=50)
    q = quat_from_axis_angle(axes, angles)
    a2, t2 = quat_to_axis_angle(q)
    np.testing.assert_allclose(t2, angles, atol=1e-12)
    np.testing.assert_allclose(a2, axes / np.linalg.norm(axes, axis=1, keepdims=True), atol=1e-9)


# ---------------------------------------------------------------- Euler angles
def test_euler_xyz_is_intrinsic_rx_ry_rz():
    a, b, c = 0.3, -0.7, 1.1
    rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    rz = np.array([[math.cos(c), -math.sin(c), 0], [math.sin(c), math.cos(c), 0], [0, 0, 1]])
    np.testing.assert_allclose(matrix_from_euler_xyz([a, b, c]), rx @ ry @ rz, atol=1e-15)
    np.testing.assert_allclose(euler_xyz_from_matrix(rx @ ry @ rz), [a, b, c], atol=1e-14)
    # X then Y then Z about fixed axes is the reverse product.
    np.testing.assert_allclose(matrix_from_xyz_sequence(np.degrees([a, b, c])), rz @ ry @ rx, atol=1e-15)
    np.testing.assert_allclose(rotation_about_axis(2, math.pi / 2), RZ90, atol=1e-15)


def test_euler_round_trip_batched():
    rng = np.random.default_rng(5)
    angles = np.stack(
        [rng.uniform(-math.pi, math.pi, 100), rng.uniform(-1.5, 1.5, 100), rng.uniform(-math.pi, math.pi, 100)], axis=1
    ).reshape(4, 25, 3)
    m = matrix_from_euler_xyz(angles)
    assert m.shape == (4, 25, 3, 3)
    np.testing.assert_allclose(euler_xyz_from_matrix(m), angles, atol=1e-12)
    r = random_rotations(rng, 100)
    np.testing.assert_allclose(matrix_from_euler_xyz(euler_xyz_from_matrix(r)), r, atol=1e-12)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_euler_gimbal_lock(sign):
    # At Y = +-90 degrees only X + Z (or X - Z) is defined: Z is reported as 0, X absorbs it.
    a, c = 0.4, 0.25
    m = matrix_from_euler_xyz([a, sign * math.pi / 2, c])
    e = euler_xyz_from_matrix(m)
    assert e[1] == pytest.approx(sign * math.pi / 2, abs=1e-7)
    assert e[2] == 0.0
    assert e[0] == pytest.approx(a + sign * c, abs=1e-7)
    np.testing.assert_allclose(matrix_from_euler_xyz(e), m, atol=1e-12)


# ---------------------------------------------------------------- poses
def test_apply_compose_invert_hand_values():
    pose = np.array([1.0, 2.0, 3.0, *QZ90])
    np.testing.assert_allclose(apply_pose(pose, [[1.0, 0.0, 0.0]]), [[1.0, 3.0, 3.0]], atol=1e-15)
    inv = invert_pose(pose)
    # Inverse of (R, t) is (R^T, -R^T t); R^T t = (2, -1, 3).
    np.testing.assert_allclose(inv, [-2.0, 1.0, -3.0, S, 0.0, 0.0, -S], atol=1e-15)
    np.testing.assert_allclose(compose_poses(pose, inv), IDENTITY_POSE, atol=1e-15)
    # a * b applies b first.
    b = np.array([0.0, 0.0, 1.0, *QX90])
    ab = compose_poses(pose, b)
    p = np.array([[0.0, 1.0, 0.0]])
    np.testing.assert_allclose(apply_pose(ab, p), apply_pose(pose, apply_pose(b, p)), atol=1e-15)
    # Hand: b maps (0,1,0) to (0,0,1)+(0,0,1) = (0,0,2); pose maps that to (1,2,5).
    np.testing.assert_allclose(apply_pose(ab, p), [[1.0, 2.0, 5.0]], atol=1e-15)


def test_pose_functions_batched_and_consistent_with_matrices():
    rng = np.random.default_rng(6)
    poses = np.concatenate([rng.normal(size=(5, 4, 3)), random_quats(rng, 20).reshape(5, 4, 4)], axis=-1)
    pts = rng.normal(size=(5, 4, 30, 3))
    mats = poses_to_matrices(poses)
    assert mats.shape == (5, 4, 4, 4)
    expect = np.einsum("...ij,...nj->...ni", mats[..., :3, :3], pts) + mats[..., None, :3, 3]
    np.testing.assert_allclose(apply_pose(poses, pts), expect, atol=1e-13)
    # One pose per batch entry applied to shared points broadcasts.
    shared = rng.normal(size=(30, 3))
    out = apply_pose(poses[0], shared)
    assert out.shape == (4, 30, 3)
    np.testing.assert_allclose(out[2], apply_pose(poses[0, 2], shared), atol=1e-14)
    other = np.concatenate([rng.normal(size=(5, 4, 3)), random_quats(rng, 20).reshape(5, 4, 4)], axis=-1)
    np.testing.assert_allclose(
        poses_to_matrices(compose_poses(poses, other)), mats @ poses_to_matrices(other), atol=1e-13
    )
    np.testing.assert_allclose(poses_to_matrices(invert_pose(poses)), np.linalg.inv(mats), atol=1e-12)
    back = matrices_to_poses(mats)
    np.testing.assert_allclose(poses_to_matrices(back), mats, atol=1e-13)


def test_pose_class():
    p = Pose.from_array([1, 2, 3, 0, 0, 0, 2.0])  # quaternion normalized on construction
    np.testing.assert_allclose(p.quaternion, [0, 0, 0, 1])
    np.testing.assert_allclose(p.apply([1.0, 0.0, 0.0]), [0.0, 2.0, 3.0], atol=1e-15)
    q = Pose(np.zeros(3), QX90)
    np.testing.assert_allclose(p.compose(q).to_matrix(), p.to_matrix() @ q.to_matrix(), atol=1e-15)
    np.testing.assert_allclose(p.compose(p.inverse()).to_array(), IDENTITY_POSE, atol=1e-15)
    np.testing.assert_allclose(Pose.from_matrix(p.to_matrix()).to_array(), p.to_array(), atol=1e-15)
    assert Pose.identity().to_list() == [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]


# ---------------------------------------------------------------- degenerate input
@pytest.mark.parametrize(
    "call",
    [
        lambda: normalize_quaternion([0, 0, 0, 0]),
        lambda: normalize_quaternion([1e-12, 0, 0, 0]),
        lambda: quat_to_matrix([math.nan, 0, 0, 1]),
        lambda: quat_to_matrix([math.inf, 0, 0, 1]),
        lambda: quat_to_matrix([1, 0, 0]),
        lambda: quat_to_matrix("wxyz"),
        lambda: quat_to_matrix(None),
        lambda: quat_to_matrix([[1, 0, 0, 0], [0, 0, 0, 0]]),
        lambda: matrix_to_quat(np.ones((3, 3))),
        lambda: matrix_to_quat(np.diag([1.0, 1.0, -1.0])),  # a reflection
        lambda: matrix_to_quat(np.full((3, 3), math.nan)),
        lambda: matrix_to_quat(np.eye(4)),
        lambda: euler_xyz_from_matrix(2 * np.eye(3)),
        lambda: matrix_from_euler_xyz([0.1, math.nan, 0.0]),
        lambda: matrix_from_euler_xyz([0.1, 0.2]),
        lambda: quat_from_axis_angle([0, 0, 0], 1.0),
        lambda: quat_from_axis_angle([0, 0, 1], math.inf),
        lambda: apply_pose([0, 0, 0, 0, 0, 0, 0], [[1.0, 2.0, 3.0]]),
        lambda: apply_pose(IDENTITY_POSE, [[1.0, math.nan, 3.0]]),
        lambda: apply_pose(IDENTITY_POSE, [[1.0, 2.0]]),
        lambda: apply_pose([0, 0, 0, 1, 0, 0], [[1.0, 2.0, 3.0]]),
        lambda: compose_poses(IDENTITY_POSE, [0, 0, math.inf, 1, 0, 0, 0]),
        lambda: invert_pose([0, 0, 0, 0, 0, 0, 0]),
        lambda: poses_to_matrices([1, 2, 3]),
        lambda: Pose(np.zeros(3), np.zeros(4)),
        lambda: Pose.from_array([0, 0, 0, 1, 0, 0]),
        lambda: rotation_about_axis(3, 1.0),
        lambda: pca_frame(np.zeros((0, 3))),
        lambda: pca_frame(np.zeros((4, 2))),
        lambda: pca_frame([[0, 0, 0], [1, math.nan, 0]]),
        lambda: as_finite([1j, 2, 3]),
    ],
)
def test_degenerate_input_raises_value_error(call):
    with pytest.raises(ValueError):
        call()


def test_error_messages_say_what_is_wrong():
    with pytest.raises(ValueError, match="zero length"):
        normalize_quaternion([0, 0, 0, 0])
    with pytest.raises(ValueError, match="non-finite"):
        quat_to_matrix([math.nan, 0, 0, 1])
    with pytest.raises(ValueError, match="trailing shape"):
        apply_pose(IDENTITY_POSE, [[1.0, 2.0]])
    with pytest.raises(ValueError, match="proper rotation"):
        matrix_to_quat(np.diag([1.0, 1.0, -1.0]))


# ---------------------------------------------------------------- PCA frame
def anisotropic_cloud(rng, n=400):
    # Standard deviations 3 (X), 2 (Y), 0.5 (Z), made skewed so third moments fix the signs.
    base = rng.normal(size=(n, 3)) * [3.0, 2.0, 0.5]
    base += np.abs(rng.normal(size=(n, 3))) ** 2 * [0.8, 0.6, 0.2]
    return base


def test_pca_frame_axis_order_handedness_and_equivariance():
    rng = np.random.default_rng(7)
    pts = anisotropic_cloud(rng)
    origin, axes = pca_frame(pts)
    np.testing.assert_allclose(origin, pts.mean(axis=0), atol=1e-12)
    np.testing.assert_allclose(axes.T @ axes, np.eye(3), atol=1e-12)
    assert np.linalg.det(axes) == pytest.approx(1.0, abs=1e-12)
    # Largest spread first, smallest along local Z.
    local = (pts - origin) @ axes
    var = local.var(axis=0)
    assert var[0] > var[1] > var[2]
    assert np.argmax(np.abs(axes[:, 0])) == 0 and np.argmax(np.abs(axes[:, 2])) == 2
    # Signs: the third moment along e1 and e2 is positive.
    assert np.mean(local[:, 0] ** 3) > 0 and np.mean(local[:, 1] ** 3) > 0
    # The frame moves with the points: rotate and shift the cloud, the frame follows exactly.
    for r in random_rotations(rng, 5):
        t = rng.normal(size=3)
        o2, a2 = pca_frame(pts @ r.T + t)
        np.testing.assert_allclose(o2, r @ origin + t, atol=1e-10)
        np.testing.assert_allclose(a2, r @ axes, atol=1e-9)


def test_pca_frame_handedness_for_mirrored_input():
    # A mirrored cloud still gets a proper (right-handed) frame: e3 = e1 x e2, never a reflection.
    rng = np.random.default_rng(8)
    pts = anisotropic_cloud(rng) * [1.0, 1.0, -1.0]
    _, axes = pca_frame(pts)
    np.testing.assert_allclose(axes[:, 2], np.cross(axes[:, 0], axes[:, 1]), atol=1e-15)
    assert np.linalg.det(axes) == pytest.approx(1.0, abs=1e-12)


def test_pca_frame_deterministic_signs_on_symmetric_box():
    # Box corners: third moments vanish; the first point decides each sign.
    corners = np.array(list(itertools.product([-2.0, 2.0], [-1.0, 1.0], [-0.5, 0.5])))
    _, axes = pca_frame(corners)
    # First corner is (-2, -1, -0.5): projections on e1 and e2 must be positive.
    np.testing.assert_allclose(axes, np.diag([-1.0, -1.0, 1.0]), atol=1e-12)
    _, again = pca_frame(corners.copy())
    np.testing.assert_array_equal(axes, again)
    # Reordering the points (new first point) changes the choice in the documented way.
    _, flipped = pca_frame(corners[::-1])
    np.testing.assert_allclose(flipped, np.diag([1.0, 1.0, 1.0]), atol=1e-12)


def test_pca_frame_repeated_eigenvalues_follow_the_points():
    # A square plate (equal in-plane spread): e1 points along the first point's in-plane direction.
    ring = np.array([[math.cos(t), math.sin(t), 0.0] for t in np.linspace(0, 2 * math.pi, 8, endpoint=False)])
    plate = np.concatenate([ring + [0, 0, 0.05], ring - [0, 0, 0.05]])
    rng = np.random.default_rng(9)
    r = random_rotations(rng, 1)[0]
    _, axes = pca_frame(plate)
    _, axes_r = pca_frame(plate @ r.T)
    np.testing.assert_allclose(axes[:, 0], [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(abs(axes[2, 2]), 1.0, atol=1e-12)
    np.testing.assert_allclose(axes_r, r @ axes, atol=1e-9)
    # Fully isotropic set (regular octahedron): still proper and deterministic.
    octa = np.concatenate([np.eye(3), -np.eye(3)])[[0, 4, 2, 3, 1, 5]]
    _, a = pca_frame(octa)
    assert np.linalg.det(a) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(a[:, 0], [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(a[:, 1], [0.0, -1.0, 0.0], atol=1e-12)


def test_pca_frame_degenerate_sets():
    # Coincident points: identity axes at the point.
    origin, axes = pca_frame(np.full((5, 3), 3.0))
    np.testing.assert_allclose(origin, [3.0, 3.0, 3.0])
    np.testing.assert_array_equal(axes, np.eye(3))
    origin, axes = pca_frame([[1.0, 2.0, 3.0]])
    np.testing.assert_array_equal(axes, np.eye(3))
    # Collinear: e1 along the line (first point positive), e2 by the fixed rule (least aligned world axis).
    line = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 2.0, 0.0], [5.0, 5.0, 0.0]])
    _, axes = pca_frame(line)
    np.testing.assert_allclose(axes[:, 0], [S, S, 0.0], atol=1e-12)  # third moment along the line > 0
    np.testing.assert_allclose(axes[:, 1], [0.0, 0.0, 1.0], atol=1e-12)
    assert np.linalg.det(axes) == pytest.approx(1.0, abs=1e-12)
    # Planar set: smallest axis is the plane normal.
    rng = np.random.default_rng(10)
    planar = np.c_[rng.normal(size=(50, 2)) * [2.0, 1.0], np.zeros(50)]
    _, axes = pca_frame(planar)
    np.testing.assert_allclose(abs(axes[2, 2]), 1.0, atol=1e-12)


# ---------------------------------------------------------------- cube group
def test_cube_rotations_are_the_proper_cube_group():
    mats = cube_rotations()
    assert mats.shape == (24, 3, 3)
    np.testing.assert_array_equal(mats[0], np.eye(3))
    # Proper: orthonormal signed permutation matrices with determinant +1.
    np.testing.assert_allclose(np.einsum("kji,kjl->kil", mats, mats), np.broadcast_to(np.eye(3), (24, 3, 3)), atol=0)
    np.testing.assert_allclose(np.linalg.det(mats), 1.0, atol=1e-12)
    assert set(np.unique(mats)) == {-1.0, 0.0, 1.0}
    # Distinct.
    keys = {m.astype(int).tobytes() for m in mats}
    assert len(keys) == 24
    # A group: closed under products and inverses.
    for a in mats:
        assert a.T.astype(int).tobytes() in keys
        for b in mats:
            assert (a @ b).astype(int).tobytes() in keys
