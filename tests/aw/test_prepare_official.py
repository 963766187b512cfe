"""The official preparation protocol, bit for bit.

The expected values are computed here by following the official procedure
(``assembly_world_agent/preparation.py`` and ``utils/{random,geometry,placement,transforms,scale}.py``
of AssemblyWorld/assembly-world-agent, as of commit e4b7c9e; docs/datasets.md lists the commit of
each step) step by step, written out plainly, and compared with
:func:`aw.prepare.official_protocol.prepare_official` for exact equality. When the official code
moves, rewrite the step here from the new commit first, then follow it in the project.
"""

from __future__ import annotations

import hashlib
import json

import mapbox_earcut
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from aw.prepare.official_protocol import OfficialPart, OfficialSample, prepare_official, stream

DATASET = "AssemblyWorld/partnet-manualpa"
Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


# ---------------------------------------------------------------- the official steps, written out


def generator(seed, *names):
    text = json.dumps([seed, *names], separators=(",", ":"))
    digest = hashlib.sha256(text.encode("ascii")).digest()
    return np.random.Generator(np.random.PCG64(int.from_bytes(digest[:16], byteorder="little")))


def quat_matrix(q):
    return Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()


def matrix_quat(m):
    x, y, z, w = Rotation.from_matrix(m).as_quat(canonical=True)
    return np.array([w, x, y, z])


def frame(v):
    """PCA frame (``utils/transforms.py`` at e4b7c9e): eigenvalues within 1e-10 of the largest
    form one eigenspace, whose axes are the first centred vertices (in order) with a part outside
    the axes already taken from it; the first two axes are made orthonormal again (Gram-Schmidt)
    before the cross product gives the third."""
    c = v.mean(axis=0)
    d = v - v.mean(axis=0)
    w, e = np.linalg.eigh(d.T @ d)
    w, e = w[::-1], e[:, ::-1]
    radius = max(np.linalg.norm(d, axis=1).max(), np.finfo(float).tiny)
    tol = max(float(w[0]), np.finfo(float).tiny) * 1e-10
    groups, k = [], 0
    while k < 3:
        m = k + 1
        while m < 3 and abs(w[m] - w[k]) <= tol:
            m += 1
        groups.append((k, m))
        k = m
    axes = []
    for lo, hi in groups:
        if len(axes) >= 2:
            break
        proj = e[:, lo:hi] @ e[:, lo:hi].T
        mine = []
        for row in d / radius:
            cand = proj @ row
            for prev in mine:
                cand = cand - prev * np.dot(prev, cand)
            n = np.linalg.norm(cand)
            if n > 1e-8:
                mine.append(cand / n)
            if len(mine) == hi - lo:
                break
        axes += mine
    x = axes[0] / np.linalg.norm(axes[0])
    y = axes[1] - np.dot(x, axes[1]) * x
    y = y / np.linalg.norm(y)
    return c, np.column_stack([x, y, np.cross(x, y)])


def triangles(v, faces):
    out = []
    for f in faces:
        if len(f) == 3:
            out.append(list(f))
            continue
        poly = v[list(f)]
        d = poly - poly.mean(axis=0)
        _, sv, vt = np.linalg.svd(d, full_matrices=False)
        assert sv[1] > np.finfo(float).eps * sv[0]
        flat = np.ascontiguousarray(d @ vt[:2].T)
        cut = mapbox_earcut.triangulate_float64(flat, np.array([len(f)], dtype=np.uint32)).reshape(-1, 3)
        out.extend([[f[a], f[b], f[c]] for a, b, c in cut])
    t = np.array(out, dtype=np.int64)
    xyz = v[t]
    area = np.linalg.norm(np.cross(xyz[:, 1] - xyz[:, 0], xyz[:, 2] - xyz[:, 0]), axis=1)
    return t[area > 0]


def surface(v, faces, rng):
    xyz = v[triangles(v, faces)]
    area = np.linalg.norm(np.cross(xyz[:, 1] - xyz[:, 0], xyz[:, 2] - xyz[:, 0]), axis=1)
    tri = rng.choice(len(xyz), size=4096, p=area / area.sum())
    u = rng.random((4096, 2))
    out = np.empty((4096, 3))
    for n in range(4096):
        s = np.sqrt(u[n, 0])
        w = np.array([1 - s, s * (1 - u[n, 1]), s * u[n, 1]])
        out[n] = np.einsum("i,ij->j", w, xyz[tri[n]])
    return out


