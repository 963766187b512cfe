"""Scene operations with the semantics of Table A-2, against hand-computed expectations (issue 2, point 2)."""

import copy
import math

import numpy as np
import pytest
import trimesh

from aw.camera import Camera
from aw.pose import quat_to_matrix
from aw.scene import MAX_GROUP_NAME, PartInfo, Scene, SceneError, scene_from_meshes

S = math.sqrt(0.5)
RX90 = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
RY90 = np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])
RZ90 = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])


def make_scene(camera: Camera | None = None) -> Scene:
    parts = [
        PartInfo(pid, f"part {pid}", np.array([-0.1, -0.2, -0.3]), np.array([0.1, 0.2, 0.3]))
        for pid in ("p1", "p2", "p3")
    ]
    poses = {"p1": [1, 0, 0, 1, 0, 0, 0], "p2": [0, 1, 0, 1, 0, 0, 0], "p3": [0, 0, 1, 1, 0, 0, 0]}
    return Scene(parts, poses, camera=camera)


def front_camera() -> Camera:
    """yaw 0, pitch 0: the camera sits on +X looking along -X; right = +Y, up = +Z, forward = -X."""
    return Camera(target=np.zeros(3), yaw=0.0, pitch=0.0, distance=3.0)


def pos(scene, pid):
    return scene.poses[pid][:3]


def rot(scene, pid):
    return quat_to_matrix(scene.poses[pid][3:])


def snapshot(scene: Scene):
    return (
        {pid: p.tobytes() for pid, p in scene.poses.items()},
        [(g.id, g.name, list(g.members)) for g in scene.groups.values()],
        scene.camera.target.tobytes(),
        (scene.camera.yaw, scene.camera.pitch, scene.camera.distance),
        scene._next_group,
    )


# ---------------------------------------------------------------- construction
def test_construction_validates():
    info = PartInfo("a", "a", np.zeros(3), np.ones(3))
    with pytest.raises(SceneError):
        Scene([])
    with pytest.raises(SceneError, match="unique"):
        Scene([info, info])
    with pytest.raises(SceneError, match="unknown"):
        Scene([info], {"b": [0, 0, 0, 1, 0, 0, 0]})
    with pytest.raises(SceneError, match="zero-length"):
        Scene([info], {"a": [0, 0, 0, 0, 0, 0, 0]})
    with pytest.raises(SceneError, match="non-finite"):
        Scene([info], {"a": [0, math.nan, 0, 1, 0, 0, 0]})
    s = Scene([info], {"a": [1, 2, 3, -2, 0, 0, 0]})
    np.testing.assert_array_equal(s.poses["a"], [1, 2, 3, 1, 0, 0, 0])
    # Identity by default, and a camera that frames the parts' boxes.
    s = Scene([info])
    np.testing.assert_array_equal(s.poses["a"], [0, 0, 0, 1, 0, 0, 0])
    np.testing.assert_allclose(s.camera.target, [0.5, 0.5, 0.5])


def test_scene_from_meshes_uses_mesh_bounds():
    box = trimesh.creation.box([1.0, 2.0, 3.0])
    s = scene_from_meshes(["p01", "p02"], [box, box.copy()])
    assert s.part_ids == ["p01", "p02"]
    rec = s.object_record("p02")
    assert rec["extents"] == [1.0, 2.0, 3.0]
    assert rec["local_bounds"] == {"min": [-0.5, -1.0, -1.5], "max": [0.5, 1.0, 1.5]}
    assert rec["position"] == [0.0, 0.0, 0.0] and rec["quaternion"] == [1.0, 0.0, 0.0, 0.0]
    assert set(rec) == {"id", "name", "position", "quaternion", "extents", "local_bounds", "groups"}


