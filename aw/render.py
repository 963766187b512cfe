"""Offscreen rendering of the scene with pyrender (EGL or OSMesa), as ``capture_scene`` shows it.

One :class:`OffscreenRenderer` per set of part meshes: the meshes are uploaded once, and each
:meth:`~OffscreenRenderer.render` only moves the part nodes, the camera, the lights and the
ground. Every GL call runs on one thread owned by the renderer, because an EGL context works
only in the thread that created it; ``render`` may be called from any thread (calls are
serialized).

The picture: 1024x768 by default, 38 degree vertical field of view (:mod:`aw.camera`), parts in
the stable colours of :func:`part_colors` with flat shading, a key and a fill light attached to
the camera plus ambient light, a light background, and a ground reference at the lowest part's
height: a one-sided plane (invisible from below) with a grid whose lines lie at fixed world
coordinates, spaced 1, 2 or 5 times a power of ten. The ground is left out when the camera is
below it, so it never hides a part.
"""

from __future__ import annotations

import atexit
import colorsys
import functools
import threading
import weakref
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import trimesh
from PIL import Image

from aw.camera import IMAGE_HEIGHT, IMAGE_WIDTH, VERTICAL_FOV_DEG, Camera
from aw.pose import as_finite, poses_to_matrices
from aw.render_platform import SYSTEM_PACKAGES, RenderError, select_platform

__all__ = [
    "OffscreenRenderer",
    "RenderError",
    "render_meshes",
    "part_colors",
    "BACKGROUND_COLOR",
    "grid_spacing",
]

# sRGB colours in [0, 1].
BACKGROUND_COLOR = (0.96, 0.965, 0.975)
_GROUND_COLOR = (0.885, 0.895, 0.91)
_GRID_COLOR = (0.70, 0.72, 0.76)
# Tableau 10 without its grey (too close to the ground); further colours are picked greedily.
_PALETTE = (
    (0.122, 0.467, 0.706),
    (1.000, 0.498, 0.055),
    (0.173, 0.627, 0.173),
    (0.839, 0.153, 0.157),
    (0.580, 0.404, 0.741),
    (0.549, 0.337, 0.294),
    (0.890, 0.467, 0.761),
    (0.737, 0.741, 0.133),
    (0.090, 0.745, 0.812),
)
_GREEDY_COLORS = 64  # beyond this many parts, golden-ratio hues

# Light directions (where the light travels) in camera coordinates (x right, y up, -z ahead).
_KEY_DIR = (0.35, -0.55, -1.0)
_FILL_DIR = (-0.6, 0.25, -1.0)
_KEY_INTENSITY = 3.2
_FILL_INTENSITY = 1.4
_AMBIENT = 0.32

_GRID_HALF_LINES = 12  # the grid has 2 * 12 + 1 lines in each direction
_GRID_TARGET_CELLS = 10  # about this many cells across the parts' extent


def _lab(rgb: np.ndarray) -> np.ndarray:
    """CIELAB (D65) of sRGB colours ``(..., 3)`` in [0, 1]: distances there follow perception."""
    c = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    m = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    xyz = c @ m.T / [0.95047, 1.0, 1.08883]
    f = np.where(xyz > 216 / 24389, np.cbrt(xyz), (24389 / 27 * xyz + 16) / 116)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], axis=-1)


@functools.lru_cache(maxsize=1)
def _greedy_palette() -> np.ndarray:
    """The fixed palette, then candidates (an HSV grid, minus colours near the background or the
    ground) added one at a time, each the farthest in CIELAB from all chosen so far."""
    cands = np.array(
        [
            colorsys.hsv_to_rgb(h / 36, s, v)
            for h in range(36)
            for s in (0.5, 0.75, 1.0)
            for v in (0.45, 0.65, 0.85, 1.0)
        ]
    )
    lab = _lab(cands)
    light = _lab(np.array([BACKGROUND_COLOR, _GROUND_COLOR]))
    keep = np.linalg.norm(lab[:, None] - light[None], axis=2).min(axis=1) > 25.0
    cands, lab = cands[keep], lab[keep]
    chosen = [np.asarray(c) for c in _PALETTE]
    dist = np.linalg.norm(lab[:, None] - _lab(np.array(_PALETTE))[None], axis=2).min(axis=1)
    while len(chosen) < _GREEDY_COLORS:
        k = int(np.argmax(dist))  # first on ties: deterministic
        chosen.append(cands[k])
        dist = np.minimum(dist, np.linalg.norm(lab - lab[k], axis=1))
    return np.asarray(chosen)