def fps(points, rng):
    best = np.full(len(points), np.inf)
    used = np.zeros(len(points), dtype=bool)
    pick = int(rng.integers(len(points)))
    order = []
    while len(order) < 1000:
        order.append(pick)
        used[pick] = True
        diff = points - points[pick]
        best = np.minimum(best, np.einsum("ij,ij->i", diff, diff))
        best[used] = -np.inf
        pick = int(np.argmax(best))  # first index among equal maxima
    return np.array(order)


def layout(local, seed, sample_id, gap=0.02):
    ids = sorted(local)
    turned, turn, box = {}, {}, {}
    for pid in ids:
        yaw = generator(seed, DATASET, sample_id, pid, "yaw").uniform(-np.pi, np.pi)
        turn[pid] = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
        turned[pid] = local[pid] @ turn[pid].T
        box[pid] = np.array([turned[pid][:, :2].min(0), turned[pid][:, :2].max(0)])
    rng = generator(seed, DATASET, sample_id, "placement")
    order = [ids[k] for k in rng.permutation(len(ids))]
    side = (max(float(np.max(b[1] - b[0])) for b in box.values()) + gap) * np.ceil(np.sqrt(len(ids)))

    def clear(a, b):
        return bool(np.any(a[1] + gap <= b[0]) or np.any(b[1] + gap <= a[0]))

    for _level in range(5):
        xy, boxes = {}, []
        for pid in order:
            for _ in range(128):
                trial = rng.uniform(-side / 2, side / 2, size=2)
                if all(clear(box[pid] + trial, other) for other in boxes):
                    xy[pid] = trial
                    boxes.append(box[pid] + trial)
                    break
            else:
                break
        if len(xy) == len(ids):
            break
        side *= 1.5
    assert len(xy) == len(ids), "the grid fallback is not exercised here"
    lo = np.min([box[p][0] + xy[p] for p in ids], axis=0)
    hi = np.max([box[p][1] + xy[p] for p in ids], axis=0)
    mid = (lo + hi) / 2
    return {p: (np.r_[xy[p] - mid, -turned[p][:, 2].min()], matrix_quat(turn[p])) for p in ids}


def adapter_pose(t, q):
    """The adapters' reading of a pose (``pose_from_values``, e4b7c9e): SciPy's matrix of the
    quaternion, then that matrix's canonical quaternion."""
    return np.asarray(t, dtype=np.float64), matrix_quat(quat_matrix(np.asarray(q, dtype=np.float64)))


def official_by_hand(parts, sample_id, seed, up):
    """``parts``: (part id, vertices, faces, (position, wxyz)) in source order."""
    parts = [(pid, v, faces, adapter_pose(*pose)) for pid, v, faces, pose in parts]
    placed = [v @ quat_matrix(q).T + t for _, v, _, (t, q) in parts]
    scale = 2 * max(float(np.linalg.norm(v - v.mean(0), axis=1).max()) for _, v, _, _ in parts)
    every = np.concatenate(placed) @ up.T
    low, high = every.min(axis=0), every.max(axis=0)
    origin = (low + high) / 2
    origin[2] = low[2]
    lin, off = up / scale, -origin / scale
    local, cloud, target = {}, {}, {}
    for pid, v, faces, (t, q) in parts:
        c, basis = frame(v)
        local[pid] = (v - c) @ basis / scale
        centre = (c @ quat_matrix(q).T + t) @ lin.T + off
        rot = up @ quat_matrix(q) @ basis
        cand = surface(local[pid], faces, generator(seed, DATASET, sample_id, pid, "surface"))
        cloud[pid] = cand[fps(cand, generator(seed, DATASET, sample_id, pid, "fps"))]
        target[pid] = (centre, matrix_quat(rot))
    start = layout(local, seed, sample_id)
    baked, final = {}, {}
    for pid, (p0, q0) in start.items():
        r0 = quat_matrix(q0)
        rt = quat_matrix(target[pid][1]) @ r0.T
        baked[pid] = local[pid] @ r0.T + p0
        cloud[pid] = cloud[pid] @ r0.T + p0
        final[pid] = np.r_[target[pid][0] - rt @ p0, matrix_quat(rt)]
    diag = []
    for pid, *_ in parts:
        c, basis = frame(baked[pid])
        diag.append(float(np.linalg.norm(np.ptp((baked[pid] - c) @ basis, axis=0))))
    ids = sorted(local)
    return ids, np.stack([cloud[p] for p in ids]), np.stack([final[p] for p in ids]), max(diag), [baked[p] for p in ids]


