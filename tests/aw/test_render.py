"""Offscreen rendering (aw.render) with the real pyrender/EGL stack: size, visibility, colours,
ground reference, change under moves and orbits, determinism, threads and input validation."""

import colorsys
import os
import subprocess
import sys
import textwrap
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
import trimesh

from aw.camera import Camera
from aw.render import (
    BACKGROUND_COLOR,
    OffscreenRenderer,
    RenderError,
    grid_spacing,
    part_colors,
    render_meshes,
)
from aw.render_platform import select_platform

W, H = 320, 240
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])


def baked_parts():
    """Three parts side by side on the XY plane, placements baked in (identity poses)."""
    a = trimesh.creation.box([0.4, 0.3, 0.2])
    a.apply_translation([-0.5, 0.0, 0.1])
    b = trimesh.creation.cylinder(radius=0.12, height=0.35)
    b.apply_translation([0.0, 0.1, 0.175])
    c = trimesh.creation.icosphere(subdivisions=2, radius=0.15)
    c.apply_translation([0.45, -0.1, 0.15])
    return [a, b, c]


@pytest.fixture(scope="module")
def renderer():
    with OffscreenRenderer(baked_parts(), width=W, height=H) as r:
        yield r


def identity_poses(n=3):
    return np.tile(IDENTITY, (n, 1))


def hue(rgb):
    return colorsys.rgb_to_hsv(*np.asarray(rgb, float))[0]


def hue_distance(a, b):
    d = abs(a - b) % 1.0
    return min(d, 1.0 - d)


def interior(mask):
    """Mask pixels whose 4 neighbours are in the mask too (drops anti-aliased edges)."""
    m = mask.copy()
    m[1:, :] &= mask[:-1, :]
    m[:-1, :] &= mask[1:, :]
    m[:, 1:] &= mask[:, :-1]
    m[:, :-1] &= mask[:, 1:]
    return m


# ---------------------------------------------------------------- the picture
def test_full_size_image_of_default_view():
    img = render_meshes(baked_parts())
    assert img.size == (1024, 768) and img.mode == "RGB"
    arr = np.asarray(img)
    # Light background in the top corners (the camera looks down on the parts).
    np.testing.assert_allclose(arr[2, 2] / 255.0, BACKGROUND_COLOR, atol=2 / 255)
    np.testing.assert_allclose(arr[2, -3] / 255.0, BACKGROUND_COLOR, atol=2 / 255)


def test_parts_visible_distinct_from_background_and_in_their_colours(renderer):
    img = np.asarray(renderer.render(identity_poses(), None)).astype(float) / 255.0
    seg = renderer.render_segmentation(identity_poses(), None)
    assert seg.shape == (H, W) and img.shape == (H, W, 3)
    bg = np.asarray(BACKGROUND_COLOR)
    colors = renderer.colors
    for i in range(3):
        mask = interior(seg == i)
        assert mask.sum() > 200, f"part {i} covers only {mask.sum()} pixels"
        pix = img[mask]
        # Clearly different from the background ...
        assert np.median(np.abs(pix - bg).sum(axis=1)) > 0.3
        # ... and in the part's own hue, closer to it than to any other part's.
        h = hue(np.median(pix, axis=0))
        dists = [hue_distance(h, hue(c)) for c in colors]
        assert int(np.argmin(dists)) == i and dists[i] < 0.04, (i, dists)
    # Pixels outside every part are background or ground: no part hue there.
    outside = seg == -1
    assert outside.mean() > 0.4


def test_ground_reference_below_the_parts_and_never_hiding_them(renderer):
    poses = identity_poses()
    seg = renderer.render_segmentation(poses, None)
    img = np.asarray(renderer.render(poses, None)).astype(float) / 255.0
    bg = np.asarray(BACKGROUND_COLOR)
    ground = (seg == -1) & (np.abs(img - bg).sum(axis=2) > 0.05)
    # From above, the ground plane and its grid show around the parts.
    assert ground.sum() > 0.05 * W * H
    # From below (pitch -30), the ground is left out, and every part shows in its colour.
    cam = Camera.framing(*renderer.posed_bounds(poses))
    cam.pitch = -30.0
    below = np.asarray(renderer.render(poses, cam)).astype(float) / 255.0
    seg_below = renderer.render_segmentation(poses, cam)
    away = interior(interior(seg_below == -1))  # not on an anti-aliased part edge
    assert (np.abs(below - bg).sum(axis=2) > 0.05)[away].sum() == 0
    for i in range(3):
        mask = interior(seg_below == i)
        assert mask.sum() > 100
        assert hue_distance(hue(np.median(below[mask], axis=0)), hue(renderer.colors[i])) < 0.04


