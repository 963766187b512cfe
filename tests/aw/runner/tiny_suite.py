"""A tiny hand-made suite for runner tests, written with the project's own format writers.

Tasks are box furniture (a table: top + legs; a shelf: sides + boards) whose parts are laid out
the way the paper initializes them (flat, random yaw, scattered on the XY plane), baked into
the meshes, with the hidden target pose that undoes the layout.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

from aw.formats import (
    PartTarget,
    SuiteEntry,
    SuiteManifest,
    Targets,
    Task,
    TaskPart,
    write_manifest,
    write_targets,
    write_task,
)
from aw.pose import invert_pose, matrices_to_poses
from aw.prompt import task_prompt


def _table() -> list[trimesh.Trimesh]:
    top = trimesh.creation.box([1.0, 0.6, 0.05])
    top.apply_translation([0, 0, 0.5])
    legs = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            leg = trimesh.creation.box([0.05, 0.05, 0.475])
            leg.apply_translation([sx * 0.45, sy * 0.25, 0.2375])
            legs.append(leg)
    return [top, *legs]


def _shelf() -> list[trimesh.Trimesh]:
    parts = []
    for sx in (-1, 1):
        side = trimesh.creation.box([0.04, 0.3, 0.8])
        side.apply_translation([sx * 0.3, 0, 0.4])
        parts.append(side)
    for z in (0.1, 0.45):
        board = trimesh.creation.box([0.56, 0.3, 0.03])
        board.apply_translation([0, 0, z])
        parts.append(board)
    return parts


def _bake(parts: list[trimesh.Trimesh], rng: np.random.Generator) -> tuple[list[trimesh.Trimesh], list[list[float]]]:
    """Lay parts flat (smallest extent along Z), random yaw, in a row; return baked meshes and
    the target pose of each (baked -> assembled)."""
    baked, targets = [], []
    x = 0.0
    for m in parts:
        c = m.bounds.mean(axis=0)
        ext = m.extents
        order = np.argsort(ext)[::-1]  # largest -> x, smallest -> z
        rot = np.zeros((3, 3))
        for row, col in enumerate(order):
            rot[row, col] = 1.0
        if np.linalg.det(rot) < 0:
            rot[2] *= -1
        yaw = rng.uniform(-np.pi, np.pi)
        rz = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
        r = rz @ rot
        t = np.eye(4)
        t[:3, :3] = r
        t[:3, 3] = -r @ c
        b = m.copy()
        b.apply_transform(t)
        lo, hi = b.bounds
        shift = np.array([x - lo[0], -0.5 * (lo[1] + hi[1]), -lo[2]])
        b.apply_translation(shift)
        t[:3, 3] += shift
        x += (hi[0] - lo[0]) + 0.05
        baked.append(b)
        targets.append(invert_pose(matrices_to_poses(t)).tolist())
    return baked, targets


def make_tiny_suite(root: Path, with_image: bool = True) -> Path:
    """``root/manifest.json``, ``tasks/``, ``targets/``: a table (none), a shelf (none) and, if
    ``with_image``, the table again with a reference image (image condition)."""
    rng = np.random.default_rng(0)
    entries = []
    specs = [("table", _table(), "none"), ("shelf", _shelf(), "none")]
    if with_image:
        specs.append(("table", _table(), "image"))
    for obj, parts, condition in specs:
        task_id = f"tiny_{obj}_{condition}"
        task_dir = root / "tasks" / task_id
        (task_dir / "parts").mkdir(parents=True)
        baked, targets = _bake(parts, rng)
        ids = [f"p{i + 1:02d}" for i in range(len(parts))]
        for pid, m in zip(ids, baked, strict=True):
            m.export(task_dir / "parts" / f"{pid}.obj")
        refs = []
        if condition == "image":
            (task_dir / "references").mkdir()
            Image.new("RGB", (64, 48), (200, 180, 150)).save(task_dir / "references" / "01.png")
            refs = ["references/01.png"]
        write_task(
            task_dir,
            Task(
                task_id=task_id,
                source="partnet",
                dataset="synthetic",
                category=obj,
                object_id=f"tiny_{obj}",
                condition=condition,
                prompt=task_prompt(condition),
                parts=[TaskPart(id=pid, mesh=f"parts/{pid}.obj") for pid in ids],
                references=refs,
            ),
        )
        write_targets(
            root / "targets" / f"{task_id}.json",
            Targets(
                task_id=task_id, parts={pid: PartTarget(pose=p) for pid, p in zip(ids, targets, strict=True)}, scale=1.0
            ),
        )
        entries.append(
            SuiteEntry(
                task_id=task_id,
                source="partnet",
                condition=condition,
                object_id=f"tiny_{obj}",
                category=obj,
                n_parts=len(ids),
            )
        )
    write_manifest(root, SuiteManifest(name="tiny", generator="tests/aw/runner/tiny_suite.py", tasks=entries))
    return root
