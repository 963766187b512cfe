"""Acceptance: an official-format fixture (package + MuJoCo episode archive) built from a native
task scores its recorded states exactly like the native path (suite + trajectory)."""

from __future__ import annotations

import numpy as np
import trimesh

from aw.assembly import AssembledObject, SourcePart
from aw.formats import FinalState, TrajectoryCall, TrajectoryHeader, TrajectoryWriter, read_trajectory, write_final
from aw.formats.suite import suite_paths
from aw.official import convert, suite_geometry
from aw.pose import compose_poses
from aw.prepare import prepare_object

from official_fixtures import episode_members, write_archive, write_package


def _object() -> AssembledObject:
    def box(size, centre):
        m = trimesh.creation.box(extents=size)
        return trimesh.Trimesh(np.asarray(m.vertices) + centre, m.faces, process=False)

    # three parts keep the evaluator's pairwise equivalence search (1000 points per part) short
    parts = [SourcePart("top", box((0.6, 0.4, 0.04), (0, 0, 0.5)))]
    for k, (x, y) in enumerate([(-0.25, -0.15), (0.25, 0.15)]):
        parts.append(SourcePart(f"leg{k}", box((0.04, 0.06, 0.48), (x, y, 0.24))))
    return AssembledObject("tbl", "partnet", "test", "table", parts, equivalence=[["leg0", "leg1"]])


def _frames(targets: np.ndarray) -> np.ndarray:
    """``(F, P, 7)``: identity, parts moved one by one to (slightly off) targets, then one fixed."""
    p = len(targets)
    cur = np.tile([0, 0, 0, 1.0, 0, 0, 0], (p, 1))
    out = [cur.copy()]
    nudge = np.array([0.004, -0.003, 0.002, 1.0, 0.0, 0.0, 0.0])
    for i in range(p):
        cur[i] = compose_poses(nudge, targets[i]) if i % 2 else targets[i]
        out.append(cur.copy())
    cur[1] = targets[1]
    out.append(cur.copy())
    out = np.stack(out)
    out[..., 3:] /= np.linalg.norm(out[..., 3:], axis=-1, keepdims=True)
    out[..., 3:] *= np.where(out[..., 3:4] < 0, -1.0, 1.0)  # MuJoCo keeps the sign; compare like with like
    return out


def test_official_path_matches_native_path(tmp_path):
    from aw_eval import ProtocolSettings, load_task_geometry, score

    suite = tmp_path / "suite"
    (entry,) = prepare_object(_object(), suite, ("none",))
    task_dir, targets_path = suite_paths(suite, entry.task_id)
    # the paper's protocol: 4096 surface candidates, 1000 farthest-point samples per part
    native = load_task_geometry(task_dir, targets_path, cache_dir=tmp_path / "cache", settings=ProtocolSettings())
    assert native.clouds.shape == (3, 1000, 3)
    assert sorted(len(g) for g in native.groups) == [1, 2]  # the legs are interchangeable
    ids = list(native.part_ids)
    from aw.formats import read_targets

    targets = read_targets(targets_path)
    target_poses = np.array([targets.parts[p].pose for p in ids])
    frames = _frames(target_poses)

    # native run: a trajectory whose checkpoints are the frames
    run = tmp_path / "runs" / "sys" / entry.task_id
    w = TrajectoryWriter(run / "trajectory.jsonl", TrajectoryHeader(
        task_id=entry.task_id, system="sys", started_at="2025-01-01T00:00:00Z", part_ids=ids,
        initial_poses={p: frames[0][k].tolist() for k, p in enumerate(ids)}))
    for f in range(1, len(frames)):
        w.call(TrajectoryCall(seq=f, t=float(f), tool="set_object_pose", args={}, ok=True, changed=[ids[0]],
                              poses={p: frames[f][k].tolist() for k, p in enumerate(ids)}))
    w.close()
    write_final(run / "final.json", FinalState(task_id=entry.task_id, reason="finished",
                                                poses={p: frames[-1][k].tolist() for k, p in enumerate(ids)}))

    # the same task and states in the official formats
    groups_label = np.zeros(len(ids), dtype=np.int64)
    for g, members in enumerate(native.groups):
        for m in members:
            groups_label[ids.index(m if isinstance(m, str) else ids[m])] = g
    pkg = write_package(tmp_path / "pkg", [{"sample_id": entry.task_id, "source": "partnet", "condition": "none", "n_parts": len(ids)}],
                        {entry.task_id: dict(part_ids=np.array(ids), points=np.asarray(native.clouds), target_poses=target_poses,
                                             scale_divisor=np.float64(native.divisor), equivalence_groups=groups_label)})
    half = [(0.05, 0.05, 0.05)] * len(ids)
    write_archive(tmp_path / "eps" / "sys" / entry.task_id / "final.episode.zip", episode_members(ids, half, frames),
                  {"sample_id": entry.task_id})
    _, (orun,) = convert(pkg, tmp_path / "eps", tmp_path / "osuite", tmp_path / "oruns")
    official = suite_geometry(tmp_path / "osuite", entry.task_id)

    ntraj = read_trajectory(run / "trajectory.jsonl")
    otraj = read_trajectory(orun / "trajectory.jsonl")
    ncp, ocp = ntraj.checkpoints(), otraj.checkpoints()
    assert len(ncp) == len(ocp) == len(frames)
    for a, b in zip(ncp, ocp):
        assert np.array_equal([a.poses[p] for p in ids], [b.poses[p] for p in ids])

    for poses_n, poses_o in [(ntraj.final_poses(), otraj.final_poses()), (ncp[2].poses, ocp[2].poses)]:
        rn = score(native, np.array([poses_n[p] for p in ids]), mode="fast")
        ro = score(official, np.array([poses_o[p] for p in ids]), mode="fast")
        assert (rn.pa, rn.sr, rn.sra) == (ro.pa, ro.sr, ro.sra)
        assert rn.scd == ro.scd
        assert np.array_equal(rn.part_errors, ro.part_errors)
    final = score(official, np.array([otraj.final_poses()[p] for p in ids]), mode="fast")
    assert final.pa == 1.0 and final.sr == 1.0

    # aw-score reads the converted suite (no task dirs: the official points) and scores every state
    import json

    from aw_eval.cli import main

    out = tmp_path / "out"
    rc = main([str(tmp_path / "osuite"), str(tmp_path / "oruns"), "--out", str(out), "--jobs", "1", "--mode", "fast",
               "--final", "fast", "--bootstrap", "200", "--permutations", "500", "--no-progress", "--no-plots"])
    assert rc == 0
    doc = json.loads((out / "scores.json").read_text())
    (r,) = [r for r in doc["runs"] if r["task_id"] == entry.task_id]
    assert r["status"] == "scored", r
    direct = score(native, np.array([ntraj.final_poses()[p] for p in ids]), mode="fast")
    assert r["sr"] == float(direct.sr) == 1.0
    assert r["pa"] == 100 * float(direct.pa)
    assert r["scd"] == float(direct.scd)
    assert doc["tasks"][0]["n_parts"] == len(ids)
