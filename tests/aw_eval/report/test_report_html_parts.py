"""Parts of report.html without a browser: the Markdown conversion, the registration that draws
a state onto its target, the shared camera, the render cache, the 3D view's data, the curves'
checkpoints."""

from __future__ import annotations

import numpy as np
import trimesh

from aw.meshes import simplify_for_display
from aw.pose import apply_pose, matrix_to_quat
from aw_eval.analyses.curves import normalized_states, normalized_values
from aw_eval.report.fmt import md_table
from aw_eval.report.html.cards import RunView, registration_hint
from aw_eval.report.html.markup import markdown_to_html, sort_value
from aw_eval.report.html.scenes import TaskScene, aligned_poses
from aw_eval.study.model import RunScore


def test_markdown_tables_become_sortable_with_the_same_cells():
    md = (
        "# Title\n\nSome `code` and **bold**.\n\n"
        + md_table(["System", "SR", "95% CI"], [["a", "**59.40**", "[1.0, 2.0]"], ["b", "7.500", "–"]])
        + "\n\n- **missing** (1):\n  - a / t1: no run\n- next\n\n![quality](plots/q.png)"
    )
    out = markdown_to_html(md)
    assert '<h1 id="title">Title</h1>' in out
    assert "<code>code</code>" in out and "<strong>bold</strong>" in out
    assert out.count('<table class="sortable">') == 1
    assert '<td class="r" data-v="59.40"><strong>59.40</strong></td>' in out
    assert '<td class="r" data-v="1.0">[1.0, 2.0]</td>' in out
    assert '<td class="r" data-v="">–</td>' in out  # a dash has no number: sorted last
    # a name column sorts by its text, whatever digits the names hold (oracle-noise0.5 is no 0.5)
    names = markdown_to_html(md_table(["System", "SR"], [["oracle-noise0.5", "1"], ["heuristic", "2"]]))
    assert '<td class="l">oracle-noise0.5</td>' in names and '<td class="l">heuristic</td>' in names
    assert '<div class="tablewrap"><table class="sortable">' in names  # wide tables scroll inside their box
    assert "<ul><li><strong>missing</strong> (1):<ul><li>a / t1: no run</li></ul></li><li>next</li></ul>" in out
    assert '<img src="plots/q.png" alt="quality" loading="lazy">' in out
    assert markdown_to_html("a <b> & c") == "<p>a &lt;b&gt; &amp; c</p>"
    assert markdown_to_html("runs ``; mode `fast`") == "<p>runs <code></code>; mode <code>fast</code></p>"


def test_sort_value_reads_the_first_number():
    assert sort_value("3: 50.00/0.00") == "3"
    assert sort_value("1,049 runs") == "1049"
    assert sort_value("-0.5 [x]") == "-0.5"
    assert sort_value("(missing)") == ""


def _rotation(axis, angle):
    return trimesh.transformations.rotation_matrix(angle, axis)[:3, :3]


def test_aligned_poses_apply_the_saved_registration_in_world_units():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(2, 20, 3))
    poses = np.array(
        [
            [0.3, -0.2, 0.5, *matrix_to_quat(_rotation([0, 1, 1], 0.7))],
            [1.0, 0.0, 0.0, *matrix_to_quat(_rotation([1, 0, 0], -0.4))],
        ]
    )
    rot, trans, divisor = _rotation([1, 2, 3], 1.1), np.array([0.05, -0.1, 0.2]), 2.5
    moved = apply_pose(aligned_poses(poses, rot, trans, divisor), pts)
    # the evaluator's map: normalized points x / d go to R (x / d) + t
    expected = divisor * ((apply_pose(poses, pts) / divisor) @ rot.T + trans)
    np.testing.assert_allclose(moved, expected, atol=1e-9)
    # N states at once, each with its own registration
    batch = aligned_poses(np.stack([poses, poses]), np.stack([rot, np.eye(3)]), np.stack([trans, np.zeros(3)]), divisor)
    np.testing.assert_allclose(batch[0], aligned_poses(poses, rot, trans, divisor), atol=1e-12)
    np.testing.assert_allclose(apply_pose(batch[1], pts), apply_pose(poses, pts), atol=1e-12)
    # without a saved registration the state is drawn as recorded
    np.testing.assert_array_equal(aligned_poses(poses, np.zeros((0, 3, 3)), np.zeros((0, 3)), divisor), poses)


def _scene(tmp_path=None):
    meshes = [trimesh.creation.box((0.2, 0.2, 0.1)), trimesh.creation.box((0.1, 0.3, 0.1))]
    target = np.array([[0, 0, 0.05, 1, 0, 0, 0], [0, 0, 0.15, 1, 0, 0, 0]], dtype=float)
    from aw.render import part_colors

    return TaskScene("t", ["p01", "p02"], meshes, target, part_colors(2), 0.4)


def test_one_camera_frames_target_and_states_but_not_a_part_far_away():
    s = _scene()
    near = s.target_poses.copy()
    near[0, 0] += 0.2
    far = s.target_poses.copy()
    far[1, 0] += 100.0
    c_target, c_near, c_far = s.camera([]), s.camera([near]), s.camera([far])
    assert c_near.distance > c_target.distance  # the union of target and state is framed
    assert c_far.distance < 5 * c_target.distance  # a part left far away does not shrink the assembly to a dot