def part_colors(n: int) -> np.ndarray:
    """``(n, 3)`` distinct sRGB colours in [0, 1]; colour ``i`` never depends on ``n``."""
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 0:
        raise ValueError(f"n must be a non-negative integer, got {n!r}")
    n = int(n)
    base = _greedy_palette()
    extra = [
        colorsys.hsv_to_rgb((0.11 + k * 0.6180339887498949) % 1.0, 0.8, 0.75) for k in range(max(0, n - len(base)))
    ]
    return np.concatenate([base[:n], np.asarray(extra, dtype=np.float64).reshape(-1, 3)])


def grid_spacing(extent: float) -> float:
    """Grid line spacing for parts spanning ``extent`` units: 1, 2 or 5 times a power of ten,
    about ``extent / 10``."""
    raw = max(float(extent), 1e-6) / _GRID_TARGET_CELLS
    exp = np.floor(np.log10(raw))
    base = raw / 10**exp
    step = 1.0 if base < 1.5 else 2.0 if base < 3.5 else 5.0 if base < 7.5 else 10.0
    return float(step * 10**exp)


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    # pyrender shades in linear space and applies a 1/2.2 gamma at the end.
    return np.power(np.clip(c, 0.0, 1.0), 2.2)


def _look_rotation(direction_cam: Sequence[float]) -> np.ndarray:
    """Rotation (camera coordinates) whose -Z axis is ``direction_cam`` (pyrender lights shine along -Z)."""
    d = np.asarray(direction_cam, float)
    d /= np.linalg.norm(d)
    z = -d
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


def _check_meshes(meshes) -> list[trimesh.Trimesh]:
    if isinstance(meshes, trimesh.Trimesh) or not isinstance(meshes, Sequence) or len(meshes) == 0:
        raise ValueError("meshes must be a non-empty list of trimesh.Trimesh")
    for i, m in enumerate(meshes):
        if not isinstance(m, trimesh.Trimesh):
            raise ValueError(f"meshes[{i}] is a {type(m).__name__}, not a trimesh.Trimesh")
        if len(m.vertices) == 0 or len(m.faces) == 0:
            raise ValueError(f"meshes[{i}] has no triangles")
        if not np.all(np.isfinite(m.vertices)):
            raise ValueError(f"meshes[{i}] has non-finite vertex coordinates")
    return list(meshes)


def _check_colors(colors, n: int) -> np.ndarray:
    if colors is None:
        return part_colors(n)
    c = as_finite(colors, (3,), "colors")
    if c.shape != (n, 3):
        raise ValueError(f"colors must have shape ({n}, 3), got {c.shape}")
    if np.issubdtype(np.asarray(colors).dtype, np.integer):
        if c.min() < 0 or c.max() > 255:
            raise ValueError("integer colors must lie in [0, 255]")
        return c / 255.0
    if c.min() < 0 or c.max() > 1:
        raise ValueError("float colors must lie in [0, 1]")
    return c


def _check_size(width, height) -> tuple[int, int]:
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or not 1 <= v <= 8192:
            raise ValueError(f"{name} must be an integer in [1, 8192], got {v!r}")
    return int(width), int(height)


