"""The classical refiner on real generated fractures: the global search puts the fragments
back together from a random layout, local refinement pulls a near start onto the fit, and a task
it cannot handle fails by name."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from fracture_suite import fragments
from scipy.spatial.transform import Rotation

from aw.formats import read_targets, read_task
from aw.prepare.official_protocol import pose_of, rotation_of
from aw.refine.base import RefinerError
from aw.refine.classical import _candidates, refine, segment_regions
from aw.refine.plugins import resolve, run_refiner
from aw.refine.runs import build_request
from aw_eval.fracture import fracture_metrics_from_samples


def _task(suite, tid):
    task = read_task(suite / "tasks" / tid)
    targets = read_targets(suite / "targets" / f"{tid}.json")
    return task, np.array([targets.parts[p].pose for p in task.part_ids])


@pytest.mark.parametrize("tid", ["frac_cylinder_1", "frac_hex_prism_2"])
def test_global_search_reassembles_two_fragments(fracture_suite, tid):
    task, target = _task(fracture_suite, tid)
    request = build_request(task, fracture_suite, None)
    poses = refine(request)
    assert np.array_equal(poses[request.anchor], request.initial_poses[request.anchor])
    m = fracture_metrics_from_samples(request.points, poses, target, 1.0)
    start = fracture_metrics_from_samples(request.points, request.initial_poses, target, 1.0)
    assert m.pa == 1.0 and m.re < 2.0 and m.te < 0.01, (m.re, m.te, m.pa)
    assert start.pa < 1.0  # the layout itself is not assembled


def test_local_refinement_pulls_a_near_start_onto_the_fit(fracture_suite):
    task, target = _task(fracture_suite, "frac_hex_prism_2")
    request = build_request(task, fracture_suite, None)
    a, b = request.anchor, 1 - request.anchor
    # the other fragment where the target puts it relative to the anchor, then 8 degrees and a shift off
    ra, rb = rotation_of(target[a, 3:]), rotation_of(target[b, 3:])
    rel_r, rel_t = ra.T @ rb, ra.T @ (target[b, :3] - target[a, :3])
    nudge = Rotation.from_rotvec(np.radians(8) * np.array([0.6, 0.8, 0.0])).as_matrix()
    start = np.array(request.initial_poses)
    start[b] = pose_of(rel_t + np.array([0.02, -0.01, 0.015]), nudge @ rel_r)
    near = build_request(task, fracture_suite, {p: list(q) for p, q in zip(task.part_ids, start, strict=True)})
    assert near.given_initial_poses
    before = fracture_metrics_from_samples(near.points, start, target, 1.0)
    after = fracture_metrics_from_samples(near.points, refine(near), target, 1.0)
    assert after.re < 1.0 and after.te < 0.005 and after.re < before.re / 4, (before.re, after.re, after.te)


@pytest.mark.parametrize("category", ["hex_prism", "bar", "cylinder"])
def test_the_break_is_one_candidate_region(category):
    """The generator writes the lower fragment's faces as bottom cap, break, wall; the break's
    faces (a polar grid of 10 rings of 48) must come out as a non-planar candidate region (most
    of it: where the height field is clipped it folds sharply), and the flat cap must not."""
    a, _ = fragments(category, 2)
    mesh = trimesh.Trimesh(a.vertices, a.faces, process=True)
    assert len(mesh.faces) == len(a.faces)
    regions = segment_regions(mesh)
    assert sorted(np.concatenate(regions).tolist()) == list(range(len(a.faces)))  # a partition
    grid = 48 + 2 * 48 * 9
    size = float(np.ptp(mesh.vertices, axis=0).max())
    brk = set(range(grid, 2 * grid))
    candidates = [set(c.tolist()) for c in _candidates(mesh, size)]
    best = max(candidates, key=lambda c: len(c & brk))
    assert best <= brk and len(best) >= 0.8 * len(brk)
    assert not any(c & set(range(grid)) for c in candidates)


def test_more_than_two_fragments_fail_by_name(fracture_suite, tmp_path):
    task, _ = _task(fracture_suite, "frac_cylinder_1")
    request = build_request(task, fracture_suite, None)
    request.part_ids = ["a", "b", "c"]
    request.points = request.points + [request.points[0][:10]]
    request.meshes = request.meshes + [request.meshes[0]]
    request.mesh_paths = request.mesh_paths + [request.mesh_paths[0]]
    request.initial_poses = np.vstack([request.initial_poses, request.initial_poses[:1]])
    with pytest.raises(
        RefinerError,
        match="refiner classical: ValueError: the classical refiner handles two-fragment tasks, got 3 parts",
    ):
        run_refiner(resolve("classical"), request, tmp_path, 120)
