"""The classical refiner on real generated breaks: the global search puts rough breaks, planar
cuts and a 3-piece break back together from a scattered layout, local refinement pulls a near
start onto the fit, and a start it cannot improve comes back unchanged with a line saying so."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from fracture_suite import fragments
from scipy.spatial.transform import Rotation

from aw.formats import read_targets, read_task
from aw.prepare.official_protocol import pose_of, rotation_of
from aw.refine.classical import refine
from aw.refine.classical.contact import tolerance
from aw.refine.classical.pairs import register_pair, score_fit
from aw.refine.classical.surface import fragment
from aw.refine.runs import build_request
from aw_eval.fracture import fracture_metrics_from_samples


def _task(suite, tid):
    task = read_task(suite / "tasks" / tid)
    targets = read_targets(suite / "targets" / f"{tid}.json")
    return task, np.array([targets.parts[p].pose for p in task.part_ids])


def _metrics(request, poses, target):
    return fracture_metrics_from_samples(request.points, poses, target, 1.0)


CAPS_MEET = pytest.mark.xfail(
    strict=True,
    reason="known failure: this cylinder's break is mostly flat stretches (its height field clipped), split into "
    "planar parts smaller than the end caps, and with two fragments the caps laid on each other score higher",
)


@pytest.mark.parametrize("tid", [pytest.param("frac_cylinder_1", marks=CAPS_MEET), "frac_hex_prism_2"])
def test_global_search_reassembles_a_rough_break(fracture_suite, tid):
    task, target = _task(fracture_suite, tid)
    request = build_request(task, fracture_suite, None)
    poses = refine(request)
    assert np.array_equal(poses[request.anchor], request.initial_poses[request.anchor])
    m = _metrics(request, poses, target)
    assert m.pa == 1.0 and m.re < 2.0 and m.te < 0.01, (m.re, m.te, m.pa)
    assert _metrics(request, request.initial_poses, target).pa < 1.0  # the layout itself is not assembled


@pytest.mark.parametrize("tid", ["frac_breaks_planar_0_0", "frac_breaks_planar_2_0"])
def test_global_search_assembles_a_planar_cut_within_2_degrees(break_suite, tid):
    """A low-poly blob and a chamfered brick cut by a plane: the cut faces are planar, and so
    are many of the brick's other faces."""
    task, target = _task(break_suite, tid)
    request = build_request(task, break_suite, None)
    m = _metrics(request, refine(request), target)
    assert m.pa == 1.0 and m.part_re.max() < 2.0 and m.te < 0.01, (m.part_re, m.te)


@pytest.mark.parametrize("tid", ["frac_fantastic_breaks_8_0", "frac_fantastic_breaks_14_0"])
def test_a_rough_break_whose_sides_are_segmented_unlike_each_other_is_found(break_suite, tid):
    """A thin tile and a bar of the seeded fracture block: one side's break region holds a strip
    that its match splits off, so the two regions' quadric sags do not cancel (both hollow on the
    tile); the pair must still be searched and win."""
    task, target = _task(break_suite, tid)
    request = build_request(task, break_suite, None)
    m = _metrics(request, refine(request), target)
    assert m.pa == 1.0 and m.re < 2.0 and m.te < 0.01, (m.re, m.te, m.pa)


@pytest.mark.parametrize("tid", ["frac_breaks_noisy_11_0", "frac_breaks_eroded_10_0"])
def test_a_noisy_rough_break_and_an_eroded_planar_cut_are_assembled_within_2_degrees(break_suite, tid):
    """A cylinder's rough break with scan noise on both sides (every vertex moved along its
    normal), and a blob's planar cut with chips taken out of one side's rim and the rims rounded:
    the two sides no longer match exactly, and the true contact must still win."""
    task, target = _task(break_suite, tid)
    request = build_request(task, break_suite, None)
    m = _metrics(request, refine(request), target)
    assert m.pa == 1.0 and m.re < 2.0 and m.te < 0.01, (m.re, m.te, m.pa)


