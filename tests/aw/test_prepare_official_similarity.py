"""The official geometry rule's registration (:func:`aw.prepare.official_similarity.register`,
the evaluator's compiled ICP from the official starts) against a NumPy transcription of the
official code's loop (``utils/registration.py`` of AssemblyWorld/assembly-world-agent: cKDTree
neighbours, Kabsch on the joined pairs with the determinant as the last singular sign, the
lowest value of each start's run)."""

from __future__ import annotations

from itertools import permutations, product

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from aw.prepare.official_frame import pca_frame
from aw.prepare.official_similarity import (
    IMPROVEMENT_TOLERANCE,
    MAX_ITERATIONS,
    official_starts,
    register,
    search_structures,
)


def _numpy_register(moving: np.ndarray, fixed: np.ndarray) -> float:
    mc, mb = pca_frame(moving)
    fc, fb = pca_frame(fixed)
    fixed_tree, moving_tree = cKDTree(fixed), cKDTree(moving)

    def cost(r, t):
        ahead, fwd = fixed_tree.query(moving @ r.T + t)
        back, bwd = moving_tree.query((fixed - t) @ r)
        return float(np.mean(ahead * ahead) + np.mean(back * back)), fwd, bwd

    best = np.inf
    for perm in permutations(range(3)):
        for signs in product((-1, 1), repeat=3):
            axes = np.eye(3)[:, perm] @ np.diag(signs)
            if np.linalg.det(axes) <= 0:
                continue
            r = fb @ axes @ mb.T
            t = fc - r @ mc
            value, fwd, bwd = cost(r, t)
            lowest = value
            for _ in range(MAX_ITERATIONS):
                src, dst = np.concatenate((moving, moving[bwd])), np.concatenate((fixed[fwd], fixed))
                a, b = src.mean(0), dst.mean(0)
                u, _, vt = np.linalg.svd((src - a).T @ (dst - b))
                flip = np.eye(3)
                flip[-1, -1] = np.linalg.det(vt.T @ u.T)
                r = vt.T @ flip @ u.T
                t = b - r @ a
                updated, fwd, bwd = cost(r, t)
                lowest = min(lowest, updated)
                gain, value = value - updated, updated
                if gain < IMPROVEMENT_TOLERANCE:
                    break
            best = min(best, lowest)
    return best


def _surface(mesh, n, seed):
    return np.asarray(trimesh.sample.sample_surface(mesh, n, seed=seed)[0])


def _box(extents, n, seed):
    return _surface(trimesh.creation.box(extents=extents), n, seed)


def _pairs():
    rng = np.random.default_rng(21)
    turn = Rotation.from_euler("xyz", [0.4, -1.1, 2.0]).as_matrix()
    box = _box((0.6, 0.25, 0.1), 200, 1)
    ell = np.concatenate([_box((0.5, 0.1, 0.1), 100, 2) + [0.2, 0, 0], _box((0.1, 0.4, 0.1), 100, 3) + [0, 0.15, 0]])
    return {
        "the same box moved": (box @ turn.T + 0.3, box),
        "two samplings of a box": (_box((0.6, 0.25, 0.1), 200, 4), box),
        "near boxes": (_box((0.62, 0.24, 0.1), 200, 5), box),
        "other proportions": (_box((0.4, 0.4, 0.1), 200, 6), box),
        "an L and a box": (ell, box),
        "an L turned": (ell @ turn.T, ell[::-1]),
        # slow to converge (runs of 50-100 fits): the stopping rule decides the value
        "cylinders": (
            _surface(trimesh.creation.cylinder(0.1, 0.6), 300, 7),
            _surface(trimesh.creation.cylinder(0.11, 0.55), 300, 8),
        ),
        "boxes sliding": (_box((0.6, 0.25, 0.1), 400, 9), _box((0.5, 0.3, 0.12), 400, 10)),
        "normal blobs": (rng.normal(size=(150, 3)) * [0.3, 0.2, 0.1], rng.normal(size=(150, 3)) * [0.3, 0.2, 0.1]),
    }


@pytest.mark.parametrize("name", list(_pairs()))
def test_register_equals_the_official_loop(name):
    moving, fixed = _pairs()[name]
    want = _numpy_register(moving, fixed)
    got = register(moving, fixed)
    assert abs(got - want) <= 1e-9 * want + 1e-18, (got, want)
    # the decision at thresholds just above and below the value, with the early return (exact
    # registrations reach rounding noise, ~1e-32, where a threshold decides nothing)
    for threshold in (want * (1 + 1e-6), want * (1 - 1e-6)) if want > 1e-20 else (1e-20,):
        assert (register(moving, fixed, enough=threshold) <= threshold) == (want <= threshold)
    # structures built once per part give the same value
    assert register(moving, fixed, structures=(search_structures(moving), search_structures(fixed))) == got


def test_the_starts_are_the_24_proper_axis_mappings():
    moving, fixed = _pairs()["an L and a box"]
    starts = official_starts(moving, fixed)
    assert len(starts) == 24
    for r, t in starts:
        assert np.allclose(r @ r.T, np.eye(3), atol=1e-12) and np.linalg.det(r) == pytest.approx(1.0)
        assert np.allclose(moving.mean(0) @ r.T + t, fixed.mean(0), atol=1e-12)  # centre onto centre
    assert len({tuple(np.round(r, 9).ravel()) for r, _ in starts}) == 24