def test_renders_are_named_by_content_and_reused(tmp_path):
    s = _scene()
    cam = s.camera([])
    try:
        a = s.render(s.target_poses, cam, (64, 48), tmp_path)
        first = (tmp_path / a).stat().st_mtime_ns
        (tmp_path / a).write_bytes(b"kept")  # a file that exists is reused, not rendered again
        assert s.render(s.target_poses.copy(), cam, (64, 48), tmp_path) == a
        assert (tmp_path / a).read_bytes() == b"kept"
        moved = s.target_poses.copy()
        moved[1, 0] += 0.1
        b = s.render(moved, cam, (64, 48), tmp_path)
        assert b != a and (tmp_path / b).stat().st_mtime_ns >= first
        from PIL import Image

        im = np.asarray(Image.open(tmp_path / b))
        assert im.shape == (48, 64, 3) and len(np.unique(im.reshape(-1, 3), axis=0)) > 20
    finally:
        s.close()


def test_viewer_meshes_are_decimated_below_the_cap():
    m = trimesh.creation.icosphere(subdivisions=5)  # 20,480 faces
    v, f = simplify_for_display(np.asarray(m.vertices), np.asarray(m.faces), 1500)
    assert 100 < len(f) <= 1500 and f.max() < len(v)
    small = trimesh.creation.box()
    v2, f2 = simplify_for_display(np.asarray(small.vertices), np.asarray(small.faces), 1500)
    assert len(f2) == len(small.faces)


def test_filmstrip_states_are_the_curves_checkpoints():
    r = RunScore(
        system="s",
        task_id="t",
        status="scored",
        pa=1.0,
        sr=1.0,
        scd=0.0,
        ck_seq=np.array([0, 2, 5]),
        ck_t=np.array([0.0, 10.0, 30.0]),
        ck_pa=np.array([0.0, 0.5, 1.0]),
        ck_sr=np.zeros(3),
        ck_sra=np.zeros(3),
        ck_scd=np.array([3.0, 2.0, 0.0]),
        call_t=np.array([0.0, 5.0, 10.0, 20.0, 30.0, 40.0]),
    )
    idx = normalized_states(r)
    assert idx[0] == 0 and idx[-1] is None and idx[3] == 1 and idx[8] == 2
    pa = normalized_values(r, "pa")
    np.testing.assert_array_equal(pa, [r.pa if k is None else r.ck_pa[k] for k in idx])


def _box_points(scene, poses, n=400, seed=0):
    """Surface samples ``(P, n, 3)`` of the scene's parts at ``poses``, normalized by the divisor."""
    out = []
    for i, m in enumerate(scene.meshes):
        pts = trimesh.sample.sample_surface(m, n, seed=seed + i)[0]
        out.append(apply_pose(poses[i], pts) / scene.divisor)
    return np.stack(out)


def test_placed_parts_are_within_the_threshold_of_their_targets_before_registration():
    from aw_eval.chamfer import chamfer_pairs

    s = _scene()  # divisor 0.4: a part is placed when 2 (largest vertex shift / 0.4)^2 <= threshold
    threshold = 0.01
    poses = s.target_poses.copy()
    poses[1, 0] += 0.02  # 2 (0.05)^2 = 0.005: placed
    assert s.placed(poses, threshold).tolist() == [True, True]
    poses[1, 0] += 0.02  # 2 (0.1)^2 = 0.02: not
    assert s.placed(poses, threshold).tolist() == [True, False]
    # the bound holds against the Chamfer distance of real surface samples, for random small motions
    rng = np.random.default_rng(1)
    target_pts = _box_points(s, s.target_poses)
    seen = set()
    for _ in range(40):
        p = s.target_poses.copy()
        p[:, :3] += rng.normal(scale=0.01, size=(2, 3))
        p[:, 3:] = [matrix_to_quat(_rotation(rng.normal(size=3), rng.normal(scale=0.08))) for _ in range(2)]
        placed = s.placed(p, threshold)
        cd = chamfer_pairs(_box_points(s, p), target_pts)
        assert np.all(cd[placed] <= threshold)
        seen.update(placed.tolist())
    assert seen == {True, False}  # both outcomes were exercised


def test_a_card_explains_parts_in_place_that_the_global_registration_does_not_count():
    s = _scene()
    final = s.target_poses.copy()
    final[1] = [0, 0, 0, 1, 0, 0, 0]  # p02 left at its initial pose (0.15 below its target: not placed)
    score = RunScore(
        system="agent", task_id="t", status="scored", pa=0.0, sr=0.0, scd=0.3, moved=np.array([True, False])
    )
    view = RunView("agent", score, np.zeros((0, 2, 7)), final, recorded_final=final)
    hint = registration_hint(s, view, 0.01)
    assert hint.startswith("agent: 1 of 2 parts lie at their targets as placed, yet PA is 0.0%.")
    assert "ONE rigid transform" in hint and "the part left away, p02 (never moved), pulls" in hint
    score.pa = 0.5  # PA counts what is in place: nothing to explain
    assert registration_hint(s, view, 0.01) == ""
    score.pa = 0.0
    assert registration_hint(s, RunView("agent", score, np.zeros((0, 2, 7)), final), 0.01) == ""  # not recorded