# ---------------------------------------------------------------- translate
def test_translate_world():
    s = make_scene()
    before = snapshot(s)
    assert s.translate(["p1"], [0.1, 0.2, 0.3]) == ["p1"]
    np.testing.assert_allclose(pos(s, "p1"), [1.1, 0.2, 0.3], atol=1e-15)
    np.testing.assert_array_equal(s.poses["p1"][3:], [1, 0, 0, 0])
    assert s.poses["p2"].tobytes() == before[0]["p2"] and s.poses["p3"].tobytes() == before[0]["p3"]
    assert s.translate(["p1"], [0, 0, 0]) == []


def test_translate_camera_axes():
    s = make_scene(front_camera())
    # delta (1, 2, 3) along right (+Y), up (+Z), forward (-X).
    s.translate(["p2"], [1.0, 2.0, 3.0], space="camera")
    np.testing.assert_allclose(pos(s, "p2"), [0 - 3.0, 1 + 1.0, 0 + 2.0], atol=1e-15)


def test_translate_camera_frame_after_orbit():
    s = make_scene()  # default camera: yaw -60, pitch 35
    s.camera = Camera(target=np.zeros(3))
    cam = s.move_camera(yaw=90)
    assert cam.yaw == pytest.approx(30.0)
    y, p = math.radians(30.0), math.radians(35.0)
    right = [-math.sin(y), math.cos(y), 0.0]
    up = [-math.sin(p) * math.cos(y), -math.sin(p) * math.sin(y), math.cos(p)]
    forward = [-math.cos(p) * math.cos(y), -math.cos(p) * math.sin(y), -math.sin(p)]
    s.translate(["p1"], [1, 0, 0], space="camera")
    np.testing.assert_allclose(pos(s, "p1"), np.add([1, 0, 0], right), atol=1e-12)
    s.translate(["p2"], [0, 1, 0], space="camera")
    np.testing.assert_allclose(pos(s, "p2"), np.add([0, 1, 0], up), atol=1e-12)
    s.translate(["p3"], [0, 0, 2], space="camera")
    np.testing.assert_allclose(pos(s, "p3"), np.add([0, 0, 1], 2 * np.array(forward)), atol=1e-12)