def test_a_three_piece_break_has_every_piece_placed(break_suite):
    task, target = _task(break_suite, "frac_breaks_pieces_0_0")
    request = build_request(task, break_suite, None)
    assert len(request.part_ids) == 3
    m = _metrics(request, refine(request), target)
    assert m.pa == 1.0 and m.part_re.max() < 5.0, m.part_re


def test_a_cut_face_split_by_a_later_cut_is_matched_on_the_part_both_fragments_share():
    """Two pieces of a 5-piece vase (``breaks_pieces/11``) meet on a planar cut whose faces have
    like areas, but a later cut took part of each: the outlines agree only where they both run.
    Laid whole on each other they were matched turned by 121 degrees; the pair's best fit must now
    be the cut itself (the fragments are given as cut, so the identity)."""
    meshes = fragments("breaks_pieces/11", 0)
    rng = np.random.default_rng(0)
    frags = [fragment(np.asarray(m.vertices), np.asarray(m.faces), 1.0, rng, keep_whole=True) for m in meshes]
    best = register_pair(frags[0], frags[2], partial=True)[0]
    turned = np.degrees(Rotation.from_matrix(best.rot).magnitude())
    assert turned < 10.0 and np.linalg.norm(best.shift) < 0.02, (turned, best.shift)


def test_like_planar_faces_that_each_hold_part_of_the_other_are_scored_on_the_part_they_share():
    """Two unit cubes, one on the other, shifted by 0.3 along x: the top face of the lower and the
    bottom face of the upper have like areas but share only 70 % of each. With three or more
    fragments (a cut face split between two pieces), the fit scores the contact (0.7 of a cube's
    area of 6) times the share of the outline on the other face (the two sides along x, 2 x 0.7 of
    4) times how closely it lies (at most 1): about 0.03; the whole outlines do not meet (0)."""
    rng = np.random.default_rng(0)
    box = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    lower, upper = (fragment(np.asarray(box.vertices), np.asarray(box.faces), 2.0, rng, True) for _ in range(2))
    top = next(r for r in lower.regions if r.normal[2] > 0.9)
    bottom = next(r for r in upper.regions if r.normal[2] < -0.9)
    tol, shift = tolerance(lower, upper), np.array([0.3, 0.0, 1.0])
    whole = score_fit(lower, upper, top, bottom, np.eye(3), shift, tol, fine=True, partial=False)
    part = score_fit(lower, upper, top, bottom, np.eye(3), shift, tol, fine=True, partial=True)
    assert whole < 1e-3 and 0.02 < part < 0.041, (whole, part)


def _near(request, target, degrees, shift):
    """The target assembly with the non-anchor fragment turned by ``degrees`` and moved by ``shift``."""
    a, b = request.anchor, 1 - request.anchor
    ra, rb = rotation_of(target[a, 3:]), rotation_of(target[b, 3:])
    rel_r, rel_t = ra.T @ rb, ra.T @ (target[b, :3] - target[a, :3])
    nudge = Rotation.from_rotvec(np.radians(degrees) * np.array([0.6, 0.8, 0.0])).as_matrix()
    start = np.array(request.initial_poses)
    start[b] = pose_of(rel_t + np.asarray(shift), nudge @ rel_r)
    return start


def test_local_refinement_pulls_a_near_start_onto_the_fit(fracture_suite, capsys):
    task, target = _task(fracture_suite, "frac_hex_prism_2")
    request = build_request(task, fracture_suite, None)
    start = _near(request, target, 8, [0.02, -0.01, 0.015])
    near = build_request(task, fracture_suite, {p: list(q) for p, q in zip(task.part_ids, start, strict=True)})
    assert near.given_initial_poses
    before = _metrics(near, start, target)
    after = _metrics(near, refine(near), target)
    assert after.re < 1.0 and after.te < 0.005 and after.re < before.re / 4, (before.re, after.re, after.te)
    assert "classical: fracture objective" in capsys.readouterr().out


