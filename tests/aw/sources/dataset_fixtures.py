"""Writers of tiny datasets in the published layouts (used by the loader and composition tests).

Every writer builds real files under a given folder; nothing here is a mock of a loader.
"""

from __future__ import annotations

import io
import itertools
import json
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

from aw.pose import matrix_to_quat, quat_to_matrix


def box(size, centre=(0, 0, 0)) -> trimesh.Trimesh:
    m = trimesh.creation.box(extents=size)
    return trimesh.Trimesh(np.asarray(m.vertices) + np.asarray(centre, float), m.faces, process=False)


def chair_boxes(n_legs: int = 4) -> list[tuple[tuple, tuple]]:
    """(size, centre) per part of a Z-up chair: seat, back, legs (all legs identical)."""
    out = [((0.5, 0.4, 0.04), (0, 0, 0.45)), ((0.5, 0.03, 0.4), (0, -0.2, 0.7))]
    for k in range(n_legs):
        a = 2 * np.pi * k / n_legs + np.pi / 4
        out.append(((0.04, 0.04, 0.43), (0.2 * np.cos(a), 0.15 * np.sin(a), 0.215)))
    return out


def z_to_y(v: np.ndarray) -> np.ndarray:
    """Inverse of aw.assembly.y_up_to_z_up: (x, y, z) -> (x, z, -y)."""
    v = np.asarray(v, float)
    return np.stack([v[:, 0], v[:, 2], -v[:, 1]], axis=1)


def png(path: Path, colour=(200, 10, 10), size=(24, 16)) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.new("RGB", size, colour).save(path)
    return path


def png_bytes(colour=(10, 200, 10), size=(24, 16)) -> bytes:
    buf = io.BytesIO()
    Image.new("RGB", size, colour).save(buf, format="PNG")
    return buf.getvalue()


def random_rotation(rng) -> np.ndarray:
    q = rng.normal(size=4)
    return quat_to_matrix(q / np.linalg.norm(q))


# ---------------------------------------------------------------- PartNet (DGL / Manual-PA)
def partnet_shape(
    root: Path,
    shape_id: str,
    n_parts: int,
    level: int = 3,
    seed: int = 0,
    n_points: int = 200,
    meshes: str | None = None,
    pages: int = 0,
) -> dict:
    """``shape_data/<id>_level<k>.npy`` for a chair-like shape with ``n_parts`` parts (two boxes
    plus identical legs), Y up; ``meshes``: also write part meshes in the ``canonical`` or
    ``assembled`` frame. Returns the dict and the Z-up assembled boxes."""
    rng = np.random.default_rng(seed)
    boxes = chair_boxes(max(0, n_parts - 2))[:n_parts]
    pcs, poses, assembled = [], [], []
    mesh_dir = root / "part_meshes" / f"{shape_id}_level{level}"
    for i, (size, centre) in enumerate(boxes):
        m = box(size)  # canonical: centred at the origin
        pts = np.asarray(trimesh.sample.sample_surface(m, n_points, seed=seed + i)[0])
        pts[:8] = m.vertices  # the corners: the hull of the points is the box itself
        rot = random_rotation(rng)
        canon = pts @ rot  # the canonical part is the box rotated by rot^T
        centre_y = z_to_y(np.asarray([centre]))[0]
        rot_y = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], float)  # Z-up -> Y-up rotation
        r_pose = rot_y @ rot
        pcs.append(canon.astype(np.float32))
        poses.append(np.concatenate([centre_y, matrix_to_quat(r_pose)]))
        assembled.append(box(size, centre))
        if meshes:
            mesh_dir.mkdir(parents=True, exist_ok=True)
            cv = np.asarray(m.vertices) @ rot
            v = cv if meshes == "canonical" else cv @ r_pose.T + centre_y
            trimesh.Trimesh(v, m.faces, process=False).export(mesh_dir / f"{i}.obj")
    data = {
        "part_pcs": np.stack(pcs),
        "part_poses": np.stack(poses),
        "part_ids": np.arange(n_parts) % 3,
        "geo_part_ids": np.array([0, 1] + [2] * (n_parts - 2))[:n_parts],
        "sym": np.zeros((n_parts, 8)),
    }
    (root / "shape_data").mkdir(parents=True, exist_ok=True)
    np.save(root / "shape_data" / f"{shape_id}_level{level}.npy", data)
    for k in range(pages):
        png(root / "diagrams" / shape_id / f"step_{k + 1}.png", (20 * k, 0, 0))
    return {"data": data, "assembled": assembled}


