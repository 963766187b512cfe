"""aw.assembly.piled_parts: real assemblies pass (every embedded synthetic object, the dataset
fixtures), the same objects with each part saved at its own origin are refused (centred on its
bounding box, its centroid or its base)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from aw.assembly import AssembledObject, SourcePart, piled_parts
from aw.sources.synthetic import BLOCKS, generate_object

sys.path.insert(0, str(Path(__file__).parent / "sources"))
from dataset_fixtures import assemblybench_object, box, chair_boxes, fractured_box  # noqa: E402


def _object(meshes: list[trimesh.Trimesh], name: str = "obj") -> AssembledObject:
    return AssembledObject(name, "custom", "test", "", [SourcePart(f"p{i}", m) for i, m in enumerate(meshes)])


def _at_own_origin(obj: AssembledObject, how: str) -> AssembledObject:
    """Each part moved so that its bounding-box centre, vertex mean or base centre is the origin."""
    parts = []
    for p in obj.parts:
        v = np.asarray(p.mesh.vertices, dtype=np.float64)
        lo, hi = v.min(axis=0), v.max(axis=0)
        origin = {"box": (lo + hi) / 2, "centroid": v.mean(axis=0), "base": np.r_[(lo + hi)[:2] / 2, lo[2]]}[how]
        parts.append(SourcePart(p.name, trimesh.Trimesh(v - origin, p.mesh.faces, process=False)))
    return AssembledObject(obj.object_id, obj.source, obj.dataset, obj.category, parts)


def _synthetic() -> list[AssembledObject]:
    """The paper-sized embedded benchmark: 20 objects of each of the four blocks, seed 0."""
    return [generate_object(block, i, 0) for block in BLOCKS for i in range(20)]


def _fixtures(tmp: Path) -> list[AssembledObject]:
    chairs = [_object([box(s, c) for s, c in chair_boxes(n)], f"chair{n}") for n in (1, 2, 4)]
    breaks = [_object(fractured_box(n, seed=n), f"break{n}") for n in (2, 3, 5)]
    bench = [_object(assemblybench_object(tmp, "gear", f"g{n}", n), f"bench{n}") for n in (2, 4)]
    return chairs + breaks + bench


@pytest.fixture(scope="module")
def assemblies(tmp_path_factory) -> list[AssembledObject]:
    return _synthetic() + _fixtures(tmp_path_factory.mktemp("fixtures"))


def test_real_assemblies_are_not_piles(assemblies):
    piled = [(o.source, o.object_id, piled_parts(o)) for o in assemblies if piled_parts(o) is not None]
    assert piled == []
    assert {o.source for o in assemblies} >= set(BLOCKS) and len(assemblies) == 88


@pytest.mark.parametrize("how", ["box", "centroid", "base"])
def test_parts_saved_at_their_own_origins_are_piles(assemblies, how):
    """Bounding-box centres always; centroids and bases where an object has 3 parts or more (two
    parts overlap in their boxes legitimately, as the halves of a slanted break do)."""
    objects = [o for o in assemblies if how == "box" or o.n_parts >= 3]
    missed = [o.object_id for o in objects if piled_parts(_at_own_origin(o, how)) is None]
    assert missed == []


def test_what_a_pile_says():
    stool = _object([box((0.4, 0.3, 0.04)), box((0.04, 0.04, 0.4)), box((0.04, 0.04, 0.4))])
    pile = piled_parts(stool)
    assert pile is not None and (pile.stacked, pile.pairs, pile.parts) == (3, 3, ["p0", "p1", "p2"])
    assert pile.reason() == (
        "the bounding boxes of its parts mostly overlap (3 of 3 part pairs share most of the smaller part's box)"
    )
    pair = piled_parts(_object([box((0.4, 0.3, 0.04)), box((0.2, 0.2, 0.2))]))
    assert pair is not None and pair.reason() == "the bounding boxes of its 2 parts are centred on one point"
    # a bolt in a nut and a washer on it beside a plate: nested pairs, not most pairs
    nested = _object(
        [
            box((0.02, 0.02, 0.2), (0, 0, 0.1)),
            box((0.05, 0.05, 0.02), (0, 0, 0.15)),
            box((0.06, 0.06, 0.005), (0, 0, 0.05)),
            box((0.5, 0.5, 0.04), (0, 0, 0.02 - 0.04)),
        ]
    )
    assert piled_parts(nested) is None