class OffscreenRenderer:
    """Renders ``meshes`` (part ``i`` in colour ``colors[i]``) under per-call poses and camera.

    ``meshes``: list of P ``trimesh.Trimesh`` in their body frames (for tasks: the baked meshes,
    whose initial poses are the identity). ``colors``: ``(P, 3)`` sRGB floats in [0, 1] or
    integers in [0, 255]; default :func:`part_colors`. Usable as a context manager.
    """

    def __init__(
        self,
        meshes: Sequence[trimesh.Trimesh],
        colors=None,
        width: int = IMAGE_WIDTH,
        height: int = IMAGE_HEIGHT,
    ):
        self._meshes = _check_meshes(meshes)
        self.n_parts = len(self._meshes)
        self.colors = _check_colors(colors, self.n_parts)
        self.width, self.height = _check_size(width, height)
        self.platform = select_platform()
        # Vertices (homogeneous, float64) for the posed bounds that place the ground and frame the view.
        self._verts = [np.c_[np.asarray(m.vertices, np.float64), np.ones(len(m.vertices))] for m in self._meshes]
        self._closed = False
        self._close_lock = threading.Lock()
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="aw-render-gl")
        self._gl: dict[str, Any] = {}
        try:
            self._call(self._gl_init)
        except BaseException:
            self._executor.shutdown(wait=True)
            self._closed = True
            raise
        _live.add(self)

    # ------------------------------------------------------------ public API
    def render(self, poses=None, camera: Camera | None = None, *, visible=None, colors=None) -> Image.Image:
        """RGB image of the parts at ``poses: (P, 7)`` wire form (None: all identity), seen from
        ``camera`` (None: :meth:`Camera.framing` of the posed visible parts).

        For this picture only: ``visible: (P,)`` bools hide parts (the ground then sits under
        the lowest visible part), ``colors: (P, 3)`` replaces the part colours (as in the
        constructor). Nothing is re-uploaded.
        """
        mats, camera, vis = self._prepare_view(poses, camera, visible)
        lin = _srgb_to_linear(self.colors if colors is None else _check_colors(colors, self.n_parts))
        rgb = self._call(self._gl_styled_render, mats, camera, False, vis, lin)
        return Image.fromarray(rgb, mode="RGB")

    def render_segmentation(self, poses=None, camera: Camera | None = None, *, visible=None) -> np.ndarray:
        """``(height, width)`` int array: the index of the part seen at each pixel, -1 for none.

        Same view as :meth:`render`, without anti-aliasing; the ground is not drawn.
        """
        mats, camera, vis = self._prepare_view(poses, camera, visible)
        codes = self._call(self._gl_styled_render, mats, camera, True, vis, None).astype(np.int64)
        ids = codes[..., 0] + (codes[..., 1] << 8) + (codes[..., 2] << 16) - 1
        ids[(ids < -1) | (ids >= self.n_parts)] = -1
        return ids

    def posed_bounds(self, poses=None) -> tuple[np.ndarray, np.ndarray]:
        """World axis-aligned bounds ``(lo (3,), hi (3,))`` of the parts at ``poses: (P, 7)``."""
        return self._bounds(self._pose_matrices(poses))

    def close(self) -> None:
        """Release the GL context and stop the GL thread; idempotent."""
        with self._close_lock:
            if self._closed:
                return
            self._closed = True
        try:
            self._executor.submit(self._gl_delete).result()
        finally:
            self._executor.shutdown(wait=True)
            _live.discard(self)

    @property
    def closed(self) -> bool:
        return self._closed

    def __enter__(self) -> OffscreenRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------ validation (caller's thread)
    def _pose_matrices(self, poses) -> np.ndarray:
        if poses is None:
            return np.broadcast_to(np.eye(4), (self.n_parts, 4, 4)).copy()
        p = as_finite(poses, (7,), "poses")
        if p.shape != (self.n_parts, 7):
            raise ValueError(f"poses must have shape ({self.n_parts}, 7), got {p.shape}")
        return poses_to_matrices(p)

    def _bounds(self, mats: np.ndarray, visible: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for k, (m, v) in enumerate(zip(mats, self._verts, strict=True)):
            if visible is not None and not visible[k]:
                continue
            w = v @ m[:3].T
            lo = np.minimum(lo, w.min(axis=0))
            hi = np.maximum(hi, w.max(axis=0))
        if not np.all(np.isfinite(lo)):  # nothing visible: an empty unit box at the origin
            lo, hi = np.zeros(3), np.zeros(3)
        return lo, hi

    def _visible_mask(self, visible) -> np.ndarray:
        if visible is None:
            return np.ones(self.n_parts, dtype=bool)
        v = np.asarray(visible)
        if v.shape != (self.n_parts,) or v.dtype != bool:
            raise ValueError(f"visible must be {self.n_parts} booleans, got {v.dtype} array of shape {v.shape}")
        return v.copy()

    def _prepare(self, poses, camera) -> tuple[np.ndarray, Camera]:
        """(pose matrices, camera) for a picture of all parts (kept for callers of the first API)."""
        mats, camera, _ = self._prepare_view(poses, camera, None)
        return mats, camera

    def _prepare_view(self, poses, camera, visible) -> tuple[np.ndarray, Camera, np.ndarray]:
        if self._closed:
            raise RenderError("the renderer is closed")
        mats = self._pose_matrices(poses)
        vis = self._visible_mask(visible)
        if camera is None:
            camera = Camera.framing(*self._bounds(mats, vis))
        elif not isinstance(camera, Camera):
            raise ValueError(f"camera must be an aw.camera.Camera, got {type(camera).__name__}")
        return mats, camera, vis

    def _call(self, fn: Callable, *args):
        try:
            return self._executor.submit(fn, *args).result()
        except RuntimeError as exc:
            if "shutdown" in str(exc):
                raise RenderError("the renderer is closed") from None
            raise

    # ------------------------------------------------------------ GL thread only
    def _gl_init(self) -> None:
        try:
            import pyrender  # imported here: PYOPENGL_PLATFORM is set by now

            renderer = pyrender.OffscreenRenderer(self.width, self.height)
        except Exception as exc:
            raise RenderError(
                f"cannot create an offscreen OpenGL context with PYOPENGL_PLATFORM={self.platform} "
                f"({type(exc).__name__}: {exc}). Install the system packages {SYSTEM_PACKAGES}, "
                "or set PYOPENGL_PLATFORM to the other of egl/osmesa before starting Python."
            ) from exc
        scene = pyrender.Scene(bg_color=[*BACKGROUND_COLOR, 1.0], ambient_light=[_AMBIENT] * 3)
        part_nodes = []
        for mesh, color in zip(self._meshes, self.colors, strict=True):
            material = pyrender.MetallicRoughnessMaterial(
                baseColorFactor=[*_srgb_to_linear(color), 1.0],
                metallicFactor=0.0,
                roughnessFactor=0.7,
                # Source meshes are not always closed or consistently wound.
                doubleSided=True,
            )
            # Geometry only: vertex colours or textures from the file would tint the part colour.
            plain = trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), process=False)
            pm = pyrender.Mesh.from_trimesh(plain, material=material, smooth=False)
            part_nodes.append(scene.add(pm, pose=np.eye(4)))
        ground_node, grid_node = self._gl_ground(pyrender, scene)
        cam = pyrender.PerspectiveCamera(yfov=np.radians(VERTICAL_FOV_DEG), aspectRatio=self.width / self.height)
        cam_node = scene.add(cam, pose=np.eye(4))
        key = scene.add(pyrender.DirectionalLight(color=np.ones(3), intensity=_KEY_INTENSITY), pose=np.eye(4))
        fill = scene.add(pyrender.DirectionalLight(color=np.ones(3), intensity=_FILL_INTENSITY), pose=np.eye(4))
        self._gl.update(
            pyrender=pyrender,
            renderer=renderer,
            scene=scene,
            parts=part_nodes,
            ground=ground_node,
            grid=grid_node,
            camera=cam,
            camera_node=cam_node,
            lights=[(key, _look_rotation(_KEY_DIR)), (fill, _look_rotation(_FILL_DIR))],
            seg_map={node: _seg_code(i) for i, node in enumerate(part_nodes)},
        )

    @staticmethod
    def _gl_ground(pyrender, scene):
        """A unit ground quad and a unit-spaced line grid, placed and scaled per render."""
        quad = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]], np.float32)
        plane = pyrender.Primitive(
            positions=quad,
            normals=np.tile(np.array([0, 0, 1], np.float32), (4, 1)),
            indices=np.array([[0, 1, 2], [0, 2, 3]], np.uint32),
            material=_emissive_material(pyrender, _GROUND_COLOR, double_sided=False),
            mode=pyrender.constants.GLTF.TRIANGLES,
        )
        h = _GRID_HALF_LINES
        ticks = np.arange(-h, h + 1, dtype=np.float32)
        segs = []
        for t in ticks:
            segs += [[t, -h, 0], [t, h, 0], [-h, t, 0], [h, t, 0]]
        grid = pyrender.Primitive(
            positions=np.asarray(segs, np.float32),
            material=_emissive_material(pyrender, _GRID_COLOR, double_sided=True),
            mode=pyrender.constants.GLTF.LINES,
        )
        ground_node = scene.add(pyrender.Mesh([plane]), pose=np.eye(4))
        grid_node = scene.add(pyrender.Mesh([grid]), pose=np.eye(4))
        return ground_node, grid_node

    def _gl_styled_render(
        self, mats: np.ndarray, camera: Camera, segmentation: bool, visible: np.ndarray, lin_colors: np.ndarray | None
    ) -> np.ndarray:
        """Set each part's visibility (and colour, unless None) for this picture, then render."""
        if "renderer" not in self._gl:  # a close() got in between
            raise RenderError("the renderer is closed")
        for k, node in enumerate(self._gl["parts"]):
            node.mesh.is_visible = bool(visible[k])
            if lin_colors is not None:
                for prim in node.mesh.primitives:
                    prim.material.baseColorFactor = np.array([*lin_colors[k], 1.0])
        return self._gl_render(mats, camera, segmentation, visible)

    def _gl_render(
        self, mats: np.ndarray, camera: Camera, segmentation: bool, visible: np.ndarray | None = None
    ) -> np.ndarray:
        g = self._gl
        pyrender, scene = g["pyrender"], g["scene"]
        for node, m in zip(g["parts"], mats, strict=True):
            scene.set_pose(node, m)
        lo, hi = self._bounds(mats, visible)
        # Ground at the lowest part's height, a hair below it so part bottoms never fight it.
        extent = max(float(hi[0] - lo[0]), float(hi[1] - lo[1]), 1e-3)
        size = max(float(np.linalg.norm(hi - lo)), 1e-3)
        step = grid_spacing(extent)
        centre = np.round(0.5 * (lo[:2] + hi[:2]) / step) * step
        z = lo[2] - 2e-3 * size
        grid_m = np.diag([step, step, 1.0, 1.0])
        grid_m[:3, 3] = [centre[0], centre[1], z]
        plane_m = np.diag([2 * _GRID_HALF_LINES * step] * 2 + [1.0, 1.0])
        plane_m[:3, 3] = [centre[0], centre[1], z - 2e-3 * size]
        scene.set_pose(g["grid"], grid_m)
        scene.set_pose(g["ground"], plane_m)
        # Seen from below, the ground would lie between the camera and the parts: leave it out.
        above = bool(camera.position[2] > z)
        g["grid"].mesh.is_visible = above
        g["ground"].mesh.is_visible = above
        cam_pose = camera.pose_matrix()
        scene.set_pose(g["camera_node"], cam_pose)
        for node, rot in g["lights"]:
            m = np.eye(4)
            m[:3, :3] = cam_pose[:3, :3] @ rot
            m[:3, 3] = cam_pose[:3, 3]
            scene.set_pose(node, m)
        # Clip planes that enclose the parts and the ground from this viewpoint.
        half = _GRID_HALF_LINES * step
        corners = np.array(
            [
                [x, y, zz]
                for x in (lo[0], hi[0], centre[0] - half, centre[0] + half)
                for y in (lo[1], hi[1], centre[1] - half, centre[1] + half)
                for zz in (lo[2], hi[2], z)
            ]
        )
        far = float(np.linalg.norm(corners - camera.position, axis=1).max()) * 1.05 + 1e-3
        g["camera"].zfar = far
        g["camera"].znear = far / 2000.0
        flags = pyrender.RenderFlags.NONE
        if segmentation:
            color, _ = g["renderer"].render(scene, flags | pyrender.RenderFlags.SEG, seg_node_map=g["seg_map"])
        else:
            color, _ = g["renderer"].render(scene, flags)
        return np.ascontiguousarray(color[..., :3])

    def _gl_delete(self) -> None:
        r = self._gl.pop("renderer", None)
        self._gl.clear()
        if r is None:
            return
        # pyrender's own delete() calls eglTerminate on the EGL display, which every renderer of
        # the process shares: it would break the other renderers. Release only our context.
        platform = r._platform
        platform.make_current()
        r._renderer.delete()
        if hasattr(platform, "_egl_context"):
            from OpenGL.EGL import EGL_NO_CONTEXT, EGL_NO_SURFACE, eglDestroyContext, eglMakeCurrent

            eglMakeCurrent(platform._egl_display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT)
            eglDestroyContext(platform._egl_display, platform._egl_context)
            # Forget the display too: pyrender's Platform.__del__ would otherwise terminate it.
            platform._egl_context = None
            platform._egl_display = None
        else:
            platform.delete_context()
        r._renderer = None
        r._platform = None