def partnet_dataset(root: Path, shapes: dict[str, list[tuple[str, int]]], split: str = "test", **kw) -> Path:
    """Split lists ``<Category>.<split>.npy`` and one shape file per (id, n_parts)."""
    root.mkdir(parents=True, exist_ok=True)
    for cat, items in shapes.items():
        np.save(root / f"{cat}.{split}.npy", np.array([int(i) for i, _ in items]))
        for sid, n in items:
            partnet_shape(root, sid, n, seed=int(sid) % 97, n_points=60, **kw)
    return root


# ---------------------------------------------------------------- IKEA-Manual
def ikea_object(root: Path, category: str, name: str, n_parts: int, pages: int = 2, write_parts: bool = True) -> dict:
    boxes = chair_boxes(max(0, n_parts - 2))[:n_parts]
    d = root / "parts" / category / name
    if write_parts:
        d.mkdir(parents=True, exist_ok=True)
        for i, (size, centre) in enumerate(boxes):
            m = box(size, centre)
            trimesh.Trimesh(z_to_y(m.vertices), m.faces, process=False).export(d / f"{i}.obj")
    for k in range(pages):
        png(root / "manual_img" / category / name / f"page_{k + 1}.png", (0, 20 * k, 0))
    legs = [str(i) for i in range(2, n_parts)]
    rec = {
        "category": category,
        "name": name,
        "parts_ct": n_parts,
        "steps": [
            {"step_id": 0, "page_id": 1, "parts": legs[:2] + ["0"]},
            {"step_id": 1, "page_id": 2, "parts": ["0," + ",".join(legs), "1"]},
        ],
        "connection_relation": [[0, int(x)] for x in legs] + [[0, 1]],
        "geometric_equivalence_relation": [legs] if len(legs) > 1 else [],
        "assembly_tree": {"0": {"children": legs}},
    }
    return rec


def ikea_dataset(root: Path, objects: list[tuple[str, str, int]], pages: int = 2) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    recs = [ikea_object(root, c, n, k, pages) for c, n, k in objects]
    (root / "main_data.json").write_text(json.dumps(recs))
    return root


# ---------------------------------------------------------------- fractures
def fractured_box(n_pieces: int, seed: int = 0) -> list[trimesh.Trimesh]:
    """A box cut into slabs along X, each slab a closed box (shared faces are the "fracture")."""
    xs = np.linspace(-0.5, 0.5, n_pieces + 1)
    rng = np.random.default_rng(seed)
    out = []
    for a, b in itertools.pairwise(xs):
        m = box((b - a, 0.6 + 0.1 * rng.random(), 0.4), ((a + b) / 2, 0, 0))
        out.append(m)
    return out


def breaking_bad_dataset(root: Path, objects: list[tuple[str, str, str, str, int]]) -> Path:
    """(subset, Category, shape, fracture, n_pieces) -> <subset>/<Category>/<shape>/<fracture>/piece_<i>.obj"""
    for subset, cat, shape, frac, n in objects:
        d = root / subset / cat / shape / frac
        d.mkdir(parents=True, exist_ok=True)
        for i, m in enumerate(fractured_box(n)):
            m.export(d / f"piece_{i}.obj")
    return root


def breaking_bad_h5(path: Path, objects: list[tuple[str, int]]) -> Path:
    import h5py

    with h5py.File(path, "w") as h5:
        for key, n in objects:
            for i, m in enumerate(fractured_box(n)):
                g = h5.create_group(f"{key}/pieces/{i}")
                g.create_dataset("vertices", data=np.asarray(m.vertices))
                g.create_dataset("faces", data=np.asarray(m.faces, dtype=np.int64))
    return path


def fantastic_breaks_dataset(root: Path, objects: list[tuple[str, str]]) -> Path:
    for cls, obj in objects:
        d = root / cls / obj
        d.mkdir(parents=True, exist_ok=True)
        b, r = fractured_box(2)
        b.export(d / "model_b_0.ply")
        r.export(d / "model_r_0.ply")
        trimesh.util.concatenate([b, r]).export(d / "model_c.ply")
        np.savez(d / "meta_0.npz", break_axis=np.array([1.0, 0.0, 0.0]), points=np.zeros((500, 3)))
    return root


