"""The orbit camera: axes, OpenGL pose, framing and validation."""

import math

import numpy as np
import pytest

from aw.camera import IMAGE_HEIGHT, IMAGE_WIDTH, VERTICAL_FOV_DEG, Camera, wrap_degrees


def test_axes_hand_values():
    # yaw 0, pitch 0: the camera sits on +X looking along -X.
    c = Camera(target=np.array([1.0, 2.0, 3.0]), yaw=0.0, pitch=0.0, distance=2.0)
    np.testing.assert_allclose(c.forward, [-1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(c.right, [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(c.up, [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(c.position, [3, 2, 3], atol=1e-15)
    # yaw 90, pitch 30: camera on the +Y side, above, looking down at the target.
    c = Camera(target=np.zeros(3), yaw=90.0, pitch=30.0, distance=2.0)
    np.testing.assert_allclose(c.position, [0, 2 * math.cos(math.radians(30)), 1.0], atol=1e-15)
    np.testing.assert_allclose(c.right, [-1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(c.up, [0, -0.5, math.cos(math.radians(30))], atol=1e-15)
    np.testing.assert_allclose(c.axes(), np.stack([c.right, c.up, c.forward], axis=1))


@pytest.mark.parametrize("yaw,pitch", [(-60, 35), (0, 0), (179, -84), (-180, 85), (33.3, -10)])
def test_axes_orthonormal_and_pose_matrix(yaw, pitch):
    c = Camera(target=np.array([0.3, -0.2, 0.1]), yaw=yaw, pitch=pitch, distance=1.7)
    a = c.axes()
    np.testing.assert_allclose(a.T @ a, np.eye(3), atol=1e-12)
    # (right, up, forward) is left-handed: right x up = -forward (OpenGL's camera Z is backward).
    np.testing.assert_allclose(np.cross(c.right, c.up), -c.forward, atol=1e-12)
    assert c.right[2] == 0.0 and c.up[2] > 0  # horizon stays level, up points skyward
    m = c.pose_matrix()
    np.testing.assert_allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.det(m[:3, :3]) == pytest.approx(1.0)
    np.testing.assert_allclose(m[:3, 2], -c.forward, atol=1e-15)
    np.testing.assert_allclose(m[:3, 3], c.target - 1.7 * c.forward, atol=1e-15)
    # The target projects to the image centre: in camera coordinates it lies straight ahead.
    local = np.linalg.inv(m) @ np.r_[c.target, 1.0]
    np.testing.assert_allclose(local[:3], [0, 0, -1.7], atol=1e-12)


def test_framing_fits_the_box_in_the_image():
    lo, hi = np.array([-1.0, -0.5, 0.0]), np.array([2.0, 0.5, 0.4])
    c = Camera.framing(lo, hi)
    np.testing.assert_allclose(c.target, (lo + hi) / 2)
    view = np.linalg.inv(c.pose_matrix())
    f = 1.0 / math.tan(math.radians(VERTICAL_FOV_DEG) / 2)
    aspect = IMAGE_WIDTH / IMAGE_HEIGHT
    for corner in [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]:
        p = view @ np.r_[corner, 1.0]
        assert p[2] < 0  # in front of the camera
        ndc_x, ndc_y = f * p[0] / (-p[2]) / aspect, f * p[1] / (-p[2])
        assert abs(ndc_x) < 1 and abs(ndc_y) < 1
    # Degenerate box (a point) still gives a usable camera.
    c = Camera.framing(np.ones(3), np.ones(3))
    assert c.distance > 0


def test_dict_round_trip_and_describe():
    c = Camera(target=np.array([0.1, 0.2, 0.3]), yaw=12.5, pitch=-20.0, distance=4.0)
    d = c.to_dict()
    assert d == {"target": [0.1, 0.2, 0.3], "yaw": 12.5, "pitch": -20.0, "distance": 4.0}
    assert Camera.from_dict(d).to_dict() == d
    desc = c.describe()
    assert desc["vertical_fov_deg"] == 38.0 and desc["image_size"] == [1024, 768]
    np.testing.assert_allclose(desc["forward"], c.forward)
    cc = c.copy()
    cc.target[0] = 9.0
    assert c.target[0] == 0.1


@pytest.mark.parametrize(
    "kwargs",
    [
        {"pitch": 90.0},
        {"pitch": -90.0},
        {"pitch": math.nan},
        {"yaw": math.inf},
        {"distance": 0.0},
        {"distance": -1.0},
        {"target": [0.0, 0.0]},
        {"target": [0.0, math.nan, 0.0]},
        {"target": "abc"},
        {"yaw": "left"},
    ],
)
def test_invalid_camera_raises(kwargs):
    with pytest.raises(ValueError):
        Camera(**kwargs)


def test_wrap_degrees():
    assert wrap_degrees(190.0) == -170.0
    assert wrap_degrees(-180.0) == 180.0
    assert wrap_degrees(180.0) == 180.0
    assert wrap_degrees(540.0) == 180.0
    assert wrap_degrees(-190.0) == 170.0
    assert wrap_degrees(0.0) == 0.0
