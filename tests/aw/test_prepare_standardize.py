"""Standardized initialization (Appendix A.1): frames, scale, yaw, scatter, ids, targets."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import trimesh
from prepare_helpers import box, brute_force_scale, normalized_source, reassembled, stool

from aw.assembly import AssembledObject, SourcePart
from aw.formats import read_targets, read_task
from aw.formats.suite import suite_paths
from aw.meshes import load_task_meshes
from aw.pose import IDENTITY_POSE, pca_frame, rotation_about_axis
from aw.prepare import MIN_GAP, box_gap, prepare_object, standardize, unique_vertices
from aw.scene import scene_from_meshes
from aw.sources.synthetic import generate_object


@pytest.fixture(scope="module")
def objects():
    # a hand-made stool (degenerate cylinder spectra, one equivalence group), a synthetic
    # 16-part storage unit, an industrial assembly with fasteners and a fracture
    return [
        stool(),
        generate_object("partnet", 2),
        generate_object("assemblybench", 2),
        generate_object("fantastic_breaks", 0),
    ]


@pytest.fixture(scope="module")
def written(objects, tmp_path_factory):
    suite = tmp_path_factory.mktemp("suite")
    tasks = []
    for obj in objects:
        (entry,) = prepare_object(obj, suite, ["none"], seed=0)
        task_dir, targets_path = suite_paths(suite, entry.task_id)
        task = read_task(task_dir)
        tasks.append((obj, task, load_task_meshes(task), read_targets(targets_path)))
    return tasks


def test_each_baked_part_lies_in_its_right_handed_pca_frame_yawed_about_z(written):
    for obj, task, meshes, _ in written:
        for pid, mesh in zip(task.part_ids, meshes, strict=True):
            v = unique_vertices(mesh)
            _, axes = pca_frame(v)
            assert np.linalg.det(axes) == pytest.approx(1.0, abs=1e-9)
            # smallest principal axis along world Z; the other two in the XY plane
            np.testing.assert_allclose(axes[:, 2], [0, 0, 1], atol=1e-6, err_msg=f"{obj.object_id}/{pid}")
            np.testing.assert_allclose(axes[2, :2], [0, 0], atol=1e-6)
            local = (v - v.mean(axis=0)) @ axes
            var = local.var(axis=0)
            # descending variance (equal within file rounding for symmetric parts)
            assert var[0] >= var[1] * (1 - 1e-6) and var[1] >= var[2] * (1 - 1e-6)


def test_bounding_boxes_are_separated_by_the_minimum_gap_and_parts_rest_on_the_ground(written):
    for _obj, _task, meshes, _ in written:
        boxes = [(m.vertices.min(axis=0), m.vertices.max(axis=0)) for m in meshes]
        for (a_lo, a_hi), (b_lo, b_hi) in itertools.combinations(boxes, 2):
            assert box_gap(a_lo, a_hi, b_lo, b_hi) >= MIN_GAP
        for lo, _ in boxes:
            assert lo[2] == pytest.approx(0.0, abs=1e-8)


def test_initial_body_poses_are_identity(written):
    for _, task, meshes, _ in written:
        scene = scene_from_meshes(task.part_ids, meshes)
        for pose in scene.pose_dict().values():
            np.testing.assert_array_equal(pose, IDENTITY_POSE)


def test_targets_reassemble_the_normalized_object(written):
    for obj, task, meshes, targets in written:
        scale = brute_force_scale(obj)
        assert targets.scale == pytest.approx(scale, rel=1e-12)
        want = normalized_source(obj, scale)
        got = reassembled(targets, task.part_ids, meshes)
        assert set(got) == set(want)
        for name in want:
            np.testing.assert_allclose(got[name], want[name], atol=1e-6, err_msg=name)


def test_baking_follows_the_documented_draws_exactly():
    # baked part k = Rz(yaw_k) A_k^T scale (v - c_k) + translation, yaw_k from default_rng(seed)
    obj = stool()
    for seed in (0, 7):
        prep = standardize(obj, seed)
        yaws = np.random.default_rng(seed).uniform(-np.pi, np.pi, size=obj.n_parts)
        by_name = {p.source_name: p for p in prep.parts}
        for k, src in enumerate(obj.parts):
            v = np.asarray(src.mesh.vertices)
            c, axes = pca_frame(unique_vertices(v))
            expect = (v - c) @ axes * prep.scale @ rotation_about_axis(2, yaws[k]).T
            baked = np.asarray(by_name[src.name].mesh.vertices)
            shift = baked - expect
            np.testing.assert_allclose(shift, np.broadcast_to(shift[0], shift.shape), atol=1e-12)


def test_scale_is_twice_the_largest_vertex_radius_hand_computed():
    # a 2 x 1 x 0.5 box: corner radius sqrt(1 + 0.25 + 0.0625) about its centroid; a small cube
    big = box((2.0, 1.0, 0.5), (3.0, -1.0, 0.25))
    small = box((0.2, 0.2, 0.2), (0.0, 0.0, 0.1))
    obj = AssembledObject("o", "custom", "test", "", [SourcePart("big", big), SourcePart("small", small)])
    prep = standardize(obj)
    assert prep.scale == pytest.approx(1.0 / (2.0 * np.sqrt(1.3125)), rel=1e-12)
    # the normalized assembly is centred: bounding box of all vertices is x in [-0.1, 4], ...
    np.testing.assert_allclose(prep.centre, [(-0.1 + 4.0) / 2, (-1.5 + 0.1) / 2, 0.25])


def test_duplicate_and_unreferenced_vertices_do_not_change_frames_or_scale():
    obj = stool()
    base = standardize(obj)
    seat = obj.parts[0].mesh
    # unmerged faces (each triangle its own vertices) plus one far-away unreferenced vertex
    soup = np.asarray(seat.vertices)[np.asarray(seat.faces).ravel()]
    verts = np.vstack([soup, [[50.0, 50.0, 50.0]]])
    faces = np.arange(len(soup)).reshape(-1, 3)
    noisy = AssembledObject(
        obj.object_id,
        obj.source,
        obj.dataset,
        obj.category,
        [SourcePart("seat", trimesh.Trimesh(verts, faces, process=False)), *obj.parts[1:]],
        equivalence=obj.equivalence,
    )
    prep = standardize(noisy)
    assert prep.scale == pytest.approx(base.scale, rel=1e-12)
    a = {p.source_name: p for p in base.parts}["seat"]
    b = {p.source_name: p for p in prep.parts}["seat"]
    np.testing.assert_allclose(
        np.unique(np.round(b.mesh.vertices, 9), axis=0), np.unique(np.round(a.mesh.vertices, 9), axis=0), atol=1e-9
    )
    assert len(b.mesh.vertices) == len(soup)  # the unreferenced vertex is gone


def test_ids_are_anonymized_in_a_seeded_order_and_hints_translated():
    obj = generate_object("partnet", 1)  # 10 parts
    assignments = set()
    for seed in range(4):
        prep = standardize(obj, seed)
        ids = prep.part_ids
        assert ids == [f"p{k:02d}" for k in range(1, obj.n_parts + 1)]
        order = tuple(p.source_name for p in prep.parts)
        assignments.add(order)
        name_to_id = {p.source_name: p.part_id for p in prep.parts}
        expected = sorted(sorted(name_to_id[n] for n in g) for g in obj.equivalence)
        assert prep.equivalence_hint == expected
    assert len(assignments) == 4  # the id order depends on the seed...
    source_order = tuple(p.name for p in obj.parts)
    assert sum(order != source_order for order in assignments) >= 3  # ...and does not follow the source


def test_identical_parts_bake_to_congruent_meshes():
    prep = standardize(stool())
    legs = [p for p in prep.parts if p.source_name.startswith("leg")]
    centred = [np.asarray(p.mesh.vertices) - np.asarray(p.mesh.vertices).mean(axis=0) for p in legs]
    # congruent: same sorted distances to the centroid
    d = [np.sort(np.linalg.norm(c, axis=1)) for c in centred]
    np.testing.assert_allclose(d[0], d[1], atol=1e-12)
    np.testing.assert_allclose(d[0], d[2], atol=1e-12)


def test_invalid_objects_raise_clear_errors():
    point = trimesh.Trimesh(np.zeros((3, 3)), [[0, 1, 2]], process=False)
    obj = AssembledObject("flat", "custom", "test", "", [SourcePart("a", point), SourcePart("b", point.copy())])
    with pytest.raises(ValueError, match="single point"):
        standardize(obj)
    bad = stool()
    bad.equivalence = [["leg1", "nope"]]
    with pytest.raises(ValueError, match="unknown parts"):
        standardize(bad)


def test_parts_already_assembled_in_the_layout_are_found_and_refused(tmp_path):
    from dataclasses import replace

    from aw.pose import apply_pose, invert_pose
    from aw.prepare.standardize import assembled_at_start

    prep = standardize(stool())
    assert assembled_at_start(prep) == []  # the standardized layout moves every part on its own
    a, b, *rest = prep.parts
    # re-bake b so that the motion that assembles a also assembles b: the two stay together
    v = apply_pose(invert_pose(a.target), apply_pose(b.target, np.asarray(b.mesh.vertices)))
    glued = prep.with_parts(
        [a, replace(b, mesh=trimesh.Trimesh(v, b.mesh.faces, process=False), target=a.target.copy()), *rest]
    )
    assert assembled_at_start(glued) == [a.part_id, b.part_id]
    from aw.prepare.build import _check_assessable

    with pytest.raises(ValueError, match=rf"2 of its 5 parts \({a.part_id}, {b.part_id}\) are already assembled"):
        _check_assessable(glued)
    # one part: the registration puts it on its target whatever its pose
    single = AssembledObject("plate", "custom", "test", "", [SourcePart("plate", box((0.4, 0.3, 0.02), (0, 0, 0)))])
    assert assembled_at_start(standardize(single)) == [standardize(single).parts[0].part_id]
    with pytest.raises(ValueError, match=r"object plate cannot be assessed: its one part p01 is on its target"):
        prepare_object(single, tmp_path, ["none"])
    assert not (tmp_path / "tasks").exists()


def test_assembled_parts_are_those_of_checking_every_pair_on_every_vertex():
    """The pairs are screened on one vertex first: a part whose target turns about that very
    vertex (the same image there, not elsewhere) is still told apart, and the group is the one
    that checking every pair on every vertex gives."""
    from dataclasses import replace

    from aw.pose import apply_pose, compose_poses, invert_pose, matrix_to_quat
    from aw.prepare.standardize import ASSEMBLED_TOLERANCE, assembled_at_start

    def every_pair(prep) -> list[str]:  # the plain statement
        best: list[str] = []
        for a in prep.scored_parts:
            group = [
                b.part_id
                for b in prep.scored_parts
                if all(
                    np.abs(apply_pose(a.target, m.vertices) - apply_pose(b.target, m.vertices)).max()
                    <= ASSEMBLED_TOLERANCE
                    for m in (a.mesh, b.mesh)
                )
            ]
            best = group if len(group) > len(best) else best
        return best if len(best) >= 2 else []

    prep = standardize(stool())
    a, b, c, *rest = prep.parts
    v = apply_pose(invert_pose(a.target), apply_pose(b.target, np.asarray(b.mesh.vertices)))
    glued = replace(b, mesh=trimesh.Trimesh(v, b.mesh.faces, process=False), target=a.target.copy())
    pivot = np.asarray(a.mesh.vertices[0], dtype=np.float64)
    turn = rotation_about_axis(2, 0.05)
    about_pivot = np.concatenate([pivot - turn @ pivot, matrix_to_quat(turn)])
    turned = replace(c, target=compose_poses(a.target, about_pivot))
    assert np.abs(apply_pose(turned.target, pivot[None]) - apply_pose(a.target, pivot[None])).max() < 1e-12
    mixed = prep.with_parts([a, glued, turned, *rest])
    assert assembled_at_start(mixed) == every_pair(mixed) == [a.part_id, b.part_id]
    assert assembled_at_start(prep) == every_pair(prep) == []