# ---------------------------------------------------------------- AssemblyBench
def assemblybench_object(
    root: Path, category: str, name: str, n_parts: int, views: int = 2, layout: str = "folders", seed: int = 0
) -> list[trimesh.Trimesh]:
    """Parts in local frames, per-view per-step poses, one diagram per step. Returns the
    assembled parts (Z up) as seen in view 0."""
    rng = np.random.default_rng(seed)
    d = root / category / name
    (d / "parts").mkdir(parents=True, exist_ok=True)
    assembled, local = [], []
    for i in range(n_parts):
        m = box((0.1 + 0.02 * i, 0.1, 0.05 + 0.01 * (i % 3)), (0.3 * i, 0.05 * (i % 2), 0.1 * i))
        assembled.append(m)
        rot = random_rotation(rng)
        c = np.asarray(m.vertices).mean(axis=0)
        lv = (np.asarray(m.vertices) - c) @ rot  # local = R^T (v - c)
        trimesh.Trimesh(lv, m.faces, process=False).export(d / "parts" / f"part{i}.obj")
        local.append((rot, c))
    steps = [list(range(0, min(2, n_parts)))] + [[i] for i in range(2, n_parts)]
    all_views = []
    for v in range(views):
        view_rot = random_rotation(rng) if v else np.eye(3)
        view_t = rng.normal(size=3) if v else np.zeros(3)
        present: list[int] = []
        per_step = []
        for step in steps:
            present = present + step
            poses = {}
            for i in present:
                rot, c = local[i]
                r = view_rot @ rot
                t = view_rot @ c + view_t
                poses[f"part{i}"] = [*t.tolist(), *matrix_to_quat(r).tolist()]
            per_step.append(poses)
        all_views.append(per_step)
    if layout == "folders":
        for v, per_step in enumerate(all_views):
            (d / "poses" / f"view_{v}").mkdir(parents=True, exist_ok=True)
            for s, poses in enumerate(per_step):
                (d / "poses" / f"view_{v}" / f"step_{s}.json").write_text(json.dumps(poses))
    else:
        (d / "poses.json").write_text(json.dumps({"views": all_views}))
    for s in range(len(steps)):
        png(d / "diagrams" / f"step_{s}.png", (0, 0, 30 * s))
    return assembled


# ---------------------------------------------------------------- re-hosted rows
def quad_box(size, centre) -> tuple[list, list]:
    """A box as 8 vertices and 6 quads (outward)."""
    sx, sy, sz = np.asarray(size, float) / 2
    v = [[x, y, z] for x in (-sx, sx) for y in (-sy, sy) for z in (-sz, sz)]
    v = (np.asarray(v) + np.asarray(centre, float)).tolist()
    quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    return v, quads


def rehosted_row(object_id: str, source: str, category: str, n_parts: int, pages: int = 2, up_axis: str = "z") -> dict:
    parts = []
    for i, (size, centre) in enumerate(chair_boxes(max(0, n_parts - 2))[:n_parts]):
        v, f = quad_box(size, centre)
        if up_axis == "y":
            v = z_to_y(np.asarray(v)).tolist()
        parts.append({"part_id": str(i), "vertices": v, "faces": f})
    legs = [str(i) for i in range(2, n_parts)]
    return {
        "object_id": object_id,
        "source": source,
        "category": category,
        "parts": parts,
        "parts_ct": n_parts,
        "geometric_equivalence_relation": [legs] if len(legs) > 1 else [],
        "manual_pages": [
            {"page": k, "step": k, "image": {"bytes": png_bytes((0, 0, 40 * k)), "path": f"p{k}.png"}}
            for k in range(pages)
        ],
        "up_axis": up_axis,
    }


def write_rehosted(path: Path, rows: list[dict], fmt: str = "parquet", row_group_size: int | None = None) -> Path:
    import pyarrow as pa

    table = pa.Table.from_pylist(rows)
    path.parent.mkdir(parents=True, exist_ok=True)
    if fmt == "parquet":
        import pyarrow.parquet as pq

        pq.write_table(table, path, row_group_size=row_group_size)
    elif fmt == "arrow-file":
        with pa.OSFile(str(path), "wb") as sink, pa.ipc.new_file(sink, table.schema) as w:
            w.write_table(table)
    else:
        with pa.OSFile(str(path), "wb") as sink, pa.ipc.new_stream(sink, table.schema) as w:
            w.write_table(table)
    return path