# ---------------------------------------------------------------- meshes made here


def slab(dx, dy, dz, quads=True):
    """A box with three distinct extents: 8 vertices, 6 quads (or 12 triangles)."""
    v = np.array([[x, y, z] for x in (0, dx) for y in (0, dy) for z in (0, dz)], dtype=np.float64)
    quad = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    if quads:
        return v, tuple(quad)
    return v, tuple(t for a, b, c, d in quad for t in ((a, b, c), (a, c, d)))


def wedge():
    """An irregular triangulated solid, plus one unused vertex (the official keeps every vertex)."""
    v = np.array([[0, 0, 0], [0.3, 0.02, 0], [0.05, 0.2, 0.01], [0.1, 0.07, 0.12], [0.9, 0.9, 0.9]], dtype=np.float64)
    return v, ((0, 2, 1), (0, 1, 3), (1, 2, 3), (2, 0, 3))


def ell_prism():
    """A prism on a concave L-shaped polygon whose long edges hold collinear vertices (as CAD
    meshes do), so that which ear the ear-clipping cuts first turns on the last bits of the
    part frame; turned off the axes. Two polygon faces of 13 vertices, 13 quads."""
    xs = np.linspace(0.0, 1.0, 6)
    outline = [(x, 0.0) for x in xs] + [
        (1.0, 0.2),
        (0.8, 0.2),
        (0.6, 0.2),
        (0.4, 0.2),
        (0.4, 0.6),
        (0.0, 0.6),
        (0.0, 0.3),
    ]
    n = len(outline)
    flat = np.array(outline)
    v = np.vstack([np.c_[flat, np.zeros(n)], np.c_[flat, np.full(n, 0.07)]])
    v = v @ Rotation.from_euler("zyx", [0.41, -0.73, 1.9]).as_matrix().T + [0.2, -0.3, 0.15]
    faces = [tuple(range(n))[::-1], tuple(range(n, 2 * n))] + [
        (i, (i + 1) % n, n + (i + 1) % n, n + i) for i in range(n)
    ]
    return v, tuple(faces)


def sample_parts():
    a = slab(0.5, 0.25, 0.08)
    b = slab(0.06, 0.3, 0.11, quads=False)
    c = wedge()
    turn = -1.3 * matrix_quat(Rotation.from_euler("xyz", [0.3, -0.2, 1.1]).as_matrix())  # neither unit nor w >= 0
    post = slab(0.1, 0.1, 0.4, quads=False)  # square section: two equal eigenvalues
    return [
        ("post", post[0], post[1], (np.array([0.3, -0.1, 0.0]), np.array([1.0, 0, 0, 0]))),
        ("seat", a[0], a[1], (np.zeros(3), np.array([1.0, 0, 0, 0]))),
        ("back", b[0], b[1], (np.array([0.1, 0.2, -0.05]), turn)),
        ("arm_2", c[0], c[1], (np.array([-0.2, 0.0, 0.3]), np.array([1.0, 0, 0, 0]))),
        ("ell", *ell_prism(), (np.array([0.0, 0.4, 0.1]), np.array([1.0, 0, 0, 0]))),
    ]


@pytest.mark.parametrize("seed", [7])
def test_prepare_official_equals_the_procedure_bit_for_bit(seed):
    raw = sample_parts()
    sample = OfficialSample(
        DATASET, "chair-0042", tuple(OfficialPart(p, v, f, (*t, *q)) for p, v, f, (t, q) in raw), Y_UP
    )
    got = prepare_official(sample, seed, groups=False)
    ids, points, targets, divisor, baked = official_by_hand(raw, "chair-0042", seed, Y_UP)
    assert got.part_ids == ids == ["arm_2", "back", "ell", "post", "seat"]
    assert got.points.shape == (5, 1000, 3) and got.points.dtype == np.float64
    assert np.array_equal(got.points, points)
    assert np.array_equal(got.targets, targets)
    assert got.divisor == divisor
    for mine, theirs in zip(got.vertices, baked, strict=True):
        assert np.array_equal(mine, theirs)
    # the targets put the baked parts back together: the assembled object, Z up, grounded
    assembled = np.concatenate(
        [v @ quat_matrix(t[3:]).T + t[:3] for v, t in zip(got.vertices, got.targets, strict=True)]
    )
    assert assembled[:, 2].min() == pytest.approx(0, abs=1e-12)


