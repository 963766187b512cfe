"""Round trip source -> suite -> oracle poses: shared by the loader tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aw.assembly import AssembledObject
from aw.formats import read_targets, read_task
from aw.formats.suite import suite_paths
from aw.meshes import load_task_meshes
from aw.pose import apply_pose
from aw.prepare import prepare_object


def oracle_roundtrip(obj: AssembledObject, suite: Path, conditions=("none",)) -> list:
    """Prepare ``obj`` into ``suite``, then check that the hidden target poses put every baked
    part exactly onto the normalized source part, and that an evaluator scores the oracle
    poses PA = SR = 1. Returns the manifest entries."""
    entries = prepare_object(obj, suite, conditions)
    by_name = {p.name: p for p in obj.parts}
    for entry in entries:
        task_dir, targets_path = suite_paths(suite, entry.task_id)
        task = read_task(task_dir)
        targets = read_targets(targets_path)
        meshes = load_task_meshes(task)
        all_v = np.concatenate([np.asarray(p.mesh.vertices) for p in obj.parts])
        centre = 0.5 * (all_v.min(axis=0) + all_v.max(axis=0))
        for pid, mesh in zip(task.part_ids, meshes, strict=True):
            t = targets.parts[pid]
            placed = apply_pose(np.asarray(t.pose), np.asarray(mesh.vertices))
            src = by_name[t.source_name].mesh
            used = np.unique(np.asarray(src.faces).ravel())
            expected = (np.asarray(src.vertices)[used] - centre) * targets.scale
            assert placed.shape == expected.shape
            assert np.abs(placed - expected).max() < 1e-6 * max(1.0, np.abs(expected).max())
        _score_oracle(task_dir, targets_path, targets, task.part_ids)
    return entries


def _score_oracle(task_dir: Path, targets_path: Path, targets, part_ids) -> None:
    from aw_eval import ProtocolSettings, load_task_geometry, score

    # fewer samples than the paper's 4096 -> 1000 keep the test fast; the protocol is otherwise the same
    settings = ProtocolSettings(n_surface=256, n_fps=64)
    geom = load_task_geometry(
        task_dir, targets_path, cache_dir=task_dir.parent.parent / ".geometry_cache", settings=settings
    )
    poses = np.array([targets.parts[p].pose for p in geom.part_ids])
    res = score(geom, poses, mode="exact")
    assert res.pa == 1.0 and res.sr == 1.0, (res.pa, res.sr)
