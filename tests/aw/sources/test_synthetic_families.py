"""The refiners' benchmark families: closed pieces meeting on a plane for planar cuts, the piece
counts of the many-piece family, and determinism by seed."""

from __future__ import annotations

import numpy as np
import pytest

from aw.sources.synthetic import FAMILIES, generate_object, plan


def _shared(a, b) -> np.ndarray:
    """The vertices two pieces share (their common cut face): ``(k, 3)``."""
    va, vb = (set(map(tuple, np.round(m.vertices, 9))) for m in (a, b))
    return np.array(sorted(va & vb))


@pytest.mark.parametrize("index", [0, 8])  # a low-poly blob, a dense rod cut across
def test_a_planar_cut_gives_two_closed_pieces_meeting_on_a_plane(index):
    obj = generate_object("breaks_planar", index)
    a, b = (p.mesh for p in obj.parts)
    for m in (a, b):
        assert m.is_watertight and m.volume > 0
    face = _shared(a, b)
    assert len(face) >= 3
    residual = np.linalg.svd(face - face.mean(0), compute_uv=False)[-1] / np.sqrt(len(face))
    assert residual < 1e-6 * np.ptp(face, axis=0).max()


def test_the_many_piece_family_has_three_to_five_closed_pieces():
    counts = []
    for index in range(3):
        obj = generate_object("breaks_pieces", index)
        counts.append(obj.n_parts)
        assert obj.n_parts == plan("breaks_pieces", index)[1]
        assert all(p.mesh.is_watertight and p.mesh.volume > 0 for p in obj.parts)
    assert counts == [3, 4, 5]


def test_noisy_and_eroded_variants_repeat_by_seed_and_change_with_it():
    for family in ("breaks_noisy", "breaks_eroded"):
        assert family in FAMILIES
        one, again, other = generate_object(family, 0), generate_object(family, 0), generate_object(family, 0, seed=1)
        for pa, pb in zip(one.parts, again.parts, strict=True):
            np.testing.assert_array_equal(pa.mesh.vertices, pb.mesh.vertices)
        a, c = one.parts[0].mesh.vertices, other.parts[0].mesh.vertices
        assert a.shape != c.shape or not np.allclose(a, c)
