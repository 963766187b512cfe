"""Robustness variants (Appendix E): layouts, a removed part, an added distractor."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from prepare_helpers import stool

from aw.formats import read_manifest, read_targets, read_task
from aw.formats.suite import suite_paths
from aw.meshes import load_task_meshes
from aw.pose import apply_pose
from aw.prepare import (
    MIN_GAP,
    VariantPlan,
    add_distractor,
    box_gap,
    eval_divisor,
    layout_variant,
    prepare_object,
    remove_part,
    standardize,
)
from aw.prepare.suite import ObjectSpec, build_suite
from aw.sources.synthetic import generate_object


def _assembled(prep) -> dict[str, np.ndarray]:
    return {p.source_name: apply_pose(p.target, np.asarray(p.mesh.vertices)) for p in prep.parts if not p.distractor}


def _by_name(prep):
    return {p.source_name: p for p in prep.parts}


def test_layout_variant_moves_parts_but_targets_agree():
    obj = generate_object("partnet", 1)
    base = standardize(obj, 0)
    alt = layout_variant(obj, 1001)
    assert alt.variant == {"kind": "layout", "layout_seed": 1001}
    assert alt.scale == base.scale
    a, b = _by_name(base), _by_name(alt)
    moved = [n for n in a if not np.allclose(a[n].mesh.vertices, b[n].mesh.vertices)]
    assert len(moved) == obj.n_parts
    assert [p.source_name for p in base.parts] != [p.source_name for p in alt.parts]  # ids re-drawn
    ga, gb = _assembled(base), _assembled(alt)
    for n in ga:
        np.testing.assert_allclose(ga[n], gb[n], atol=1e-12)


def test_missing_part_keeps_poses_targets_and_original_divisor():
    obj = generate_object("partnet", 1)
    base = standardize(obj, 0)
    miss = remove_part(base, 2001)
    removed = miss.variant["removed_source_names"]
    assert miss.variant["kind"] == "missing" and len(removed) == 1
    assert len(miss.parts) == obj.n_parts - 1
    assert miss.part_ids == [f"p{k:02d}" for k in range(1, obj.n_parts)]  # no gap in the numbering
    a = _by_name(base)
    for p in miss.parts:
        assert p.source_name != removed[0]
        np.testing.assert_array_equal(p.mesh.vertices, a[p.source_name].mesh.vertices)
        np.testing.assert_array_equal(p.target, a[p.source_name].target)
    assert miss.eval_divisor == pytest.approx(eval_divisor([p.mesh for p in base.parts]), rel=1e-12)
    # hints follow the renaming and drop a group left with one member
    names = {p.part_id: p.source_name for p in miss.parts}
    for group in miss.equivalence_hint or []:
        assert len(group) >= 2
        assert any(set(names[i] for i in group) <= set(g) for g in obj.equivalence)


def test_missing_part_needs_three_parts():
    with pytest.raises(ValueError, match="at least 3 parts"):
        remove_part(standardize(generate_object("fantastic_breaks", 0)), 1)


def test_distractor_is_flagged_placed_apart_and_leaves_the_rest_unchanged():
    obj, donor = stool(), generate_object("partnet", 0)
    base = standardize(obj, 0)
    dis = add_distractor(base, donor, 3001)
    extra = [p for p in dis.parts if p.distractor]
    assert len(extra) == 1 and len(dis.parts) == obj.n_parts + 1
    (d,) = extra
    assert d.source_name.startswith(f"{donor.object_id}/")
    np.testing.assert_array_equal(d.target, [0, 0, 0, 1, 0, 0, 0])
    assert dis.variant == {"kind": "distractor", "distractor_from": donor.object_id, "layout_seed": 0}
    assert dis.eval_divisor == pytest.approx(base.divisor())
    a = _by_name(base)
    for p in dis.parts:
        if not p.distractor:
            np.testing.assert_array_equal(p.mesh.vertices, a[p.source_name].mesh.vertices)
            np.testing.assert_array_equal(p.target, a[p.source_name].target)
    boxes = [(p.mesh.vertices.min(axis=0), p.mesh.vertices.max(axis=0)) for p in dis.parts]
    for (a_lo, a_hi), (b_lo, b_hi) in itertools.combinations(boxes, 2):
        assert box_gap(a_lo, a_hi, b_lo, b_hi) >= MIN_GAP
    assert d.mesh.vertices.min(axis=0)[2] == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(ValueError, match="different object"):
        add_distractor(base, obj, 1)


def test_prepare_object_writes_paired_variants(tmp_path):
    obj, donor = stool(source="partnet"), generate_object("partnet", 0)
    entries = prepare_object(obj, tmp_path, ["none", "image"], variants=VariantPlan.appendix_e(0), donor=donor)
    kinds = [(e.condition, e.variant) for e in entries]
    assert kinds == [
        (c, v) for c in ("none", "image") for v in ("original", "layout", "layout", "missing", "distractor")
    ]
    for e in entries:
        task_dir, targets_path = suite_paths(tmp_path, e.task_id)
        targets = read_targets(targets_path)
        assert targets.variant.kind == e.variant
        if e.variant != "original":
            assert e.base_task_id == f"partnet-stool-{e.condition}" and targets.variant.base_task_id == e.base_task_id
        if e.variant == "missing":
            assert targets.eval_divisor is not None and e.n_parts == obj.n_parts - 1
        if e.variant == "distractor":
            assert sum(t.distractor for t in targets.parts.values()) == 1
            assert len(targets.scored_part_ids) == obj.n_parts
    # both conditions share each perturbation: identical part files and targets
    for suffix in ("", "-layout1", "-missing", "-distractor"):
        none_dir, none_t = suite_paths(tmp_path, f"partnet-stool-none{suffix}")
        img_dir, img_t = suite_paths(tmp_path, f"partnet-stool-image{suffix}")
        for f in sorted((none_dir / "parts").iterdir()):
            assert f.read_bytes() == (img_dir / "parts" / f.name).read_bytes()
        assert read_targets(none_t).parts == read_targets(img_t).parts
        assert read_task(img_dir).references == ["references/01.png"]
        # every image-condition variant shows the same reference
        assert (img_dir / "references" / "01.png").read_bytes() == (
            suite_paths(tmp_path, "partnet-stool-image")[0] / "references" / "01.png"
        ).read_bytes()


def test_build_suite_with_variants_reads_back(tmp_path):
    specs = [
        ObjectSpec(
            "aw.sources.synthetic:generate_object",
            ("fantastic_breaks", i, 0),
            ("none",),
            ObjectSpec("aw.sources.synthetic:generate_object", ("fantastic_breaks", (i + 1) % 2, 0)),
        )
        for i in range(2)
    ]
    manifest, _ = build_suite(specs, tmp_path, name="t", variants=VariantPlan.appendix_e(0), jobs=1, progress=False)
    assert [t.variant for t in manifest.tasks] == [
        "original",
        "layout",
        "layout",
        "distractor",
    ] * 2  # no missing for 2 parts
    assert read_manifest(tmp_path) == manifest
    for t in manifest.tasks:
        task_dir, _ = suite_paths(tmp_path, t.task_id)
        assert len(load_task_meshes(read_task(task_dir))) == t.n_parts