def test_ground_follows_the_lowest_part(renderer):
    poses = identity_poses()
    lo, _ = renderer.posed_bounds(poses)
    assert lo[2] == pytest.approx(0.0, abs=1e-12)
    lifted = poses.copy()
    lifted[:, 2] += 2.0
    lo2, _ = renderer.posed_bounds(lifted)
    assert lo2[2] == pytest.approx(2.0, abs=1e-12)
    # Lift everything and look with the same relative camera: the picture is the same up to the
    # grid (whose lines stay at fixed world XY), so the ground moved up with the parts.
    cam = Camera.framing(*renderer.posed_bounds(poses))
    cam2 = cam.copy()
    cam2.target = cam2.target + [0, 0, 2.0]
    a = np.asarray(renderer.render(poses, cam)).astype(int)
    b = np.asarray(renderer.render(lifted, cam2)).astype(int)
    # (Identical but for rounding on a few anti-aliased edge pixels.)
    assert (np.abs(a - b).max(axis=2) > 8).mean() < 0.003


def test_picture_changes_when_a_part_moves_or_the_camera_orbits(renderer):
    poses = identity_poses()
    cam = Camera.framing(*renderer.posed_bounds(poses))
    base = np.asarray(renderer.render(poses, cam))
    seg = renderer.render_segmentation(poses, cam)
    moved = poses.copy()
    moved[0, :3] = 0.3 * cam.right
    after = np.asarray(renderer.render(moved, cam))
    seg_after = renderer.render_segmentation(moved, cam)
    assert (np.abs(base.astype(int) - after).sum(axis=2) > 30).sum() > 200
    # Part 0 moved to the right in the image; part 2 did not move.
    c0 = np.argwhere(seg == 0).mean(axis=0)
    c1 = np.argwhere(seg_after == 0).mean(axis=0)
    assert c1[1] > c0[1] + 10
    np.testing.assert_array_equal(seg == 2, seg_after == 2)
    # A rotation of the part changes its silhouette.
    turned = poses.copy()
    turned[0, 3:] = [np.cos(np.pi / 8), 0.0, 0.0, np.sin(np.pi / 8)]
    turned[0, :3] = [-0.5, 0.0, 0.0] - trimesh.transformations.quaternion_matrix(turned[0, 3:])[:3, :3] @ [
        -0.5,
        0.0,
        0.0,
    ]
    assert (renderer.render_segmentation(turned, cam) != seg).sum() > 100
    # Orbit.
    orbit = cam.copy()
    orbit.yaw += 90.0
    assert (np.abs(base.astype(int) - np.asarray(renderer.render(poses, orbit))).sum(axis=2) > 30).sum() > 1000


def test_deterministic_for_the_same_input(renderer):
    poses = identity_poses()
    poses[1, :3] = [0.1, 0.2, 0.3]
    cam = Camera(target=np.array([0.0, 0.0, 0.2]), yaw=30.0, pitch=20.0, distance=2.5)
    a = renderer.render(poses, cam).tobytes()
    renderer.render(identity_poses(), Camera())  # something else in between
    assert renderer.render(poses, cam).tobytes() == a


def test_render_from_other_threads(renderer):
    poses = identity_poses()
    expect = renderer.render(poses, None).tobytes()
    out = {}

    def work(k):
        out[k] = renderer.render(poses, None).tobytes()

    t = threading.Thread(target=work, args=("thread",))
    t.start()
    t.join()
    with ThreadPoolExecutor(max_workers=4) as pool:
        results = list(pool.map(lambda _: renderer.render(poses, None).tobytes(), range(4)))
    assert out["thread"] == expect
    assert all(r == expect for r in results)


def test_renderer_created_in_a_worker_thread():
    meshes = baked_parts()[:1]
    with ThreadPoolExecutor(max_workers=1) as pool:
        r = pool.submit(OffscreenRenderer, meshes, None, 64, 48).result()
    try:
        img = r.render()
        assert img.size == (64, 48)
        assert (r.render_segmentation() == 0).sum() > 20
    finally:
        r.close()


# ---------------------------------------------------------------- colours and grid
def test_part_colors_distinct_stable_and_off_background():
    c30 = part_colors(30)
    assert c30.shape == (30, 3) and c30.min() >= 0 and c30.max() <= 1
    np.testing.assert_array_equal(part_colors(5), c30[:5])
    d = np.linalg.norm(c30[:, None] - c30[None], axis=2) + np.eye(30) * 9
    assert d.min() > 0.15
    assert np.linalg.norm(c30 - BACKGROUND_COLOR, axis=1).min() > 0.3
    assert part_colors(0).shape == (0, 3)
    for bad in (-1, 2.5, "3", True):
        with pytest.raises(ValueError):
            part_colors(bad)


@pytest.mark.parametrize(
    "extent,step", [(1.0, 0.1), (2.4, 0.2), (5.0, 0.5), (0.03, 0.002), (8.0, 1.0), (14.0, 1.0), (16.0, 2.0)]
)
def test_grid_spacing(extent, step):
    assert grid_spacing(extent) == pytest.approx(step)


def test_custom_colors(renderer):
    with OffscreenRenderer(baked_parts()[:2], colors=[[255, 0, 0], [0, 0, 255]], width=96, height=72) as r:
        np.testing.assert_array_equal(r.colors, [[1, 0, 0], [0, 0, 1]])
        img = np.asarray(r.render()).astype(float)
        seg = r.render_segmentation()
        red = img[interior(seg == 0)].mean(axis=0)
        assert red[0] > 2 * red[2]


