"""The procedural benchmark: counts, categories, identical parts, size ratios, fractures."""

from __future__ import annotations

import numpy as np
import pytest

from aw.prepare.geometry import part_size_ratio, pca_bbox_diagonal
from aw.sources.synthetic import BANDS, BLOCKS, generate_object, iter_suite_objects, plan
from aw.sources.synthetic.checks import accidental_twins

N = 9  # three objects per part-count band


@pytest.fixture(scope="module")
def blocks():
    return {b: [generate_object(b, i) for i in range(N)] for b in BLOCKS}


def test_part_counts_follow_the_bands(blocks):
    for block, objs in blocks.items():
        for i, obj in enumerate(objs):
            assert obj.source == block and obj.dataset == "synthetic"
            assert obj.category in BLOCKS[block].categories
            assert (obj.category, obj.n_parts) == plan(block, i)
            if block == "fantastic_breaks":
                assert obj.n_parts == 2
                continue
            lo, hi = BANDS[i % 3]
            assert lo <= obj.n_parts <= hi
        if block != "fantastic_breaks":
            counts = [o.n_parts for o in objs]
            assert min(counts) <= 5 and max(counts) >= 11
            assert len({o.category for o in objs}) == len(BLOCKS[block].categories) or len(objs) < len(
                BLOCKS[block].categories
            )


def test_every_category_meets_every_band():
    for block in ("partnet", "assemblybench"):
        seen = {(plan(block, i)[0], i % 3) for i in range(3 * 3 * len(BLOCKS[block].categories))}
        assert len(seen) == 3 * len(BLOCKS[block].categories)


def test_furniture_has_identical_parts_recorded_as_equivalent(blocks):
    for block in ("partnet", "ikea_manual"):
        with_groups = 0
        for obj in blocks[block]:
            names = {p.name: p.mesh for p in obj.parts}
            for group in obj.equivalence or []:
                with_groups += 1
                ref = names[group[0]]
                for other in group[1:]:
                    m = names[other]
                    # congruent: same vertex count, same sorted distances to the vertex mean
                    assert len(m.vertices) == len(ref.vertices)
                    d0 = np.sort(np.linalg.norm(ref.vertices - ref.vertices.mean(axis=0), axis=1))
                    d1 = np.sort(np.linalg.norm(m.vertices - m.vertices.mean(axis=0), axis=1))
                    np.testing.assert_allclose(d0, d1, atol=1e-12)
                    assert not np.allclose(m.vertices, ref.vertices)  # placed elsewhere
        assert with_groups >= N  # legs, slats, shelves, doors, ...
        assert sum(1 for o in blocks[block] if o.n_parts >= 6 and o.equivalence) >= 5


def test_no_unrelated_parts_are_near_identical(blocks):
    for objs in blocks.values():
        for obj in objs:
            assert accidental_twins(obj) == []


def test_industrial_part_size_ratios_are_larger(blocks):
    ratio = {b: np.median([part_size_ratio([p.mesh for p in o.parts]) for o in objs]) for b, objs in blocks.items()}
    assert ratio["assemblybench"] > 3.0
    assert ratio["assemblybench"] > 1.5 * ratio["partnet"]
    assert ratio["assemblybench"] > 1.5 * ratio["ikea_manual"]
    # industrial objects with fasteners have a small part next to a large one
    big = [o for o in blocks["assemblybench"] if any(p.name.startswith(("bolt", "nut", "washer")) for p in o.parts)]
    assert big
    for o in big:
        d = [pca_bbox_diagonal(p.mesh) for p in o.parts]
        assert max(d) / min(d) > 2.0


def test_fractures_are_two_closed_complementary_fragments(blocks):
    for obj in blocks["fantastic_breaks"]:
        a, b = (p.mesh for p in obj.parts)
        for m in (a, b):
            assert m.is_watertight and m.is_winding_consistent and m.volume > 0
        # the fragments share the fracture surface vertex for vertex ...
        shared = set(map(tuple, np.round(a.vertices, 12))) & set(map(tuple, np.round(b.vertices, 12)))
        assert len(shared) >= 100
        pts = np.array(sorted(shared))
        # ... and it is rough: far from any plane
        centred = pts - pts.mean(axis=0)
        residual = np.linalg.svd(centred, compute_uv=False)[-1] / np.sqrt(len(pts))
        assert residual > 1e-3 * np.ptp(pts, axis=0).max()


def test_manual_steps_cover_every_part_once(blocks):
    for block in ("ikea_manual", "assemblybench"):
        for obj in blocks[block]:
            steps = obj.meta["steps"]
            flat = [n for s in steps for n in s]
            assert sorted(flat) == sorted(p.name for p in obj.parts)
            assert len(steps) >= 2 or obj.n_parts <= 3


def test_generation_is_deterministic_by_seed():
    a, b = generate_object("assemblybench", 4), generate_object("assemblybench", 4)
    assert [p.name for p in a.parts] == [p.name for p in b.parts]
    for pa, pb in zip(a.parts, b.parts, strict=True):
        np.testing.assert_array_equal(pa.mesh.vertices, pb.mesh.vertices)
        np.testing.assert_array_equal(pa.mesh.faces, pb.mesh.faces)
    c = generate_object("assemblybench", 4, seed=1)
    assert a.n_parts != c.n_parts or any(
        pa.mesh.vertices.shape != pc.mesh.vertices.shape or not np.allclose(pa.mesh.vertices, pc.mesh.vertices)
        for pa, pc in zip(a.parts, c.parts, strict=True)
    )


def test_suite_objects_and_bad_arguments():
    pairs = list(iter_suite_objects(1))
    assert [(o.source, conds) for o, conds in pairs] == [(b, BLOCKS[b].conditions) for b in BLOCKS]
    assert BLOCKS["partnet"].conditions == ("none", "image")
    with pytest.raises(ValueError, match="unknown block"):
        generate_object("lego", 0)
    with pytest.raises(ValueError, match="index"):
        generate_object("partnet", -1)
