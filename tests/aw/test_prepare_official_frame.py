"""The official PCA frame (:func:`aw.prepare.official_frame.pca_frame`), the one rule the
preparation and the evaluator's PCA starts share: the numbers of the official procedure at
commit e4b7c9e (written out in :func:`tests.aw.test_prepare_official.frame`), bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from aw.pose import pca_frame as project_frame
from aw.prepare.official_frame import DegenerateFrameError, pca_frame
from aw.prepare.official_protocol import moved, pose_of
from aw_eval.starts import start_frame
from tests.aw.test_prepare_official import ell_prism, frame, slab


def _nearly_cancelling(offset: float) -> np.ndarray:
    """Eight points whose second axis comes from a projection that nearly cancels (the case
    the official ``tests/test_pca_precision.py`` checks), turned off the axes."""
    pts = np.array(
        [
            [offset, 1, 0],
            [-offset, 1, 0],
            [offset, -1, 0],
            [-offset, -1, 0],
            [3, 0, 0],
            [-3, 0, 0],
            [0, 0, 0.5],
            [0, 0, -0.5],
        ],
        dtype=np.float64,
    )
    return pts @ Rotation.from_euler("xyz", [17, 29, 43], degrees=True).as_matrix().T


def _point_sets() -> list[np.ndarray]:
    rng = np.random.default_rng(11)
    post = slab(0.1, 0.1, 0.4, quads=False)[0]  # two equal eigenvalues
    cube = slab(0.2, 0.2, 0.2)[0]  # three
    return [
        *(_nearly_cancelling(o) for o in (3.1e-8, 4.1e-8, 1e-7)),
        ell_prism()[0],
        post,
        cube,
        post @ Rotation.from_euler("xyz", [0.3, 1.2, -0.5]).as_matrix().T,
        *(rng.normal(size=(n, 3)) * [3, 2, 1] + rng.normal(size=3) for n in (4, 50, 1000)),
    ]


@pytest.mark.parametrize("k", range(10))
def test_the_frame_is_the_official_procedure_bit_for_bit(k):
    pts = _point_sets()[k]
    before = pts.copy()
    center, basis = pca_frame(pts)
    want_center, want_basis = frame(pts)
    assert np.array_equal(center, want_center) and np.array_equal(basis, want_basis)
    assert np.array_equal(pts, before)  # the input is left alone


@pytest.mark.parametrize("offset", [3.1e-8, 4.1e-8, 1e-7])
def test_a_nearly_cancelling_projection_still_gives_a_rigid_frame(offset):
    """The reason for e4b7c9e's second Gram-Schmidt step: without it the basis is off
    orthonormal by more than 1e-14 here, and the part's pose no longer rebuilds it."""
    pts = _nearly_cancelling(offset)
    center, basis = pca_frame(pts)
    assert np.abs(basis.T @ basis - np.eye(3)).max() <= 1e-14
    assert abs(np.linalg.det(basis) - 1) <= 1e-14
    rebuilt = moved((pts - center) @ basis, pose_of(center, basis))
    assert np.abs(rebuilt - pts).max() <= 1e-12


def test_the_evaluator_starts_from_the_same_frame():
    for pts in _point_sets():
        assert all(np.array_equal(a, b) for a, b in zip(start_frame(pts), pca_frame(pts), strict=True))


def test_degenerate_points_have_no_official_frame():
    """Collinear points: the official preparation and scorer refuse them; the evaluator's own
    protocol falls back to the project's frame (documented in aw_eval.starts)."""
    rod = np.array([[0, 0, 0], [1, 1, 1], [3, 3, 3.0]])
    with pytest.raises(DegenerateFrameError, match="degenerate part"):
        pca_frame(rod)
    assert all(np.array_equal(a, b) for a, b in zip(start_frame(rod), project_frame(rod), strict=True))