def _emissive_material(pyrender, srgb, double_sided: bool):
    # Unlit: black base colour, the colour comes from the emissive term, which pyrender's
    # shader multiplies by the emissive factor twice before the 1/2.2 gamma.
    lin = np.sqrt(_srgb_to_linear(np.asarray(srgb, float)))
    return pyrender.MetallicRoughnessMaterial(
        baseColorFactor=[0.0, 0.0, 0.0, 1.0],
        emissiveFactor=lin,
        metallicFactor=0.0,
        roughnessFactor=1.0,
        doubleSided=double_sided,
    )


def _seg_code(i: int) -> np.ndarray:
    """Segmentation colour (0-255) of part ``i``: ``i + 1`` in 24 bits; black is no part."""
    k = i + 1
    return np.array([k & 255, (k >> 8) & 255, (k >> 16) & 255], dtype=np.float64)


# Renderers still open at exit get their context released on their own thread. This must run
# before concurrent.futures stops accepting work at interpreter shutdown, which plain atexit
# handlers come after; threading's shutdown hooks run in reverse order of registration, and
# concurrent.futures registered its own when it was imported above.
_live: weakref.WeakSet[OffscreenRenderer] = weakref.WeakSet()


def _close_all() -> None:
    for r in list(_live):
        try:
            r.close()
        except Exception:
            pass


if hasattr(threading, "_register_atexit"):
    threading._register_atexit(_close_all)
else:  # pragma: no cover - older interpreters
    atexit.register(_close_all)


def render_meshes(
    meshes: Sequence[trimesh.Trimesh],
    poses=None,
    camera: Camera | None = None,
    colors=None,
    width: int = IMAGE_WIDTH,
    height: int = IMAGE_HEIGHT,
) -> Image.Image:
    """One-off render (creates and closes a renderer). ``poses: (P, 7)`` or None (identity);
    ``camera`` None frames the posed parts with :meth:`Camera.framing`."""
    with OffscreenRenderer(meshes, colors=colors, width=width, height=height) as r:
        return r.render(poses, camera)