# ---------------------------------------------------------------- rotate
def test_rotate_x_then_y_then_z_world_hand_matrix():
    s = make_scene()
    # X 90 then Y 90 (fixed axes): M = Ry(90) @ Rx(90).
    m_xy = np.array([[0.0, 1, 0], [0, 0, -1], [-1, 0, 0]])
    assert s.rotate(["p2"], [90, 90, 0], pivot=[0, 0, 0]) == ["p2"]
    np.testing.assert_allclose(rot(s, "p2"), m_xy, atol=1e-15)
    np.testing.assert_allclose(pos(s, "p2"), [1.0, 0.0, 0.0], atol=1e-15)  # (0,1,0) -X-> (0,0,1) -Y-> (1,0,0)
    # X 90 then Z 90: M = Rz(90) @ Rx(90).
    m_xz = np.array([[0.0, 0, 1], [1, 0, 0], [0, 1, 0]])
    s.rotate(["p3"], [90, 0, 90], pivot=[0, 0, 0])
    np.testing.assert_allclose(rot(s, "p3"), m_xz, atol=1e-15)
    np.testing.assert_allclose(pos(s, "p3"), m_xz @ [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(
        s.rotation_matrix([30, -45, 60]),
        s.rotation_matrix([0, 0, 60]) @ s.rotation_matrix([0, -45, 0]) @ s.rotation_matrix([30, 0, 0]),
        atol=1e-15,
    )


def test_rotate_premultiplies_existing_orientation():
    s = make_scene()
    s.set_pose("p1", quaternion=[S, 0, 0, S])  # Rz(90)
    s.rotate(["p1"], [90, 0, 0])
    np.testing.assert_allclose(rot(s, "p1"), RX90 @ RZ90, atol=1e-15)
    np.testing.assert_allclose(pos(s, "p1"), [1, 0, 0], atol=1e-15)  # single part: pivot is its own origin
    assert s.poses["p1"][3] >= 0


def test_rotate_default_pivot_is_mean_of_selected_origins():
    s = make_scene()
    s.rotate(["p1", "p2"], [0, 0, 180])  # pivot (0.5, 0.5, 0)
    np.testing.assert_allclose(pos(s, "p1"), [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(pos(s, "p2"), [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(np.abs(s.poses["p1"][3:]), [0, 0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(pos(s, "p3"), [0, 0, 1], atol=0)


def test_rotate_explicit_pivot():
    s = make_scene()
    s.rotate(["p3"], [90, 0, 0], pivot=[0, 0, 0])
    np.testing.assert_allclose(pos(s, "p3"), [0, -1, 0], atol=1e-15)
    s = make_scene()
    s.rotate(["p1"], [0, 0, 90], pivot=[1, 1, 0])
    np.testing.assert_allclose(pos(s, "p1"), [2, 1, 0], atol=1e-15)  # (0,-1) about the pivot -> (1,0)


def test_rotate_camera_axes():
    # right = +Y, up = +Z, forward = -X.
    for angles, expect in (([90, 0, 0], RY90), ([0, 90, 0], RZ90), ([0, 0, 90], RX90.T)):
        s = make_scene(front_camera())
        s.rotate(["p1"], angles, space="camera")
        np.testing.assert_allclose(rot(s, "p1"), expect, atol=1e-15)
    # X (right) first, then Y (up): Rz(90) @ Ry(90) in world terms.
    s = make_scene(front_camera())
    s.rotate(["p1"], [90, 90, 0], space="camera")
    np.testing.assert_allclose(rot(s, "p1"), RZ90 @ RY90, atol=1e-15)


def test_rotate_zero_angles_changes_nothing():
    s = make_scene()
    s.rotate(["p1", "p2"], [10, 20, 30])
    before = snapshot(s)
    assert s.rotate(["p1", "p2"], [0, 0, 0]) == []
    assert snapshot(s) == before


def test_rotate_360_keeps_pose():
    s = make_scene()
    s.rotate(["p1", "p2"], [360, 0, 0])
    np.testing.assert_allclose(pos(s, "p1"), [1, 0, 0], atol=1e-14)
    np.testing.assert_allclose(rot(s, "p1"), np.eye(3), atol=1e-14)


# ---------------------------------------------------------------- groups
def test_group_selection_everywhere_and_nothing_moves():
    s = make_scene()
    before = snapshot(s)
    g = s.group(["p1", "p2"], name="legs")
    assert (g.id, g.name, g.members) == ("g1", "legs", ["p1", "p2"])
    assert snapshot(s)[0] == before[0]  # grouping moves nothing
    assert s.resolve(["g1"]) == ["p1", "p2"]
    assert s.resolve(["p2", "g1"]) == ["p2", "p1"]  # unique, selection order kept
    assert s.object_record("p1")["groups"] == ["g1"] and s.object_record("p3")["groups"] == []
    assert s.group_record("g1") == {"id": "g1", "name": "legs", "members": ["p1", "p2"]}
    # translate by group
    assert sorted(s.translate(["g1"], [0, 0, 1])) == ["p1", "p2"]
    np.testing.assert_allclose(pos(s, "p1"), [1, 0, 1])
    np.testing.assert_allclose(pos(s, "p2"), [0, 1, 1])
    np.testing.assert_allclose(pos(s, "p3"), [0, 0, 1])
    # rotate by group: default pivot = mean of the members' origins (0.5, 0.5, 1)
    s.rotate(["g1"], [0, 0, 180])
    np.testing.assert_allclose(pos(s, "p1"), [0, 1, 1], atol=1e-15)
    np.testing.assert_allclose(pos(s, "p2"), [1, 0, 1], atol=1e-15)
    # a group plus one of its own members counts each part once
    s.rotate(["g1", "p1"], [0, 0, 180])
    np.testing.assert_allclose(pos(s, "p1"), [1, 0, 1], atol=1e-15)
    # a group plus another part: pivot over all three
    s2 = make_scene()
    s2.group(["p1", "p2"])
    s2.rotate(["g1", "p3"], [0, 0, 180])  # pivot (1/3, 1/3, 1/3)
    np.testing.assert_allclose(pos(s2, "p3"), [2 / 3, 2 / 3, 1], atol=1e-15)
    # groups of groups flatten to parts
    g2 = s.group(["g1", "p3"])
    assert g2.id == "g2" and g2.name == "g2" and g2.members == ["p1", "p2", "p3"]
    # ungroup: nothing moves, the ids are gone
    mid = snapshot(s)[0]
    assert s.ungroup(["g1", "g2"]) == ["g1", "g2"]
    assert snapshot(s)[0] == mid and s.groups == {}
    with pytest.raises(SceneError):
        s.resolve(["g1"])
    # ids are never reused
    assert s.group(["p1"]).id == "g3"


def test_group_ids_avoid_part_ids():
    parts = [PartInfo(pid, pid, np.zeros(3), np.ones(3)) for pid in ("g1", "g2", "p1")]
    s = Scene(parts)
    assert s.group(["g1", "p1"]).id == "g3"


def test_exclusive_group_replaces_overlapping_groups():
    s = make_scene()
    s.group(["p1", "p2"])
    s.group(["p3"])  # the default rule allows one member and overlapping groups
    with pytest.raises(SceneError, match="at least two objects"):
        s.group(["p3"], exclusive=True)
    with pytest.raises(SceneError, match="at least two objects"):
        s.group(["g2"], exclusive=True)  # a group id counts its members: one here
    g = s.group(["p2", "p3"], exclusive=True)
    assert list(s.groups) == [g.id] and g.members == ["p2", "p3"]
    with pytest.raises(SceneError, match="exclusive"):
        s.group(["p1", "p2"], exclusive="yes")
    assert list(s.groups) == [g.id]


def test_set_pose_rejects_group_ids_with_a_hint():
    s = make_scene()
    s.group(["p1", "p2"])
    with pytest.raises(SceneError, match="group id"):
        s.set_pose("g1", position=[0, 0, 0])


# ---------------------------------------------------------------- set_pose
def test_set_pose_position_and_or_quaternion():
    s = make_scene()
    assert s.set_pose("p1", position=[0.5, -0.5, 2.0]) == ["p1"]
    np.testing.assert_array_equal(s.poses["p1"], [0.5, -0.5, 2.0, 1, 0, 0, 0])
    assert s.set_pose("p1", quaternion=[0, 0, 0, 3.0]) == ["p1"]  # normalized
    np.testing.assert_array_equal(s.poses["p1"], [0.5, -0.5, 2.0, 0, 0, 0, 1])
    s.set_pose("p1", quaternion=[-1.0, 0, 0, -1.0])  # normalized, sign made w >= 0
    np.testing.assert_allclose(s.poses["p1"][3:], [S, 0, 0, S], atol=1e-15)
    s.set_pose("p2", position=[1, 2, 3], quaternion=[0, 2.0, 0, 0])
    np.testing.assert_array_equal(s.poses["p2"], [1, 2, 3, 0, 1, 0, 0])
    assert s.set_pose("p2", position=[1, 2, 3]) == []  # no change reported


# ---------------------------------------------------------------- camera
def test_move_camera_orbit_zoom_pan():
    s = make_scene(Camera(target=np.zeros(3), yaw=170.0, pitch=80.0, distance=2.0))
    cam = s.move_camera(yaw=20)
    assert cam.yaw == pytest.approx(-170.0)  # wrapped to (-180, 180]
    cam = s.move_camera(pitch=10)
    assert cam.pitch == 85.0  # clamped
    cam = s.move_camera(pitch=-85)
    assert cam.pitch == 0.0
    cam = s.move_camera(yaw=-10)
    assert cam.yaw == 180.0  # -180 is reported as 180
    cam = s.move_camera(zoom=0.25)
    assert cam.distance == 0.5
    cam = s.move_camera(zoom=4)
    assert cam.distance == 2.0
    # Pan along the view's right and up (yaw 180, pitch 0: right = -Y, up = +Z).
    cam = s.move_camera(right=1.0, up=2.0)
    np.testing.assert_allclose(cam.target, [0, -1, 2], atol=1e-15)
    # Pan uses the axes before the orbit in the same call.
    cam = s.move_camera(yaw=90, right=1.0)
    np.testing.assert_allclose(cam.target, [0, -2, 2], atol=1e-15)
    assert cam.yaw == pytest.approx(-90.0)
    # Omitted (None) arguments change nothing; the camera never moves parts.
    before = snapshot(s)
    s.move_camera(yaw=None, pitch=None, zoom=None, right=None, up=None)
    assert snapshot(s) == before


def test_move_camera_range_edges_are_allowed():
    s = make_scene()
    s.move_camera(yaw=180, pitch=85, zoom=4)
    s.move_camera(yaw=-180, pitch=-85, zoom=0.25)


# ---------------------------------------------------------------- all-or-nothing
def _prepared_scene():
    s = make_scene()
    s.group(["p1", "p2"], name="pair")
    s.rotate(["p3"], [10, 20, 30])
    return s


INVALID = [
    # selection
    ("translate", (["nope"], [1, 0, 0])),
    ("translate", (["p1", "nope"], [1, 0, 0])),
    ("translate", ([], [1, 0, 0])),
    ("translate", (["p1", "p1"], [1, 0, 0])),
    ("translate", ("p1", [1, 0, 0])),
    ("translate", ([1], [1, 0, 0])),
    ("translate", (None, [1, 0, 0])),
    ("translate", ({"p1": 1}, [1, 0, 0])),
    # numbers
    ("translate", (["p1"], [math.nan, 0, 0])),
    ("translate", (["p1"], [0, math.inf, 0])),
    ("translate", (["p1"], [0, 0, 1e300])),
    ("translate", (["p1"], [0, 0, 1001])),
    ("translate", (["p1"], [1, 0])),
    ("translate", (["p1"], [1, 0, 0, 0])),
    ("translate", (["p1"], "100")),
    ("translate", (["p1"], [True, 0, 0])),
    ("translate", (["p1"], ["1", 0, 0])),
    ("translate", (["p1"], None)),
    ("translate", (["g1"], [999.5, 0, 0])),  # p1 would end beyond 1000 (p2 alone would not)
    # space
    ("translate", (["p1"], [1, 0, 0], "local")),
    ("translate", (["p1"], [1, 0, 0], None)),
    ("translate", (["p1"], [1, 0, 0], ["world"])),
    ("translate", (["p1"], [1, 0, 0], np.array(["world"]))),
    ("rotate", (["p1"], [90, 0, 0], "Camera")),
    # rotate
    ("rotate", (["nope", "p1"], [90, 0, 0])),
    ("rotate", (["p1"], [math.nan, 0, 0])),
    ("rotate", (["p1"], [0, 0, 1e6])),
    ("rotate", (["p1"], [90, 0])),
    ("rotate", (["p1"], [90, 0, 0], "world", [0, 0])),
    ("rotate", (["p1"], [90, 0, 0], "world", [0, math.inf, 0])),
    ("rotate", (["p1"], [90, 0, 0], "world", [0, 0, 1e9])),
    ("rotate", (["p1"], [90, 0, 0], "world", "origin")),
    ("rotate", (["p1"], [180, 0, 0], "world", [0, 600, 0])),  # p1 would land at y = 1200
    # set_pose
    ("set_pose", ("nope",), {"position": [0, 0, 0]}),
    ("set_pose", ("g1",), {"position": [0, 0, 0]}),
    ("set_pose", (["p1"],), {"position": [0, 0, 0]}),
    ("set_pose", ("p1",), {}),
    ("set_pose", ("p1",), {"quaternion": [0, 0, 0, 0]}),
    ("set_pose", ("p1",), {"quaternion": [1e-12, 0, 0, 0]}),
    ("set_pose", ("p1",), {"quaternion": [math.nan, 0, 0, 1]}),
    ("set_pose", ("p1",), {"quaternion": [1, 0, 0]}),
    ("set_pose", ("p1",), {"position": [0, 0, 0], "quaternion": [0, 0, 0, 0]}),  # valid position, bad quaternion
    ("set_pose", ("p1",), {"position": [math.inf, 0, 0], "quaternion": [1, 0, 0, 0]}),
    ("set_pose", ("p1",), {"position": [0, 0, 2000]}),
    ("set_pose", ("p1",), {"position": [0, 0]}),
    # groups
    ("group", (["p1", "p3"],), {"name": "x" * (MAX_GROUP_NAME + 1)}),
    ("group", (["p1", "p3"],), {"name": 5}),
    ("group", (["p1", "nope"],)),
    ("group", ([],)),
    ("group", (["p3", "p3"],)),
    ("ungroup", (["p1"],)),
    ("ungroup", (["g1", "nope"],)),
    ("ungroup", ([],)),
    ("ungroup", (["g1", "g1"],)),
    ("ungroup", ([1],)),
    ("ungroup", ([["g1"]],)),
    ("ungroup", ("g1",)),
    # camera
    ("move_camera", (), {"yaw": 180.5}),
    ("move_camera", (), {"yaw": math.nan}),
    ("move_camera", (), {"pitch": 86}),
    ("move_camera", (), {"pitch": -90}),
    ("move_camera", (), {"zoom": 0.2}),
    ("move_camera", (), {"zoom": 4.5}),
    ("move_camera", (), {"zoom": 0}),
    ("move_camera", (), {"zoom": "2"}),
    ("move_camera", (), {"yaw": True}),
    ("move_camera", (), {"right": math.inf}),
    ("move_camera", (), {"up": 1e4}),
    ("move_camera", (), {"yaw": 10, "zoom": 10}),  # valid yaw, invalid zoom: nothing applied
]


@pytest.mark.parametrize("op,args,kwargs", [(e[0], e[1], e[2] if len(e) > 2 else {}) for e in INVALID])
def test_invalid_requests_change_nothing(op, args, kwargs):
    s = _prepared_scene()
    before = snapshot(s)
    camera_before = copy.deepcopy(s.camera)
    with pytest.raises(SceneError):
        getattr(s, op)(*args, **kwargs)
    assert snapshot(s) == before
    assert s.camera.to_dict() == camera_before.to_dict()


def test_camera_limits_all_or_nothing():
    s = make_scene()
    s.move_camera(right=900)
    before = snapshot(s)
    with pytest.raises(SceneError, match="target"):
        s.move_camera(right=900)  # the target would pass 1000 units
    assert snapshot(s) == before
    s = make_scene(Camera(target=np.zeros(3), distance=300.0))
    before = snapshot(s)
    with pytest.raises(SceneError, match="distance"):
        s.move_camera(yaw=30, zoom=4)  # 1200 units away: refused, the yaw is not applied either
    assert snapshot(s) == before
    assert s.move_camera(zoom=3).distance == 900.0


def test_error_messages_name_the_problem_without_geometry():
    s = make_scene()
    with pytest.raises(SceneError, match="unknown id 'zz'"):
        s.translate(["zz"], [0, 0, 0])
    with pytest.raises(SceneError, match="unique"):
        s.translate(["p1", "p1"], [0, 0, 0])
    with pytest.raises(SceneError, match="non-finite"):
        s.translate(["p1"], [math.nan, 0, 0])
    with pytest.raises(SceneError, match="space"):
        s.translate(["p1"], [0, 0, 0], space="local")
    with pytest.raises(SceneError, match="200 characters"):
        s.group(["p1"], name="n" * 201)
    with pytest.raises(SceneError, match=r"zoom must lie in \[0.25, 4\]"):
        s.move_camera(zoom=5)