def test_streams_are_per_identity_and_order_free():
    a = stream(0, DATASET, "s", "p1", "surface").random(4)
    assert np.array_equal(a, generator(0, DATASET, "s", "p1", "surface").random(4))
    assert not np.array_equal(a, stream(0, DATASET, "s", "p2", "surface").random(4))
    assert not np.array_equal(a, stream(1, DATASET, "s", "p1", "surface").random(4))
    # a part's points do not depend on which other parts the object has
    raw = sample_parts()
    whole = prepare_official(
        OfficialSample(DATASET, "x", tuple(OfficialPart(p, v, f, (*t, *q)) for p, v, f, (t, q) in raw), Y_UP),
        groups=False,
    )
    fewer = prepare_official(
        OfficialSample(DATASET, "x", tuple(OfficialPart(p, v, f, (*t, *q)) for p, v, f, (t, q) in raw[:2]), Y_UP),
        groups=False,
    )
    k, j = whole.part_ids.index("seat"), fewer.part_ids.index("seat")
    # same local samples up to the (different) layout: same shape of cloud
    d1 = np.linalg.norm(whole.points[k] - whole.points[k][0], axis=1)
    d2 = np.linalg.norm(fewer.points[j] - fewer.points[j][0], axis=1)
    assert np.allclose(d1 * whole.scale, d2 * fewer.scale, rtol=1e-12, atol=1e-12)


def test_a_degenerate_part_is_named():
    flat = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]])
    bad = OfficialSample(DATASET, "s9", (OfficialPart("rod", flat, ((0, 1, 2),)),))
    with pytest.raises(ValueError, match="degenerate part"):
        prepare_official(bad, groups=False)


def test_geometry_groups_join_congruent_parts_only():
    from aw.prepare.official_similarity import geometry_groups

    rng = np.random.default_rng(3)
    shape = rng.normal(size=(120, 3)) * [0.3, 0.1, 0.05]
    other = rng.normal(size=(120, 3)) * [0.2, 0.15, 0.02]
    turn = Rotation.from_euler("zyx", [0.7, 0.1, -0.4]).as_matrix()
    moved = shape @ turn.T + [1.0, -2.0, 0.5]
    ids = ["a", "b", "c"]
    clouds = np.stack([shape, other, moved])
    groups = geometry_groups(ids, clouds, list(clouds), 1.0)
    assert sorted(sorted(g) for g in groups) == [["a", "c"], ["b"]]


def test_the_concave_face_is_cut_differently_under_the_older_frame_rule():
    """Why the L-shaped prism is in the sample: under the frame of the earlier official commit
    (6ddf7cf: third axis the cross product of the first two as found, no second Gram-Schmidt
    step) its ear-clipping differs, so a project still on that rule samples other points."""
    v, faces = ell_prism()
    c, basis = frame(v)
    # the older rule's first two axes are the newer's before the second step: rebuild them
    d = v - v.mean(axis=0)
    w, e = np.linalg.eigh(d.T @ d)
    e = e[:, ::-1]
    rows = d / np.linalg.norm(d, axis=1).max()
    first = next(r for r in (e[:, :1] @ e[:, :1].T @ row for row in rows) if np.linalg.norm(r) > 1e-8)
    first = first / np.linalg.norm(first)
    second = next(r for r in (e[:, 1:2] @ e[:, 1:2].T @ row for row in rows) if np.linalg.norm(r) > 1e-8)
    second = second / np.linalg.norm(second)
    assert len(set(np.round(w, 12))) == 3  # distinct eigenvalues: one axis per eigenspace
    older = np.column_stack([first, second, np.cross(first, second)])
    assert not np.array_equal(older, basis)
    assert not np.array_equal(triangles((v - c) @ older, faces), triangles((v - c) @ basis, faces))


def test_a_pose_needs_seven_finite_numbers_and_a_nonzero_quaternion():
    v, faces = slab(0.5, 0.25, 0.08)
    for pose, message in (((0, 0, 0, 0, 0, 0, 0), "non-zero"), ((0, 0, np.nan, 1, 0, 0, 0), "7 finite numbers")):
        bad = OfficialSample(DATASET, "s8", (OfficialPart("seat", v, faces, pose),))
        with pytest.raises(ValueError, match=f"{DATASET}/s8: a pose.*{message}"):
            prepare_official(bad, groups=False)


