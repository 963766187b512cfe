"""Reference images rendered from the assembled object: the finished object and manual pages.

References never reveal which task part is which: parts are drawn in neutral shades chosen by
source order (not by anonymized id, and never in the colours ``capture_scene`` uses), from one
fixed viewpoint framing the whole normalized assembly.

* ``image``: one picture of the finished assembly.
* ``manual``: one page per assembly step. Step ``k`` shows the parts of steps ``1..k``; parts
  added at step ``k`` are highlighted, earlier ones are grey, later ones are not drawn; the page
  carries "Step k / K". Steps come from ``obj.meta["steps"]`` (lists of part names), else one
  part per step in source order.

One renderer per object serves every page: a new renderer compiles its shaders on its first
picture, which on a CPU costs about as much again as the picture itself.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import trimesh
from PIL import Image, ImageDraw, ImageFont

from aw.camera import Camera
from aw.prepare.standardize import PreparedObject

__all__ = ["IMAGE_SIZE", "MANUAL_SIZE", "ReferenceRenderer", "manual_steps", "reference_images"]

IMAGE_SIZE = (1024, 768)
"""Assembled-object image: the size of ``capture_scene`` pictures."""
MANUAL_SIZE = (640, 480)
"""Manual pages: smaller, since there are several per task and CPU rendering costs per pixel."""

_NEUTRAL = np.array([0.80, 0.78, 0.74])  # warm light grey
_DONE = np.array([0.72, 0.72, 0.72])
_NEW = np.array([0.93, 0.45, 0.10])  # orange


def _neutral_shades(n: int) -> np.ndarray:
    """``(n, 3)`` close neutral shades (enough contrast to see part boundaries)."""
    k = np.arange(n)
    factor = 0.86 + 0.14 * ((k * 0.618034) % 1.0)
    return np.clip(_NEUTRAL[None, :] * factor[:, None], 0, 1)


def manual_steps(prep: PreparedObject) -> list[list[int]]:
    """Assembly steps as lists of indices into the object's source parts.

    From ``obj.meta["steps"]`` (part names); parts no step names are added in a last step.
    """
    obj = prep.obj
    index = {p.name: i for i, p in enumerate(obj.parts)}
    raw = obj.meta.get("steps") if isinstance(obj.meta, dict) else None
    if not raw:
        return [[i] for i in range(obj.n_parts)]
    steps, seen = [], set()
    for step in raw:
        unknown = [n for n in step if n not in index]
        if unknown:
            raise ValueError(f"object {obj.object_id}: manual steps name unknown parts {unknown}")
        idx = [index[n] for n in step if index[n] not in seen]
        seen.update(idx)
        if idx:
            steps.append(idx)
    rest = [i for i in range(obj.n_parts) if i not in seen]
    if rest:
        steps.append(rest)
    return steps


def assembled_meshes(prep: PreparedObject) -> tuple[list[trimesh.Trimesh], np.ndarray]:
    """The normalized assembled parts (``scale * (v - centre)``) in source order, each about its
    own vertex mean, and the poses ``(P, 7)`` that put them in place.

    Distinct body origins matter: pyrender draws opaque meshes sorted by the distance of their
    node origin from the camera, and equal distances fall back to an arbitrary set order, which
    would make touching coplanar faces come out differently from run to run.
    """
    meshes, poses = [], []
    for p in prep.obj.parts:
        v = (np.asarray(p.mesh.vertices, dtype=np.float64) - prep.centre) * prep.scale
        c = v.mean(axis=0)
        meshes.append(trimesh.Trimesh(v - c, np.asarray(p.mesh.faces), process=False))
        poses.append([*c, 1.0, 0.0, 0.0, 0.0])
    return meshes, np.asarray(poses)


def _font(size: int) -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1 has a single bitmap size
        return ImageFont.load_default()


def _label(img: Image.Image, text: str) -> Image.Image:
    draw = ImageDraw.Draw(img)
    size = max(14, img.height // 14)
    font = _font(size)
    pad = size // 2
    box = draw.textbbox((pad, pad), text, font=font)
    draw.rectangle(
        (box[0] - pad // 2, box[1] - pad // 2, box[2] + pad // 2, box[3] + pad // 2),
        fill=(255, 255, 255),
        outline=(40, 40, 40),
    )
    draw.text((pad, pad), text, fill=(20, 20, 20), font=font)
    return img


class ReferenceRenderer:
    """Renders the references of one prepared object (use as a context manager)."""

    def __init__(self, prep: PreparedObject, size: tuple[int, int]):
        self.prep = prep
        self.meshes, self.poses = assembled_meshes(prep)
        self.n = len(self.meshes)
        self._renderer = _StepRenderer(self.meshes, _neutral_shades(self.n), size)
        lo = np.min([m.vertices.min(axis=0) + c for m, c in zip(self.meshes, self.poses[:, :3], strict=True)], axis=0)
        hi = np.max([m.vertices.max(axis=0) + c for m, c in zip(self.meshes, self.poses[:, :3], strict=True)], axis=0)
        self.camera = Camera.framing(lo, hi, margin=1.05)

    def image(self) -> Image.Image:
        """The finished assembly."""
        return self._renderer.render(self.poses, np.ones(self.n, bool), _neutral_shades(self.n), self.camera)

    def manual(self, steps: Sequence[Sequence[int]] | None = None) -> list[Image.Image]:
        """One labelled page per step (indices into source parts)."""
        steps = list(steps) if steps is not None else manual_steps(self.prep)
        pages, done = [], np.zeros(self.n, bool)
        for k, step in enumerate(steps, start=1):
            new = np.zeros(self.n, bool)
            new[list(step)] = True
            colors = np.where(new[:, None], _NEW[None, :], _DONE[None, :])
            img = self._renderer.render(self.poses, done | new, colors, self.camera)
            pages.append(_label(img, f"Step {k} / {len(steps)}"))
            done |= new
        return pages

    def close(self) -> None:
        self._renderer.close()

    def __enter__(self) -> ReferenceRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class _StepRenderer:
    """An :class:`aw.render.OffscreenRenderer` that can hide parts and recolour them per picture.

    ``aw.render`` fixes colours at construction and draws every part; manual pages need subsets
    in changing colours without re-uploading meshes or recompiling shaders (the bulk of the cost
    of a picture on a CPU). This toggles pyrender's per-mesh visibility and material colour on
    the renderer's GL thread, then runs its ordinary render path.
    """

    def __init__(self, meshes, colors, size):
        from aw import render as _render

        self._render_mod = _render
        self._r = _render.OffscreenRenderer(meshes, colors=colors, width=size[0], height=size[1])

    def render(self, poses: np.ndarray, visible: np.ndarray, colors: np.ndarray, camera: Camera) -> Image.Image:
        r = self._r
        mats, camera = r._prepare(poses, camera)
        lin = self._render_mod._srgb_to_linear(np.asarray(colors, dtype=np.float64))

        def draw():
            for node, vis, col in zip(r._gl["parts"], visible, lin, strict=True):
                node.mesh.is_visible = bool(vis)
                for prim in node.mesh.primitives:
                    prim.material.baseColorFactor = np.array([*col, 1.0])
            return r._gl_render(mats, camera, False)

        return Image.fromarray(r._call(draw), mode="RGB")

    def close(self) -> None:
        self._r.close()


def reference_images(prep: PreparedObject, condition: str, image_size=IMAGE_SIZE, manual_size=MANUAL_SIZE) -> list:
    """References for ``condition``: provided by the source if it has them, else rendered.

    Returns a list of ``PIL.Image`` or image paths (empty for ``none``).
    """
    if condition == "none":
        return []
    provided = prep.obj.references.get(condition) if prep.obj.references else None
    if provided:
        return list(provided)
    if condition == "image":
        with ReferenceRenderer(prep, image_size) as rr:
            return [rr.image()]
    if condition == "manual":
        with ReferenceRenderer(prep, manual_size) as rr:
            return rr.manual()
    raise ValueError(f"unknown condition {condition!r}")
