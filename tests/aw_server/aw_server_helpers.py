"""Helpers for the aw-serve tests: small task directories (three boxes), server commands,
and decoding of MCP results. (A uniquely named module, so that tests can import it.)"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image
from scipy.spatial.transform import Rotation

from aw.formats import PartTarget, Targets, Task, TaskPart, write_targets, write_task
from aw.pose import invert_pose, matrix_to_quat
from aw.prompt import task_prompt

# Assembled object (a small table): box extents and centers in the assembled frame.
PARTS = {
    "p01": ((0.80, 0.50, 0.06), (0.00, 0.00, 0.45)),
    "p02": ((0.06, 0.06, 0.42), (-0.30, -0.15, 0.21)),
    "p03": ((0.10, 0.05, 0.42), (0.30, 0.15, 0.21)),
}


def make_task(
    root: Path, condition: str = "none", n_refs: int | None = None, seed: int = 0, task_id: str = "box3"
) -> tuple[Path, Path, Targets]:
    """Write ``root/tasks/<task_id>`` and ``root/targets/<task_id>.json``; return (task_dir, targets_path, targets).

    Each part is baked with a random rotation and a scattered offset; its target pose undoes that.
    """
    rng = np.random.default_rng(seed)
    task_dir = root / "tasks" / task_id
    (task_dir / "parts").mkdir(parents=True, exist_ok=True)
    targets = {}
    for k, (pid, (ext, centre)) in enumerate(PARTS.items()):
        mesh = trimesh.creation.box(extents=ext)
        mesh.apply_translation(centre)
        rot = Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix()
        shift = np.array([1.2 * (k - 1), 0.9, 0.0]) + rng.uniform(-0.1, 0.1, 3)
        bake = np.eye(4)
        bake[:3, :3], bake[:3, 3] = rot, shift
        mesh.apply_transform(bake)
        mesh.export(task_dir / "parts" / f"{pid}.obj")
        baked_pose = np.concatenate([shift, matrix_to_quat(rot)])
        targets[pid] = PartTarget(pose=[float(v) for v in invert_pose(baked_pose)])
    if n_refs is None:
        n_refs = {"none": 0, "image": 1, "manual": 3}[condition]
    refs = []
    (task_dir / "references").mkdir(exist_ok=True)
    for i in range(1, n_refs + 1):
        rel = f"references/{i:02d}.png"
        Image.new("RGB", (64, 48), (40 * i, 100, 200)).save(task_dir / rel)
        refs.append(rel)
    task = Task(
        task_id=task_id,
        source="custom",
        dataset="test",
        category="table",
        object_id=task_id,
        condition=condition,
        prompt=task_prompt(condition),
        parts=[TaskPart(id=pid, mesh=f"parts/{pid}.obj") for pid in PARTS],
        references=refs,
    )
    write_task(task_dir, task)
    tgt = Targets(task_id=task_id, parts=targets, scale=1.0)
    targets_path = root / "targets" / f"{task_id}.json"
    write_targets(targets_path, tgt)
    return task_dir, targets_path, tgt


def server_command(task_dir: Path, run_dir: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "aw_server.cli", str(task_dir), "--record", str(run_dir), *extra]


def server_params(task_dir: Path, run_dir: Path, *extra: str):
    from mcp import StdioServerParameters

    cmd = server_command(task_dir, run_dir, *extra)
    return StdioServerParameters(command=cmd[0], args=cmd[1:], env=dict(os.environ))


def result_text(result) -> str:
    """All text blocks of a CallToolResult, joined."""
    return "\n".join(c.text for c in result.content if getattr(c, "type", "") == "text")


def result_png(result) -> Image.Image:
    """The single image block of a capture_scene result, decoded."""
    import base64
    import io

    images = [c for c in result.content if getattr(c, "type", "") == "image"]
    assert len(images) == 1, result
    assert images[0].mime_type == "image/png"
    return Image.open(io.BytesIO(base64.b64decode(images[0].data)))


def png_bytes(result) -> bytes:
    import base64

    return base64.b64decode(next(c for c in result.content if c.type == "image").data)


def image_diff(a: Image.Image, b: Image.Image) -> float:
    """Mean absolute pixel difference (0..255)."""
    return float(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float)).mean())


def quat_close(q1, q2, tol: float) -> bool:
    """Equal rotations (q and -q are the same rotation)."""
    q1, q2 = np.asarray(q1, float), np.asarray(q2, float)
    return bool(min(np.abs(q1 - q2).max(), np.abs(q1 + q2).max()) <= tol)