# ---------------------------------------------------------------- validation and lifecycle
@pytest.mark.parametrize(
    "poses",
    [
        np.zeros((3, 7)),  # zero quaternions
        identity_poses(2),
        identity_poses(3)[:, :6],
        np.where(np.eye(3, 7, dtype=bool), np.nan, identity_poses(3)),
        [[0, 0, 0, 1, 0, 0, 0]] * 2 + [["a"] * 7],
    ],
)
def test_invalid_poses_raise(renderer, poses):
    with pytest.raises(ValueError):
        renderer.render(poses, None)


def test_invalid_construction_and_camera(renderer):
    with pytest.raises(ValueError):
        renderer.render(None, {"yaw": 0})
    for bad in ([], [trimesh.Trimesh()], ["mesh"], trimesh.creation.box()):
        with pytest.raises(ValueError):
            OffscreenRenderer(bad, width=16, height=16)
    with pytest.raises(ValueError, match="shape"):
        OffscreenRenderer(baked_parts(), colors=[[1, 0, 0]], width=16, height=16)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        OffscreenRenderer(baked_parts(), colors=[[2.0, 0, 0]] * 3, width=16, height=16)
    with pytest.raises(ValueError, match="width"):
        OffscreenRenderer(baked_parts(), width=0)


def test_closing_one_renderer_leaves_the_others_working(renderer):
    expect = renderer.render(identity_poses(), None).tobytes()
    other = OffscreenRenderer(baked_parts()[:1], width=32, height=24)
    other.render()
    other.close()
    assert renderer.render(identity_poses(), None).tobytes() == expect


def test_close_is_idempotent_and_final():
    r = OffscreenRenderer(baked_parts()[:1], width=32, height=24)
    r.render()
    r.close()
    r.close()
    assert r.closed
    with pytest.raises(RenderError, match="closed"):
        r.render()


# ---------------------------------------------------------------- platform choice
def test_platform_respects_the_environment(monkeypatch):
    assert select_platform() == os.environ["PYOPENGL_PLATFORM"]
    monkeypatch.setenv("PYOPENGL_PLATFORM", "glx")
    with pytest.raises(RenderError, match="not supported"):
        select_platform()


_CHILD = textwrap.dedent(
    """
    import trimesh
    from aw.render import OffscreenRenderer
    with OffscreenRenderer([trimesh.creation.box()], width=32, height=24) as r:
        print(r.platform, int((r.render_segmentation() == 0).sum()))
    left_open = OffscreenRenderer([trimesh.creation.box()], width=32, height=24)
    left_open.render()  # released at interpreter exit on its own GL thread
    """
)


def run_child(**env_changes):
    env = {k: v for k, v in os.environ.items() if k != "PYOPENGL_PLATFORM"}
    env.update(env_changes)
    proc = subprocess.run([sys.executable, "-c", _CHILD], env=env, capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    platform, pixels = proc.stdout.split()
    return platform, int(pixels)


def test_default_platform_is_egl_with_osmesa_fallback(renderer):
    # Unset PYOPENGL_PLATFORM: EGL where it can make a context, and it renders.
    platform, pixels = run_child()
    assert pixels > 50
    if renderer.platform == "egl":  # EGL demonstrably works in this process
        assert platform == "egl"
    # With EGL broken (no glvnd vendor), the renderer falls back to OSMesa and still renders.
    platform, pixels = run_child(__EGL_VENDOR_LIBRARY_FILENAMES="/nonexistent/none.json")
    if platform == "egl":
        pytest.skip("this EGL does not go through glvnd; cannot simulate a broken EGL")
    assert platform == "osmesa" and pixels > 50


# ---------------------------------------------------------------- per-picture overrides
def test_visible_and_color_overrides_apply_to_one_picture_only(renderer):
    poses = identity_poses()
    cam = Camera.framing(*renderer.posed_bounds(poses))
    full = renderer.render(poses, cam).tobytes()
    seg = renderer.render_segmentation(poses, cam, visible=np.array([True, False, True]))
    assert (seg == 1).sum() == 0 and (seg == 0).sum() > 100 and (seg == 2).sum() > 100
    img = np.asarray(renderer.render(poses, cam, visible=np.array([False, True, False]), colors=[[0.0, 0.0, 1.0]] * 3))
    seg1 = renderer.render_segmentation(poses, cam)
    px = img[interior(seg1 == 1)].astype(float).mean(axis=0)
    assert px[2] > 2 * px[0] and px[2] > 2 * px[1]  # drawn in the override colour
    assert (
        ((np.abs(img.astype(int) - np.asarray(BACKGROUND_COLOR) * 255).sum(axis=2) > 60)[interior(seg1 == 0)]).mean()
        < 0.2
    )
    # The next ordinary picture is the original one again.
    assert renderer.render(poses, cam).tobytes() == full
    with pytest.raises(ValueError, match="visible"):
        renderer.render(poses, cam, visible=[1, 0, 1])
    with pytest.raises(ValueError):
        renderer.render(poses, cam, colors=[[0, 0, 1]])
