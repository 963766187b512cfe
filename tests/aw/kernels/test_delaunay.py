"""Exact nearest neighbours by Delaunay walks, their Voronoi-margin certificate, and ICP with them."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from scipy.spatial import Delaunay

from aw.kernels.delaunay import LANES, SENTINEL, _scan, build_graph, uncertified, walk
from aw.kernels.icp import ICPProblem, build_tree, graph_for
from aw_eval.fixtures import make_points_geometry, trajectory_checkpoints
from aw_eval.reference import icp as ref_icp


@njit
def _walk_all(pts, graph, x, start):
    out = np.empty(len(x), np.int64)
    margin = np.empty(len(x))
    for i in range(len(x)):
        out[i], _, _, margin[i] = walk(pts, graph, x[i, 0], x[i, 1], x[i, 2], start[i])
    return out, margin


def _brute(x, ref):
    return ((x[:, None, :] - ref[None, :, :]) ** 2).sum(-1).argmin(1)


def _surface_cloud(rng, n=900):
    """Points on the faces of two boxes: flat, nearly coplanar sheets, as sampled parts are."""
    out = []
    for centre, size in (((0, 0, 0), (1.0, 0.6, 0.1)), ((0.8, 0.2, 0.5), (0.2, 0.2, 0.9))):
        u = rng.random((n // 2, 3)) - 0.5
        face = rng.integers(0, 3, n // 2)
        u[np.arange(n // 2), face] = np.sign(u[np.arange(n // 2), face]) * 0.5
        out.append(np.asarray(centre) + u * np.asarray(size))
    return np.concatenate(out)


@pytest.mark.parametrize("cloud", ["gaussian", "surfaces"])
def test_walk_from_any_start_finds_the_nearest_point(cloud):
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(700, 3)) if cloud == "gaussian" else _surface_cloud(rng)
    graph = build_graph(pts)
    assert graph is not None
    x = np.concatenate(
        [
            rng.normal(size=(300, 3)) * 0.5,  # inside and near
            rng.normal(size=(200, 3)) * 6.0,  # far: wide, almost tied balls
            pts[:100] + rng.normal(size=(100, 3)) * 1e-3,
        ]
    )  # on the cloud
    start = rng.integers(0, len(pts), len(x))
    got, margin = _walk_all(pts, tuple(graph), x, start)
    assert np.array_equal(got, _brute(x, pts))
    assert np.all(margin >= 0)


def test_voronoi_margin_certifies_the_nearest_point():
    """Any move shorter than the margin keeps the nearest point; far queries get real slack."""
    rng = np.random.default_rng(1)
    pts = _surface_cloud(rng)
    graph = tuple(build_graph(pts))
    x = np.concatenate([rng.normal(size=(300, 3)) * 0.4, rng.normal(size=(300, 3)) * 5.0])
    j, margin = _walk_all(pts, graph, x, np.zeros(len(x), np.int64))
    for scale in (0.999, 0.5, 0.1):
        d = rng.normal(size=x.shape)
        d *= (scale * margin / np.linalg.norm(d, axis=1))[:, None]
        assert np.array_equal(_brute(x + d, pts), j)
    # the ball certificate's slack (half the gap to the second nearest) is far smaller out there
    dist = np.sqrt(np.sort(((x[300:, None, :] - pts[None]) ** 2).sum(-1), axis=1)[:, :2])
    assert np.median(margin[300:]) > 5 * np.median((dist[:, 1] - dist[:, 0]) / 2)


def test_graph_rows_hold_the_delaunay_neighbours_in_order_then_sentinels():
    rng = np.random.default_rng(5)
    pts = _surface_cloud(rng, 300)
    graph = build_graph(pts)
    indptr, indices = Delaunay(pts).vertex_neighbor_vertices
    for i in range(len(pts)):
        lo, hi = graph.indptr[i], graph.indptr[i + 1]
        real = indices[indptr[i] : indptr[i + 1]]
        assert (hi - lo) % LANES == 0 and len(real) <= hi - lo < len(real) + LANES
        assert np.array_equal(graph.indices[lo : lo + len(real)], real)
        assert np.all(graph.indices[lo + len(real) : hi] == i)
        assert np.array_equal(graph.coords[:, lo : lo + len(real)], pts[real].T)
        assert np.all(graph.coords[:, lo + len(real) : hi] == SENTINEL)
        assert np.allclose(graph.half_inv[lo : lo + len(real)], 0.5 / np.linalg.norm(pts[real] - pts[i], axis=1))


@pytest.mark.parametrize("cloud", ["gaussian", "surfaces"])
def test_one_qhull_run_serves_the_cloud_in_every_frame_and_order(cloud):
    """The graph of a rotated, reflected, moved and scaled copy in KD-tree order, made from the
    neighbours of the original cloud (:func:`graph_for` with ``cloud``), walks from any start to
    the exact nearest point, and a move shorter than its margin keeps that point. (Where points
    are cospherical, as on the flat faces of sampled parts, a Delaunay triangulation is not
    unique and Qhull's choice depends on the frame; every choice holds these properties.)"""
    rng = np.random.default_rng(11)
    pts = rng.normal(size=(400, 3)) if cloud == "gaussian" else _surface_cloud(rng, 400)
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0] * [1.0, 1.0, -1.0]  # a reflection too
    copy = (pts - pts.mean(axis=0)) @ rot * 0.37 + [2.0, -1.0, 0.5]
    tree = build_tree(copy)
    shared = tuple(graph_for(tree, pts))
    if cloud == "gaussian":  # in general position the triangulation is unique: the same rows
        own = graph_for(tree)

        def rows(g):
            return [set(g[1][g[0][i] : g[0][i + 1]].tolist()) - {i} for i in range(len(copy))]

        assert rows(shared) == rows(own)
    x = np.concatenate(
        [
            tree.points[rng.integers(0, len(copy), 300)] + rng.normal(size=(300, 3)) * 0.02,
            rng.normal(size=(100, 3)) * 2.0,
        ]
    )
    j, margin = _walk_all(tree.points, shared, x, rng.integers(0, len(copy), len(x)))
    assert np.array_equal(j, _brute(x, tree.points))
    for scale in (0.999, 0.5):
        d = rng.normal(size=x.shape)
        d *= (scale * margin / np.linalg.norm(d, axis=1))[:, None]
        assert np.array_equal(_brute(x + d, tree.points), j)


