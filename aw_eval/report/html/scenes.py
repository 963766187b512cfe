"""The pictures of a task: its target and the runs' states drawn aligned onto it, from one camera.

A run's state is drawn in the target's frame through the registration its scoring saved
(:class:`~aw_eval.study.model.RunScore` ``reg_*``/``ck_reg_*``): the evaluator maps a state's
normalized points ``x / d`` onto the normalized target by ``R (x / d) + t``, so a part at world
pose ``(R_i, p_i)`` is drawn at ``(R R_i, R p_i + d t)``. Part ``i`` has the same colour in the
target and in every state (:func:`aw.render.part_colors`).

Renders are files named by a hash of everything that changes the picture (mesh bytes, poses,
camera, size, colours): one that exists is reused, so a second report renders only what changed
and identical states (consecutive filmstrip frames, systems that ended alike) render once.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from PIL import Image

from aw.camera import Camera
from aw.formats.io import atomic_path
from aw.pose import matrices_to_poses, poses_to_matrices

if TYPE_CHECKING:  # imported where it is opened: GL set-up only when a picture is asked for
    from aw.render import OffscreenRenderer

__all__ = ["TaskScene", "aligned_poses", "RENDER_FORMAT"]

RENDER_FORMAT = "jpg"
_RENDER_VERSION = "1"  # bump when the picture changes for the same inputs
_QUALITY = 85


def aligned_poses(poses: np.ndarray, rotation: np.ndarray, translation: np.ndarray, divisor: float) -> np.ndarray:
    """Wire-form poses ``(P, 7)`` of a state, or ``(N, P, 7)`` of N states, moved by their saved
    registrations ``rotation (3, 3)`` / ``(N, 3, 3)`` and ``translation (3,)`` / ``(N, 3)``
    (normalized units) into the target's frame; unchanged when the registration is missing
    (empty arrays: caches written before it was kept)."""
    poses = np.asarray(poses, dtype=np.float64)
    rotation, translation = np.asarray(rotation, np.float64), np.asarray(translation, np.float64)
    if rotation.shape != poses.shape[:-2] + (3, 3) or translation.shape != poses.shape[:-2] + (3,):
        return poses
    reg = np.zeros(poses.shape[:-2] + (1, 4, 4))
    reg[..., 0, :3, :3] = rotation
    reg[..., 0, :3, 3] = divisor * translation
    reg[..., 0, 3, 3] = 1.0
    return matrices_to_poses(reg @ poses_to_matrices(poses))


@dataclass
class TaskScene:
    """The scored parts of one task: ``meshes`` (P baked meshes), ``target_poses (P, 7)``,
    ``colors (P, 3)`` sRGB in [0, 1], ``divisor`` (evaluation scale, baked units)."""

    task_id: str
    part_ids: list[str]
    meshes: list
    target_poses: np.ndarray
    colors: np.ndarray
    divisor: float

    def __post_init__(self) -> None:
        h = hashlib.sha1()
        for m in self.meshes:
            h.update(np.ascontiguousarray(m.vertices, dtype=np.float64).tobytes())
            h.update(np.ascontiguousarray(m.faces, dtype=np.int64).tobytes())
        self.digest = h.hexdigest()
        self._renderer: OffscreenRenderer | None = None  # opened on the first picture, at its size

    @classmethod
    def load(cls, suite_dir: Path, task_id: str, part_ids: list[str], divisor: float) -> TaskScene:
        """Read a native task's meshes and targets (raises ``FormatError``/``OSError``/``ValueError``)."""
        from aw.formats import read_targets, read_task
        from aw.formats.suite import suite_paths
        from aw.meshes import load_task_meshes
        from aw.render import part_colors

        task_dir, targets_path = suite_paths(suite_dir, task_id)
        task = read_task(task_dir)
        targets = read_targets(targets_path)
        by_id = dict(zip(task.part_ids, load_task_meshes(task), strict=True))
        meshes = [by_id[p] for p in part_ids]
        target = np.array([targets.parts[p].pose for p in part_ids], dtype=np.float64).reshape(-1, 7)
        return cls(task_id, list(part_ids), meshes, target, part_colors(len(part_ids)), float(divisor))

    def bounds(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World bounds ``(lo (3,), hi (3,))`` of the parts at ``poses (P, 7)``."""
        mats = poses_to_matrices(poses)
        pts = np.concatenate([m.vertices @ t[:3, :3].T + t[:3, 3] for m, t in zip(self.meshes, mats, strict=True)])
        return pts.min(axis=0), pts.max(axis=0)

    def placed(self, poses: np.ndarray, threshold: float) -> np.ndarray:
        """``(P,)`` bool: the parts that lie at their targets as placed in ``poses (P, 7)``, before
        any registration (:func:`aw_eval.analyses.failures.placed_parts`)."""
        from aw_eval.analyses.failures import placed_parts

        return placed_parts(self.meshes, poses, self.target_poses, self.divisor, threshold)

    def camera(self, states: list[np.ndarray]) -> Camera:
        """One camera for the target and every ``states`` entry ``(P, 7)``: frames their union,
        limited to twice the target's extent around it (a part left far away is cut, not the
        assembly shrunk to a dot)."""
        lo, hi = self.bounds(self.target_poses)
        centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        reach = 2.0 * np.maximum(half, 1e-6 + 0.05 * half.max())
        for p in states:
            a, b = self.bounds(p)
            lo, hi = np.minimum(lo, a), np.maximum(hi, b)
        lo, hi = np.maximum(lo, centre - reach), np.minimum(hi, centre + reach)
        return Camera.framing(lo, hi)

    def render(self, poses: np.ndarray, camera: Camera, size: tuple[int, int], folder: Path) -> str:
        """File name (in ``folder``) of the picture of ``poses (P, 7)``; rendered only if absent.
        The first picture's size is the renderer's: ask for the largest first."""
        w, h = size
        key = hashlib.sha1(f"{_RENDER_VERSION}|{self.digest}|{w}x{h}|{camera.to_dict()}|".encode())
        key.update(np.round(np.asarray(poses, dtype=np.float64), 7).tobytes())
        key.update(np.round(self.colors, 4).tobytes())
        name = f"{key.hexdigest()[:20]}.{RENDER_FORMAT}"
        path = folder / name
        if not path.is_file():
            if self._renderer is None:  # one per task: opening a GL context costs more than many pictures
                from aw.render import OffscreenRenderer

                self._renderer = OffscreenRenderer(self.meshes, colors=self.colors, width=w, height=h)
            im = self._renderer.render(poses, camera)
            if im.size != (w, h):  # smaller pictures (filmstrip frames) are scaled down
                im = im.resize((w, h), Image.Resampling.LANCZOS)
            with atomic_path(path) as tmp:  # workers may render the same picture
                im.save(tmp, quality=_QUALITY, optimize=True)
        return name

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