def test_a_start_it_cannot_improve_comes_back_unchanged_and_it_says_so(fracture_suite, capsys):
    """The other fragment far from the anchor: nothing to fit it to within reach of the local
    ICP, so the fracture objective does not improve and the start comes back as it was."""
    task, target = _task(fracture_suite, "frac_cylinder_1")
    request = build_request(task, fracture_suite, None)
    start = _near(request, target, 3, [3.0, 0.0, 0.0])
    far = build_request(task, fracture_suite, {p: list(q) for p, q in zip(task.part_ids, start, strict=True)})
    poses = refine(far)
    assert np.array_equal(poses, far.initial_poses)
    assert "classical: kept the start state" in capsys.readouterr().out


@pytest.mark.parametrize("category", ["hex_prism", "bar", "cylinder"])
def test_the_rough_break_is_one_candidate_region_and_not_planar(category):
    """The generator writes the lower fragment's faces as bottom cap, break, wall; the break's
    faces (a polar grid of 10 rings of 48) must come out as a rough candidate region (most of
    it: where the height field is clipped it folds sharply), and the flat cap as a planar one.
    With two fragments (``keep_whole`` off) the break's flat stretches are split off as planar
    parts: its candidates then stay inside it and still cover most of it."""
    a, _ = fragments(category, 2)
    grid = 48 + 2 * 48 * 9
    brk = set(range(grid, 2 * grid))
    whole = fragment(np.asarray(a.vertices), np.asarray(a.faces), 1.0, np.random.default_rng(0), keep_whole=True)
    assert len(whole.mesh.faces) == len(a.faces)
    best = max(whole.regions, key=lambda r: len(set(r.faces.tolist()) & brk))
    assert set(best.faces.tolist()) <= brk and len(best.faces) >= 0.8 * len(brk) and not best.planar
    cap = max(whole.regions, key=lambda r: len(set(r.faces.tolist()) & set(range(grid))))
    assert set(cap.faces.tolist()) == set(range(grid)) and cap.planar
    split = fragment(np.asarray(a.vertices), np.asarray(a.faces), 1.0, np.random.default_rng(0))
    inside = [set(r.faces.tolist()) for r in split.regions if set(r.faces.tolist()) & brk]
    assert all(faces <= brk for faces in inside)
    assert len(set().union(*inside)) >= 0.8 * len(brk)
    assert any(set(r.faces.tolist()) == set(range(grid)) and r.planar for r in split.regions)


def test_a_planar_cut_meeting_the_surface_at_a_shallow_angle_is_still_its_own_region():
    """A thin lens split through its thickness: where the cut grazes the lens's faces the rim is
    too shallow to separate them by normals alone; the planar part is split off all the same."""
    a, b = fragments("breaks_planar/9", 0)
    for mesh in (a, b):
        frag = fragment(np.asarray(mesh.vertices), np.asarray(mesh.faces), 1.0, np.random.default_rng(0))
        planar = [r for r in frag.regions if r.planar]
        assert planar and max(r.area for r in planar) > 0.3 * trimesh.Trimesh(mesh.vertices, mesh.faces).area


def test_a_thin_slice_that_is_one_smooth_region_also_offers_its_two_sides():
    """A flattened sphere (a slice 0.2 thick) bends smoothly everywhere, so it is one smooth
    region holding both faces; with three or more fragments either face may be the break, so
    each side (normals within 60 degrees of +z or -z) is a candidate of its own, beside the whole.
    With two fragments the sides are not offered."""
    sheet = trimesh.creation.icosphere(subdivisions=4)
    sheet.apply_scale([0.5, 0.4, 0.1])
    v, f = np.asarray(sheet.vertices), np.asarray(sheet.faces)
    frag = fragment(v, f, 1.0, np.random.default_rng(0), keep_whole=True)
    shares = sorted((round(r.area / frag.mesh.area, 2), round(float(r.normal[2]), 2)) for r in frag.regions)
    assert shares[-1][0] == 1.0
    sides = [(share, nz) for share, nz in shares if 0.3 < share < 0.6]
    assert sorted(np.sign([nz for _, nz in sides])) == [-1, 1]
    assert all(abs(nz) > 0.95 for _, nz in sides)
    two = fragment(v, f, 1.0, np.random.default_rng(0))
    assert not any(0.3 < r.area / two.mesh.area < 0.6 for r in two.regions)