@njit
def _scan_rows(graph, x, dj):
    out = np.empty((x.shape[0], 2))
    indptr, _, coords, half_inv = graph
    for i in range(x.shape[0]):
        j = i % (indptr.shape[0] - 1)
        out[i, 0], out[i, 1] = _scan(
            coords[0], coords[1], coords[2], half_inv, indptr[j], indptr[j + 1], x[i, 0], x[i, 1], x[i, 2], dj[i]
        )
    return out


def test_simd_scan_gives_the_scalar_minima_bitwise():
    rng = np.random.default_rng(6)
    pts = _surface_cloud(rng, 200)
    graph = build_graph(pts)
    x = rng.normal(size=(1000, 3)) * 2.0
    dj = rng.random(1000)
    got = _scan_rows(tuple(graph), x, dj)
    for i in range(len(x)):
        j = i % len(pts)
        lo, hi = graph.indptr[j], graph.indptr[j + 1]
        a, b, c = x[i, 0] - graph.coords[0, lo:hi], x[i, 1] - graph.coords[1, lo:hi], x[i, 2] - graph.coords[2, lo:hi]
        d = a * a + b * b + c * c  # the scalar loop's order of operations
        assert got[i, 0] == d.min() and got[i, 1] == ((d - dj[i]) * graph.half_inv[lo:hi]).min()


def test_uncertified_lists_the_queries_that_moved_past_their_margin_in_order():
    rng = np.random.default_rng(7)
    xref = rng.normal(size=(500, 3))
    x = xref + rng.normal(size=(500, 3)) * 0.1
    margin2 = rng.random(500) * 0.05
    margin2[::7] = -1.0  # no margin left: always searched
    todo = np.empty(500, np.int64)
    for scale in (1.0, 4.0):
        count = uncertified(x, xref, margin2, scale, todo)
        want = np.flatnonzero(((x - xref) ** 2).sum(axis=1) * scale >= margin2)
        assert np.array_equal(todo[:count], want)


