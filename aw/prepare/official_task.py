"""Tasks by the official preparation protocol: an assembled object in, a task (baked meshes,
targets) and its evaluation points ``SUITE/eval_points/<task_id>.npz`` out.

An object read from an official re-hosted dataset carries ``meta["official"]``::

    dataset          the Hugging Face repository id the official streams are named by
    sample_id        the official sample id (default: the object id)
    source_to_z_up   (3, 3) the rotation the loader applied to reach Z up (default: identity)
    faces            {part name: polygons} where the source has faces other than triangles
    local            {part name: (n, 3) source-frame vertices} where the loader moved the part
    poses            {part name: [tx, ty, tz, qw, qx, qy, qz]} assembled pose of each ``local`` part

Without it (folder imports, synthetic objects) the object's own meshes are the source: dataset
``obj.dataset``, identity frame and poses. The part ids are the source part names, as the
official names them.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import trimesh

from aw.assembly import AssembledObject
from aw.formats.common import PART_ID_PATTERN
from aw.prepare.official_protocol import OfficialPart, OfficialPrepared, OfficialSample, prepare_official
from aw.prepare.standardize import PreparedObject, PreparedPart

__all__ = ["OFFICIAL_DATASETS", "official_sample", "prepare_official_object", "write_eval_points"]

# The official adapters' repository ids (assembly_world_agent/adapters/*.py, REPO_ID).
OFFICIAL_DATASETS = {
    "partnet": "AssemblyWorld/partnet-manualpa",
    "ikea_manual": "AssemblyWorld/ikea-manual",
    "assemblybench": "AssemblyWorld/assemblybench",
    "fantastic_breaks": "AssemblyWorld/fantastic-breaks",
    "breaking_bad": "AssemblyWorld/breaking-bad-volume-constrained",
}


def official_sample(obj: AssembledObject) -> OfficialSample:
    """The official adapters' view of ``obj`` (see the module doc)."""
    info = obj.meta.get("official", {}) if isinstance(obj.meta, dict) else {}
    frame = np.asarray(info.get("source_to_z_up", np.eye(3)), dtype=np.float64)
    faces, local, poses = info.get("faces", {}), info.get("local", {}), info.get("poses", {})
    parts = []
    for p in obj.parts:
        if not re.fullmatch(PART_ID_PATTERN, p.name):
            raise ValueError(f"object {obj.object_id}: part id {p.name!r} cannot name a task part ({PART_ID_PATTERN})")
        if p.name in local:
            vertices = np.asarray(local[p.name], dtype=np.float64)
        else:  # undo the loader's turn to Z up (a signed permutation: exact)
            vertices = np.asarray(p.mesh.vertices, dtype=np.float64) @ frame
        polygons = faces.get(p.name)
        polygons = tuple(tuple(int(i) for i in f) for f in (polygons if polygons is not None else p.mesh.faces))
        pose = tuple(
            float(x) for x in poses.get(p.name, (0, 0, 0, 1, 0, 0, 0))
        )  # prepare_official reads it as the adapters do
        parts.append(OfficialPart(p.name, vertices, polygons, pose))
    dataset = str(info.get("dataset") or OFFICIAL_DATASETS.get(obj.source, obj.dataset))
    return OfficialSample(dataset, str(info.get("sample_id", obj.object_id)), tuple(parts), frame)


def prepare_official_object(obj: AssembledObject, seed: int = 0) -> tuple[PreparedObject, OfficialPrepared]:
    """``obj`` prepared by the official protocol, as a :class:`PreparedObject` for the task
    writer (and reference rendering) and the official result itself."""
    done = prepare_official(official_sample(obj), seed)
    meshes = {p.name: p.mesh for p in obj.parts}
    parts = []
    for pid, baked, target in zip(done.part_ids, done.vertices, done.targets, strict=True):
        parts.append(
            PreparedPart(pid, pid, trimesh.Trimesh(baked, np.asarray(meshes[pid].faces), process=False), target)
        )
    upright = np.concatenate([np.asarray(p.mesh.vertices, dtype=np.float64) for p in obj.parts])
    centre = 0.5 * (upright.min(axis=0) + upright.max(axis=0))
    hint = sorted(g for g in done.groups if len(g) > 1) or None
    prep = PreparedObject(obj, seed, 1.0 / done.scale, centre, parts, hint, done.divisor, {"kind": "original"})
    return prep, done


def write_eval_points(suite_dir: str | Path, task_id: str, done: OfficialPrepared) -> Path:
    """``SUITE/eval_points/<task_id>.npz``: the official evaluation inputs of a task.

    Keys (those :func:`aw.official.suite_eval_inputs` reads): ``part_ids (P,)``, ``points (P, 1000,
    3)``, ``target_poses (P, 7)``, ``scale_divisor ()``, ``equivalence_groups (P,)`` group labels;
    for the fracture protocol (:func:`aw_eval.fracture.fracture_metrics`) also ``dataset``,
    ``sample_id`` (the names of its random streams) and ``fracture_divisor ()``.
    """
    path = Path(suite_dir) / "eval_points" / f"{task_id}.npz"
    path.parent.mkdir(parents=True, exist_ok=True)
    label = {pid: g for g, members in enumerate(done.groups) for pid in members}
    np.savez(
        path,
        part_ids=np.asarray(done.part_ids),
        points=np.asarray(done.points, dtype=np.float64),
        target_poses=np.asarray(done.targets, dtype=np.float64),
        scale_divisor=np.float64(done.divisor),
        equivalence_groups=np.asarray([label[pid] for pid in done.part_ids], dtype=np.int64),
        dataset=np.asarray(done.dataset),
        sample_id=np.asarray(done.sample_id),
        fracture_divisor=np.float64(done.fracture_divisor),
    )
    return path
