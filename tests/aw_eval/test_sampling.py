"""Surface sampling and farthest-point sampling (NumPy and JAX pick identical indices)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from aw_eval.kernels.fps import fps_batch
from aw_eval.sampling import fps_jax, fps_numpy, part_clouds, part_seed, surface_samples
from aw_eval.settings import ProtocolSettings


def test_fps_numpy_and_jax_pick_identical_indices():
    meshes = [
        trimesh.creation.box(extents=[1, 0.5, 0.2]),
        trimesh.creation.cylinder(radius=0.1, height=1.0),
        trimesh.creation.icosphere(subdivisions=2),
        trimesh.creation.annulus(0.2, 0.4, 0.1),
    ]
    cands = np.stack([surface_samples(m, 1024, part_seed(7, i)) for i, m in enumerate(meshes)])
    want = np.stack([fps_numpy(c, 300) for c in cands])
    assert np.array_equal(fps_jax(cands, 300), want)
    assert all(len(set(w.tolist())) == 300 for w in want)


@pytest.mark.parametrize("threads", [1, 2])
def test_compiled_fps_picks_the_numpy_indices(threads):
    """The compiled batch kernel picks :func:`fps_numpy`'s indices, on curved and flat meshes and
    on a lattice full of exact ties, on one thread or several."""
    meshes = [
        trimesh.creation.box(extents=[1, 0.5, 0.2]),
        trimesh.creation.cylinder(radius=0.1, height=1.0),
        trimesh.creation.icosphere(subdivisions=2),
        trimesh.creation.annulus(0.2, 0.4, 0.1),
    ]
    cands = np.stack([surface_samples(m, 1024, part_seed(7, i)) for i, m in enumerate(meshes)])
    assert np.array_equal(fps_batch(cands, 300, threads=threads), np.stack([fps_numpy(c, 300) for c in cands]))
    g = np.stack(np.meshgrid(*[np.arange(4.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    assert np.array_equal(
        fps_batch(np.stack([g, g[::-1]]), 20, threads=threads), np.stack([fps_numpy(g, 20), fps_numpy(g[::-1], 20)])
    )
    with pytest.raises(ValueError):
        fps_batch(cands, 2000)


def test_fps_ties_go_to_the_lowest_index():
    # a lattice is full of exact ties
    g = np.stack(np.meshgrid(*[np.arange(4.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    a, b = fps_numpy(g, 20), fps_jax(g[None], 20)[0]
    assert np.array_equal(a, b)
    pts = np.array([[0.0, 0, 0], [1.0, 0, 0], [-1.0, 0, 0], [0.5, 0, 0]])
    assert fps_numpy(pts, 4).tolist() == [0, 1, 2, 3]  # 1 and 2 tie at distance 1: 1 first
    with pytest.raises(ValueError):
        fps_numpy(pts, 5)


def test_seeds_and_samples_are_deterministic():
    assert part_seed(0, 1) == part_seed(0, 1) and len({part_seed(0, i) for i in range(50)}) == 50
    assert part_seed(0, 1) != part_seed(1, 1)
    m = trimesh.creation.box()
    assert np.array_equal(surface_samples(m, 100, 5), surface_samples(m, 100, 5))
    with pytest.raises(ValueError):
        surface_samples(trimesh.Trimesh(vertices=np.zeros((3, 3)), faces=[[0, 1, 2]], process=False), 10, 0)


def test_part_clouds_shapes_and_paths_agree():
    st = ProtocolSettings(n_surface=200, n_fps=50)
    meshes = [trimesh.creation.box(), trimesh.creation.icosphere(subdivisions=1)]
    a = part_clouds(meshes, st, use_jax=True)
    b = part_clouds(meshes, st, use_jax=False)
    assert a.shape == (2, 50, 3) and np.array_equal(a, b)
    # every FPS sample is one of the mesh's surface samples
    c0 = surface_samples(meshes[0], 200, part_seed(0, 0))
    assert all(np.any(np.all(c0 == p, axis=1)) for p in a[0])
