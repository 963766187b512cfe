"""The external-command interface: the request file a refiner reads and the result file it
writes (schemas in ``docs/formats.md``, "Refiner exchange")."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aw.cli.common import plural
from aw.formats.common import pose_problem
from aw.formats.errors import FormatError
from aw.formats.io import write_json_atomic
from aw.formats.strict_json import JsonLimits, read_json, read_json_object
from aw.refine.base import RefineRequest, RefinerError

__all__ = ["REQUEST_FORMAT", "RESULT_FORMAT", "read_request", "read_result", "write_request", "write_result"]

REQUEST_FORMAT = "assemblyworld.refine-request"
RESULT_FORMAT = "assemblyworld.refine-result"
# A result holds 7 numbers a part: 16 MiB is far beyond any answer, and bounds what is read.
RESULT_LIMITS = JsonLimits(max_document_bytes=16 << 20)


def write_request(path: str | Path, request: RefineRequest) -> None:
    """Write ``request`` as JSON (points as nested lists in the part's mesh frame)."""
    doc = {
        "format": REQUEST_FORMAT,
        "format_version": 1,
        "task_id": request.task_id,
        "part_ids": list(request.part_ids),
        "anchor": request.part_ids[request.anchor],
        "points": {
            pid: np.asarray(p, dtype=float).tolist() for pid, p in zip(request.part_ids, request.points, strict=True)
        },
        "meshes": dict(zip(request.part_ids, request.mesh_paths, strict=True)),
        "initial_poses": {
            pid: [float(v) for v in p] for pid, p in zip(request.part_ids, request.initial_poses, strict=True)
        },
        "given_initial_poses": bool(request.given_initial_poses),
        "seed": int(request.seed),
        "steps": int(request.steps),
        "options": dict(request.options),
    }
    write_json_atomic(path, doc)


def read_request(path: str | Path) -> RefineRequest:
    """A request file back as :class:`RefineRequest` (meshes loaded from their paths)."""
    from aw.meshes import load_mesh

    doc = read_json_object(path)
    if doc.get("format") != REQUEST_FORMAT:
        raise ValueError(f"{path}: not a {REQUEST_FORMAT} file")
    ids = list(doc["part_ids"])
    meshes = []
    for pid in ids:
        m = load_mesh(doc["meshes"][pid])
        meshes.append((np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces)))
    return RefineRequest(
        task_id=doc["task_id"],
        part_ids=ids,
        points=[np.asarray(doc["points"][pid], dtype=np.float64) for pid in ids],
        meshes=meshes,
        mesh_paths=[doc["meshes"][pid] for pid in ids],
        initial_poses=np.asarray([doc["initial_poses"][pid] for pid in ids], dtype=np.float64),
        given_initial_poses=bool(doc.get("given_initial_poses", False)),
        seed=int(doc.get("seed", 42)),
        steps=int(doc.get("steps", 20)),
        options=dict(doc.get("options") or {}),
    )


def write_result(path: str | Path, part_ids: list[str], poses: np.ndarray) -> None:
    write_json_atomic(
        path,
        {
            "format": RESULT_FORMAT,
            "format_version": 1,
            "poses": {pid: [float(v) for v in p] for pid, p in zip(part_ids, np.asarray(poses), strict=True)},
        },
    )


def read_result(name: str, path: str | Path, part_ids: list[str]) -> list[list[float]]:
    """The poses of a result file in ``part_ids`` order (checked further by
    :func:`aw.refine.base.check_poses`); :class:`RefinerError` naming the refiner and the file
    when it is missing, refused by the JSON reader (:mod:`aw.formats.strict_json`, within
    :data:`RESULT_LIMITS`), names other parts, or holds a pose that no recording would accept
    (:func:`aw.formats.common.pose_problem`: a position beyond +-1e6, say)."""
    path = Path(path)
    if not path.is_file():
        raise RefinerError(f"refiner {name}: wrote no result file {path.name}")
    try:
        doc = read_json(path, limits=RESULT_LIMITS)
    except FormatError as exc:
        raise RefinerError(f"refiner {name}: result file {path.name}: {exc.problem}") from None
    poses = doc.get("poses") if isinstance(doc, dict) else None
    if not isinstance(poses, dict):
        raise RefinerError(f"refiner {name}: result file {path.name} has no 'poses' object {{part id: pose}}")
    missing = [p for p in part_ids if p not in poses]
    extra = [p for p in poses if p not in part_ids]
    if missing or extra:
        detail = "; ".join(
            x
            for x in (
                f"missing {', '.join(missing)}" if missing else "",
                f"unknown {', '.join(map(str, extra))}" if extra else "",
            )
            if x
        )
        raise RefinerError(
            f"refiner {name}: returned {plural(len(poses), 'pose')} for {plural(len(part_ids), 'part')} ({detail})"
        )
    out = []
    for pid in part_ids:
        p = poses[pid]
        if (
            not isinstance(p, list)
            or len(p) != 7
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in p)
        ):
            raise RefinerError(f"refiner {name}: pose of {pid} is not 7 numbers [x, y, z, qw, qx, qy, qz]")
        problem = pose_problem(p)
        if problem:
            raise RefinerError(f"refiner {name}: pose of {pid}: {problem}")
        out.append([float(v) for v in p])
    return out
