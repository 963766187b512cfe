"""A small two-fragment fracture suite for refiner tests, written with the project's own
generator (:func:`aw.sources.synthetic.fracture.fracture`) and format writers: each fragment is
baked at a random rotation and a scattered position, its target pose undoing that."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

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
from aw.prepare.official_protocol import pose_of
from aw.prompt import task_prompt
from aw.sources.synthetic.builder import Builder
from aw.sources.synthetic.fracture import fracture


def fragments(category: str, seed: int) -> list[trimesh.Trimesh]:
    """The two assembled fragments of a ``category`` solid, scaled to about unit size."""
    b = Builder(category)
    fracture(b, category, np.random.default_rng(seed))
    meshes = [p.mesh for p in b.parts]
    size = float(np.ptp(np.vstack([m.vertices for m in meshes]), axis=0).max())
    return [trimesh.Trimesh(np.asarray(m.vertices) / size, m.faces, process=False) for m in meshes]


def bake(meshes: list[trimesh.Trimesh], rng: np.random.Generator) -> tuple[list[trimesh.Trimesh], np.ndarray]:
    """Each mesh turned and moved apart; the ``(P, 7)`` target poses that put them back."""
    baked, targets = [], []
    for k, m in enumerate(meshes):
        rot = Rotation.random(random_state=rng).as_matrix()
        shift = np.array([1.5 * k, rng.uniform(-0.3, 0.3), 0.5])
        baked.append(trimesh.Trimesh(np.asarray(m.vertices) @ rot.T + shift, m.faces, process=False))
        targets.append(pose_of(-rot.T @ shift, rot.T))  # undoes x -> R x + s
    return baked, np.array(targets)


def make_fracture_suite(root: Path, objects=(("cylinder", 1), ("hex_prism", 2))) -> Path:
    rng = np.random.default_rng(7)
    entries = []
    for category, seed in objects:
        task_id = f"frac_{category}_{seed}"
        task_dir = root / "tasks" / task_id
        (task_dir / "parts").mkdir(parents=True)
        baked, targets = bake(fragments(category, seed), rng)
        ids = ["fragment_a", "fragment_b"]
        for pid, m in zip(ids, baked, strict=True):
            m.export(task_dir / "parts" / f"{pid}.obj")
        write_task(
            task_dir,
            Task(
                task_id=task_id,
                source="fantastic_breaks",
                dataset="synthetic",
                category=category,
                object_id=f"{category}_{seed}",
                condition="none",
                prompt=task_prompt("none"),
                parts=[TaskPart(id=p, mesh=f"parts/{p}.obj") for p in ids],
            ),
        )
        write_targets(
            root / "targets" / f"{task_id}.json",
            Targets(
                task_id=task_id,
                parts={p: PartTarget(pose=t.tolist()) for p, t in zip(ids, targets, strict=True)},
                scale=1.0,
            ),
        )
        entries.append(
            SuiteEntry(
                task_id=task_id,
                source="fantastic_breaks",
                condition="none",
                object_id=f"{category}_{seed}",
                category=category,
                n_parts=2,
            )
        )
    write_manifest(root, SuiteManifest(name="fractures", generator="tests/aw/refine/fracture_suite.py", tasks=entries))
    return root