@pytest.mark.parametrize("case", ["few", "flat", "duplicate"])
def test_build_graph_declines_what_a_walk_cannot_use(case):
    rng = np.random.default_rng(2)
    if case == "few":
        pts = rng.normal(size=(4, 3))
    elif case == "flat":
        pts = np.c_[rng.normal(size=(50, 2)), np.zeros(50)]
    else:
        pts = rng.normal(size=(50, 3))
        pts[7] = pts[3]
    assert build_graph(pts) is None


def test_icp_with_graphs_equals_icp_with_trees_and_the_reference():
    rng = np.random.default_rng(3)
    t_pts = _surface_cloud(rng, 600)
    p = t_pts[rng.permutation(600)[:500]] + rng.normal(size=(500, 3)) * 0.01
    tree_t, tree_p = build_tree(t_pts), build_tree(p)
    plain = ICPProblem(p, t_pts, tree_t=tree_t, tree_p=tree_p)
    walked = ICPProblem(p, t_pts, tree_t=tree_t, tree_p=tree_p, graph_t=graph_for(tree_t), graph_p=graph_for(tree_p))
    for ang, shift in ((0.3, 0.05), (2.5, 3.0), (np.pi, 0.0)):  # near, far and flipped starts
        r0 = np.array([[np.cos(ang), -np.sin(ang), 0], [np.sin(ang), np.cos(ang), 0], [0, 0, 1.0]])
        t0 = np.array([shift, -0.5 * shift, 0.1])
        a, b = plain.run(r0, t0, 100, 1e-9), walked.run(r0, t0, 100, 1e-9)
        assert a.objective == b.objective and a.iterations == b.iterations
        assert np.array_equal(a.rotation, b.rotation) and np.array_equal(a.translation, b.translation)
        want = ref_icp(p, t_pts, r0, t0, 100, 1e-9)
        assert abs(b.objective - want[0]) <= 1e-12 * max(want[0], 1.0)
        # with a graph only the Voronoi certificate is checked: nearer than the sample spacing the
        # ball one can hold longer, far from the cloud it collapses and the Voronoi one holds
        assert b.searched < (b.iterations + 1) * (len(p) + len(t_pts))
        if shift > 1.0:
            assert b.searched < a.searched


def test_icp_falls_back_to_trees_without_a_graph():
    """A flat target has no 3-D Delaunay graph: the search falls back to the KD-tree."""
    rng = np.random.default_rng(4)
    t_pts = np.c_[rng.random((200, 2)), np.zeros(200)]
    p = t_pts + rng.normal(size=(200, 3)) * 0.01
    tree_t = build_tree(t_pts)
    assert graph_for(tree_t) is None
    got = ICPProblem(p, t_pts, tree_t=tree_t, graph_t=graph_for(tree_t)).run(np.eye(3), np.zeros(3), 50, 1e-9)
    want = ref_icp(p, t_pts, np.eye(3), np.zeros(3), 50, 1e-9)
    assert abs(got.objective - want[0]) <= 1e-12 * max(want[0], 1.0)


def test_exact_registration_of_trajectory_checkpoints_is_unchanged_by_graphs():
    """Every start of a few synthetic-trajectory checkpoints, with and without graphs."""
    from aw_eval.registration import checkpoint_starts
    from aw_eval.settings import ProtocolSettings

    geom, obj = make_points_geometry(3, 120, seed=3, settings=ProtocolSettings(n_fps=120, n_surface=1024))
    index = geom.index()
    for poses in trajectory_checkpoints(obj, 12, seed=5)[::4]:
        ck = geom.checkpoint(poses)
        pred = ck.points
        r0, t0 = checkpoint_starts(geom, ck)
        tree_p = build_tree(pred)
        plain = ICPProblem(pred, index.target, tree_t=index.tree_t, tree_p=tree_p)
        walked = ICPProblem(
            pred, index.target, tree_t=index.tree_t, tree_p=tree_p, graph_t=index.graph_t, graph_p=graph_for(tree_p)
        )
        for k in range(len(r0)):
            a, b = plain.run(r0[k], t0[k], 100, 1e-9), walked.run(r0[k], t0[k], 100, 1e-9)
            assert a.objective == b.objective and np.array_equal(a.rotation, b.rotation)