def _placed_boxes(extents, n_points, seed):
    """Official-style inputs: points ``(P, n, 3)`` and mesh vertices of turned, spread-out boxes."""
    import trimesh

    rng = np.random.default_rng(seed)
    points, verts = [], []
    for k, e in enumerate(extents):
        box = trimesh.creation.box(extents=e)
        pts, _ = trimesh.sample.sample_surface(box, n_points, seed=100 + k)
        turn = Rotation.random(random_state=rng).as_matrix()
        points.append(np.asarray(pts) @ turn.T + [2.0 * k, 0, 0])
        verts.append(np.asarray(box.vertices) @ turn.T + [2.0 * k, 0, 0])
    return np.stack(points), verts


def test_geometry_groups_equal_registering_every_pair(monkeypatch):
    import aw.prepare.official_similarity as sim

    rng = np.random.default_rng(8)
    objects = {
        "pegs": [(3.0, 3.0, 0.05)] + [(0.1, 0.1, 0.3)] * 9,  # many identical small parts
        "near": [
            (4.0, 4.0, 0.05),
            (0.6, 0.2, 0.1),
            (0.63, 0.2, 0.1),
            (0.66, 0.21, 0.1),
            (0.7, 0.2, 0.1),
            (0.6, 0.2, 0.14),
            (0.75, 0.25, 0.1),
        ],  # pairs on both sides of 1e-4
        "distinct": [tuple(sorted(rng.uniform(0.05, 1.0, 3), reverse=True)) for _ in range(8)],
    }
    calls = []
    real = sim.register
    monkeypatch.setattr(sim, "register", lambda *a, **k: calls.append(1) or real(*a, **k))
    sizes = set()
    for name, extents in objects.items():
        points, verts = _placed_boxes(extents, 64, seed=len(name))
        ids = [f"p{k:02d}" for k in range(len(extents))]
        divisor = max(float(np.linalg.norm(e)) for e in extents)
        calls.clear()
        fast = sim.geometry_groups(ids, points, verts, divisor, workers=2)  # threads: the same groups
        n_fast = len(calls)
        assert fast == sim.geometry_groups_all_pairs(ids, points, verts, divisor), name
        assert n_fast < len(calls) - n_fast, name
        sizes |= {len(g) for g in fast}
    assert max(sizes) >= 5 and 1 in sizes


class _Fixed:
    """A stand-in stream whose one ``integers`` draw is given (the batched version takes the draws)."""

    def __init__(self, value):
        self.value = int(value)

    def integers(self, n):
        return self.value


def test_batched_farthest_point_samples_pick_the_single_version_indices(monkeypatch):
    from aw.prepare import official_protocol
    from aw.prepare.official_protocol import farthest_point_sample, farthest_point_samples, stream

    rng = np.random.default_rng(12)
    clouds = rng.normal(size=(7, 300, 3)) * [1.0, 0.3, 0.1] + rng.normal(size=3) * 100  # far off: rounding
    clouds[3, 150:] = clouds[3, :150]  # duplicates: ties among equal distances
    clouds[5, :, 2] = 0.0  # flat
    clouds[6] = np.round(clouds[6], 1)  # many exact ties
    firsts = [int(stream(0, "d", "s", str(k), "fps").integers(300)) for k in range(7)]
    single = np.stack([farthest_point_sample(c, 200, stream(0, "d", "s", str(k), "fps")) for k, c in enumerate(clouds)])
    assert np.array_equal(farthest_point_samples(clouds, 200, firsts, chunk=3), single)
    first_single = single
    many = rng.uniform(-1, 1, size=(40, 4096, 3)) * rng.uniform(0.01, 10, size=(40, 1, 3))
    starts = rng.integers(4096, size=40)
    single = [farthest_point_sample(c, 1000, _Fixed(s)) for c, s in zip(many, starts, strict=True)]
    assert np.array_equal(farthest_point_samples(many, 1000, starts), np.stack(single))
    # the batched einsum, where NumPy rounds its sum in another order, picks them too
    monkeypatch.setattr(official_protocol, "_einsum_sums_x_z_then_y", lambda: False)
    assert np.array_equal(farthest_point_samples(clouds, 200, firsts, chunk=3), first_single)
    with pytest.raises(ValueError, match="count"):
        farthest_point_samples(clouds, 301, firsts)
