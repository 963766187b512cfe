"""Task geometry: loading real task directories, the cache, distractors, divisor, groups."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import trimesh

import aw_eval
from aw.formats import FormatError, PartTarget, Targets, Task, TaskPart, write_targets, write_task
from aw.pose import apply_pose, quat_to_matrix
from aw_eval.fixtures import make_object, random_rotation_quat
from aw_eval.geometry import part_divisor

SETTINGS = aw_eval.ProtocolSettings(n_surface=256, n_fps=48, max_iters=20)


def _write_task(root, n_parts=4, distractor=None, eval_divisor=None, seed=0, task_id="t1"):
    obj = make_object(n_parts, seed=seed)
    task_dir = root / "tasks" / task_id
    (task_dir / "parts").mkdir(parents=True, exist_ok=True)
    parts = []
    for pid, mesh in zip(obj.part_ids, obj.meshes, strict=True):
        mesh.export(task_dir / "parts" / f"{pid}.obj")
        parts.append(TaskPart(id=pid, mesh=f"parts/{pid}.obj"))
    write_task(
        task_dir, Task(task_id=task_id, source="custom", dataset="test", object_id="o1", prompt="assemble", parts=parts)
    )
    targets = Targets(
        task_id=task_id,
        parts={
            pid: PartTarget(pose=list(map(float, t)), distractor=(pid == distractor))
            for pid, t in zip(obj.part_ids, obj.target_poses, strict=True)
        },
        scale=1.0,
        eval_divisor=eval_divisor,
        equivalence_hint=[obj.part_ids[1:3]] if n_parts >= 3 else None,
    )
    tpath = root / "targets" / f"{task_id}.json"
    tpath.parent.mkdir(parents=True, exist_ok=True)
    write_targets(tpath, targets)
    return task_dir, tpath, obj


def test_cache_miss_then_hit(tmp_path):
    task_dir, tpath, obj = _write_task(tmp_path)
    cache = tmp_path / "cache"
    g1 = aw_eval.load_task_geometry(task_dir, tpath, cache_dir=cache, settings=SETTINGS)
    files = list(cache.glob("*.npz"))
    assert len(files) == 1 and files[0].stem == g1.key
    assert g1.clouds.shape == (4, 48, 3) and g1.part_ids == tuple(obj.part_ids)
    assert g1.equivalence_hint == (tuple(obj.part_ids[1:3]),)
    # A hit reads the cache: plant a recognisable cloud under the same key and get it back.
    planted = aw_eval.TaskGeometry(
        g1.part_ids, g1.clouds + 1.0, g1.target_poses, g1.divisor, g1.groups, SETTINGS, key=g1.key
    )
    planted.save(files[0])
    g2 = aw_eval.load_task_geometry(task_dir, tpath, cache_dir=cache, settings=SETTINGS)
    assert np.array_equal(g2.clouds, g1.clouds + 1.0) and g2.groups == g1.groups
    # other settings, or a changed target, are other entries
    aw_eval.load_task_geometry(
        task_dir, tpath, cache_dir=cache, settings=aw_eval.ProtocolSettings(n_surface=256, n_fps=40)
    )
    assert len(list(cache.glob("*.npz"))) == 2
    t = Targets.model_validate_json(tpath.read_text())
    t.parts[obj.part_ids[0]].pose[0] += 0.5
    write_targets(tpath, t)
    g3 = aw_eval.load_task_geometry(task_dir, tpath, cache_dir=cache, settings=SETTINGS)
    assert g3.key != g1.key and len(list(cache.glob("*.npz"))) == 3
    assert np.array_equal(g3.clouds, g1.clouds)  # same meshes, same samples


def test_cache_dir_from_environment(tmp_path, monkeypatch):
    task_dir, tpath, _ = _write_task(tmp_path, n_parts=2)
    monkeypatch.setenv("AW_CACHE_DIR", str(tmp_path / "envcache"))
    g = aw_eval.load_task_geometry(task_dir, tpath, settings=SETTINGS)
    assert (tmp_path / "envcache" / f"{g.key}.npz").is_file()


def test_distractors_are_not_scored(tmp_path):
    task_dir, tpath, obj = _write_task(tmp_path, n_parts=4, distractor="p03")
    g = aw_eval.load_task_geometry(task_dir, tpath, cache_dir=tmp_path / "c", settings=SETTINGS)
    assert g.part_ids == ("p01", "p02", "p04") and g.all_part_ids == ("p01", "p02", "p03", "p04")
    poses = {pid: list(obj.target_poses[i]) for i, pid in enumerate(obj.part_ids)}
    poses["p03"] = [9.0, 9, 9, 1, 0, 0, 0]  # wherever the distractor is, it does not count
    r = aw_eval.score(g, g.poses_from_dict(poses))
    assert r.pa == 1.0 and r.scd < 1e-20
    with pytest.raises(ValueError, match="not in this task"):
        g.poses_from_dict({**poses, "p99": [0, 0, 0, 1, 0, 0, 0]})
    with pytest.raises(ValueError, match="lack scored parts"):
        g.poses_from_dict({"p01": poses["p01"]})


def test_divisor_rule_and_override(tmp_path):
    box = trimesh.creation.box(extents=[0.3, 0.4, 1.2])
    rng = np.random.default_rng(0)
    rot = quat_to_matrix(random_rotation_quat(rng))
    assert part_divisor(np.asarray(box.vertices) @ rot.T + 5.0) == pytest.approx(np.sqrt(0.09 + 0.16 + 1.44))
    task_dir, tpath, obj = _write_task(tmp_path)
    g = aw_eval.load_task_geometry(task_dir, tpath, cache_dir=tmp_path / "c", settings=SETTINGS)
    assert g.divisor == pytest.approx(max(part_divisor(m.vertices) for m in obj.meshes), rel=1e-6)
    task_dir2, tpath2, _ = _write_task(tmp_path / "b", eval_divisor=2.5)
    assert aw_eval.load_task_geometry(task_dir2, tpath2, cache_dir=tmp_path / "c", settings=SETTINGS).divisor == 2.5


def test_bad_task_files_raise_format_errors(tmp_path):
    task_dir, tpath, obj = _write_task(tmp_path)
    _, other, _ = _write_task(tmp_path / "x", task_id="t2")
    with pytest.raises(FormatError, match="targets are for task"):
        aw_eval.load_task_geometry(task_dir, other, cache_dir=tmp_path / "c", settings=SETTINGS)
    t = Targets.model_validate_json(tpath.read_text())
    del t.parts["p04"]
    write_targets(tpath, t)
    with pytest.raises(FormatError, match="exactly the task's parts"):
        aw_eval.load_task_geometry(task_dir, tpath, cache_dir=tmp_path / "c", settings=SETTINGS)


def test_from_points_groups_and_pickling():
    rng = np.random.default_rng(0)
    clouds = rng.normal(size=(3, 20, 3))
    poses = np.tile([0.0, 0, 0, 1, 0, 0, 0], (3, 1))
    g = aw_eval.TaskGeometry.from_points(["a", "b", "c"], clouds, poses, 2.0, groups=[["c", "a"]])
    assert g.groups == ((0, 2), (1,)) and g.group_ids == [["a", "c"], ["b"]]
    with pytest.raises(ValueError, match="more than one group"):
        aw_eval.TaskGeometry.from_points(["a", "b", "c"], clouds, poses, 2.0, groups=[["a", "b"], ["b"]])
    with pytest.raises(ValueError, match="unknown"):
        aw_eval.TaskGeometry.from_points(["a", "b", "c"], clouds, poses, 2.0, groups=[["a", "z"]])
    with pytest.raises(ValueError, match="divisor"):
        aw_eval.TaskGeometry.from_points(["a", "b", "c"], clouds, poses, 0.0, groups=[])
    r1 = aw_eval.score(g, poses)
    g2 = pickle.loads(pickle.dumps(g))
    assert g2._derived == {} and aw_eval.score(g2, poses).scd == r1.scd


def test_centroids_are_baked_frame_sample_means():
    rng = np.random.default_rng(1)
    clouds = rng.normal(size=(2, 10, 3))
    g = aw_eval.TaskGeometry.from_points(["a", "b"], clouds, np.tile([1.0, 2, 3, 1, 0, 0, 0], (2, 1)), 1.0, groups=[])
    assert np.allclose(g.centroids, clouds.mean(axis=1))
    assert np.allclose(g.target_parts(), apply_pose(g.target_poses, clouds))


def test_checkpoint_has_its_rotations_and_clouds_once():
    """``TaskGeometry.checkpoint``: the poses' rotation matrices (read-only), the normalized
    predicted clouds built from them and their join, as scoring uses them; one checkpoint only."""
    import pytest

    from aw.pose import quat_to_matrix
    from aw_eval.fixtures import make_points_geometry

    geom, _ = make_points_geometry(3, 40, seed=1)
    rng = np.random.default_rng(2)
    poses = np.concatenate([rng.normal(size=(3, 3)), rng.normal(size=(3, 4))], axis=1)
    ck = geom.checkpoint(poses)
    assert np.array_equal(ck.rotations, quat_to_matrix(poses[:, 3:])) and not ck.rotations.flags.writeable
    assert np.array_equal(ck.parts, apply_pose(poses, geom.clouds, ck.rotations) / geom.divisor)
    assert ck.points.flags.c_contiguous and np.array_equal(ck.points, ck.parts.reshape(-1, 3))
    assert np.array_equal(geom.target_rotations(), quat_to_matrix(geom.target_poses[:, 3:]))
    with pytest.raises(ValueError, match="one checkpoint"):
        geom.checkpoint(np.stack([poses, poses]))
