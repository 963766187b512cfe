"""Small synthetic assemblies and checkpoints for the evaluator's tests and benchmarks.

Objects are built from trimesh primitives (boxes, cylinders, identical legs, spheres): an
assembled part mesh ``A_i`` is moved by a random layout pose ``L_i`` into the baked mesh
``B_i = L_i(A_i)``, and the target pose is ``L_i^{-1}`` (so it maps the baked mesh onto the
assembled object), exactly the task convention. Checkpoints are part poses ``(P, 7)`` made
from the targets by perturbations of chosen sizes, optional global rigid motions, and
never-moved parts (identity poses).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from aw.pose import IDENTITY_POSE, apply_pose, compose_poses, invert_pose, quat_from_axis_angle, quat_to_matrix

__all__ = [
    "SyntheticObject",
    "make_object",
    "random_rotation_quat",
    "perturb",
    "random_checkpoints",
    "trajectory_checkpoints",
    "PERTURBATION_KINDS",
]


@dataclass
class SyntheticObject:
    meshes: list[trimesh.Trimesh]  # baked meshes (initial layout placement included)
    target_poses: np.ndarray  # (P, 7)
    part_ids: list[str]
    identical: list[list[int]]  # groups built from the same primitive mesh (size >= 2)


def random_rotation_quat(rng: np.random.Generator, max_angle_rad: float | None = None) -> np.ndarray:
    """A random unit quaternion (uniform if ``max_angle_rad`` is None, else a random axis and an
    angle uniform in ``[0, max_angle_rad]``)."""
    if max_angle_rad is None:
        q = rng.normal(size=4)
        return q / np.linalg.norm(q)
    axis = rng.normal(size=3)
    return quat_from_axis_angle(axis, rng.uniform(0, max_angle_rad))


def _moved(mesh: trimesh.Trimesh, pose: np.ndarray) -> trimesh.Trimesh:
    return trimesh.Trimesh(apply_pose(pose, np.asarray(mesh.vertices)), np.asarray(mesh.faces), process=False)


def make_object(n_parts: int, seed: int = 0, identical_legs: bool = True) -> SyntheticObject:
    """A table-like assembly of ``n_parts`` parts: a top, up to four identical legs, and assorted
    boxes, cylinders and spheres (symmetric shapes) around it. Baked into a spread-out layout."""
    if n_parts < 1:
        raise ValueError("n_parts must be >= 1")
    rng = np.random.default_rng(seed)
    assembled: list[trimesh.Trimesh] = []
    kinds: list[str] = []
    top = trimesh.creation.box(extents=[1.0, 0.6, 0.05])
    top.apply_translation([0, 0, 0.5])
    assembled.append(top)
    kinds.append("top")
    n_legs = min(4, n_parts - 1) if identical_legs else 0
    leg = trimesh.creation.cylinder(radius=0.03, height=0.48, sections=10)
    for k in range(n_legs):
        sx, sy = (1 if k % 2 == 0 else -1), (1 if k < 2 else -1)
        m = leg.copy()
        m.apply_translation([0.42 * sx, 0.24 * sy, 0.24])
        assembled.append(m)
        kinds.append("leg")
    while len(assembled) < n_parts:
        k = len(assembled)
        choice = k % 3
        centre = rng.uniform([-0.5, -0.3, 0.0], [0.5, 0.3, 0.9])
        if choice == 0:
            m = trimesh.creation.box(extents=rng.uniform(0.05, 0.35, 3))
        elif choice == 1:
            m = trimesh.creation.cylinder(radius=rng.uniform(0.02, 0.08), height=rng.uniform(0.1, 0.5), sections=12)
        else:
            m = trimesh.creation.icosphere(subdivisions=1, radius=rng.uniform(0.03, 0.1))
        rot = np.eye(4)
        rot[:3, :3] = trimesh.transformations.random_rotation_matrix(rng.random(3))[:3, :3]
        m.apply_transform(rot)
        m.apply_translation(centre)
        assembled.append(m)
        kinds.append(f"misc{k}")
    # Layout: parts on a grid, randomly rotated (the baked initial placement).
    baked, targets = [], []
    cols = int(np.ceil(np.sqrt(n_parts)))
    for i, m in enumerate(assembled):
        pos = np.array([1.3 * (i % cols) - 2.0, 1.3 * (i // cols) - 2.0, 0.0]) - m.centroid
        q = random_rotation_quat(rng)
        layout = np.concatenate([np.zeros(3), q])
        # rotate about the centroid, then move to the grid cell
        layout[:3] = pos + m.centroid - _rot(q) @ m.centroid
        baked.append(_moved(m, layout))
        targets.append(invert_pose(layout))
    legs = [i for i, k in enumerate(kinds) if k == "leg"]
    return SyntheticObject(
        baked, np.stack(targets), [f"p{i + 1:02d}" for i in range(n_parts)], [legs] if len(legs) > 1 else []
    )


def _rot(q):
    return quat_to_matrix(q)


PERTURBATION_KINDS = ("exact", "tiny", "near", "small", "medium", "far", "never")


def perturb(
    target_pose: np.ndarray, kind: str, rng: np.random.Generator, centre: np.ndarray | None = None
) -> np.ndarray:
    """A part pose near ``target_pose`` (baked frame -> assembled frame).

    ``kind``: ``exact`` (the target), ``tiny`` (~1e-3 units and 0.1 deg), ``near`` (~0.01 and 1 deg),
    ``small`` (~0.03 and 3 deg), ``medium`` (~0.2 and 20 deg), ``far`` (random orientation, up to
    2 units away), ``never`` (the identity: never moved). Rotations turn about ``centre`` (the
    part's assembled centre) so that translation and rotation sizes stay independent.
    """
    if kind == "exact":
        return np.asarray(target_pose, dtype=np.float64).copy()
    if kind == "never":
        return IDENTITY_POSE.copy()
    sizes = {"tiny": (1e-3, 0.1), "near": (0.01, 1.0), "small": (0.03, 3.0), "medium": (0.2, 20.0)}
    if kind == "far":
        q = random_rotation_quat(rng)
        shift = rng.uniform(-2, 2, 3)
    elif kind in sizes:
        t, deg = sizes[kind]
        q = random_rotation_quat(rng, np.radians(deg))
        shift = rng.normal(size=3) * t / np.sqrt(3)
    else:
        raise ValueError(f"unknown perturbation kind {kind!r}; use one of {PERTURBATION_KINDS}")
    c = np.zeros(3) if centre is None else np.asarray(centre, dtype=np.float64)
    # delta = translate(c + shift) * rotate(q) * translate(-c), applied after the target pose
    delta = np.concatenate([c + shift - _rot(q) @ c, q])
    return compose_poses(delta, target_pose)


def random_checkpoints(
    obj: SyntheticObject, n: int, seed: int = 0, kinds=PERTURBATION_KINDS, global_motion: bool = True
) -> np.ndarray:
    """``(n, P, 7)`` checkpoints: each draws one dominant perturbation kind, applies it to a random
    subset of parts (others exact or tiny), and optionally moves the whole prediction rigidly."""
    rng = np.random.default_rng(seed)
    p = len(obj.meshes)
    centres = np.stack([_assembled_centre(m, t) for m, t in zip(obj.meshes, obj.target_poses, strict=True)])
    out = np.empty((n, p, 7))
    for k in range(n):
        kind = kinds[rng.integers(len(kinds))]
        mask = rng.random(p) < rng.uniform(0.2, 1.0)
        for i in range(p):
            kk = kind if mask[i] else ("exact" if rng.random() < 0.5 else "tiny")
            out[k, i] = perturb(obj.target_poses[i], kk, rng, centres[i])
        if global_motion and rng.random() < 0.7:
            g = np.concatenate([rng.uniform(-3, 3, 3), random_rotation_quat(rng)])
            moved = ~np.all(out[k] == IDENTITY_POSE, axis=1)
            out[k, moved] = compose_poses(g, out[k, moved])
    return out


def _assembled_centre(mesh: trimesh.Trimesh, target: np.ndarray) -> np.ndarray:
    return apply_pose(target, np.asarray(mesh.vertices)).mean(axis=0)


def make_points_geometry(n_parts: int, n_points: int, seed: int = 0, settings=None, groups=None):
    """A :class:`aw_eval.TaskGeometry` of :func:`make_object` built straight from point clouds
    (no mesh files): every assembled part is sampled (``4 n_points`` surface samples, then FPS
    to ``n_points``), identical legs share one sample pattern (so they are exactly equivalent at
    any resolution), and clouds are baked by the layout poses. Returns ``(geometry, object)``."""
    from aw_eval.geometry import TaskGeometry, part_divisor
    from aw_eval.sampling import fps_numpy, part_seed, surface_samples
    from aw_eval.settings import ProtocolSettings

    obj = make_object(n_parts, seed)
    settings = settings or ProtocolSettings(n_surface=4 * n_points, n_fps=n_points)
    legs = obj.identical[0] if obj.identical else []
    clouds = []
    leg_cloud = None
    for i, (mesh, target) in enumerate(zip(obj.meshes, obj.target_poses, strict=True)):
        assembled = apply_pose(target, np.asarray(mesh.vertices))
        m = trimesh.Trimesh(assembled, np.asarray(mesh.faces), process=False)
        if i in legs and leg_cloud is not None:
            c = leg_cloud[0] + (assembled.mean(axis=0) - leg_cloud[1])
        else:
            cand = surface_samples(m, 4 * n_points, part_seed(seed, i))
            c = cand[fps_numpy(cand, n_points)]
            if i in legs:
                leg_cloud = (c, assembled.mean(axis=0))
        clouds.append(apply_pose(invert_pose(target), c))
    divisor = max(part_divisor(np.asarray(m.vertices)) for m in obj.meshes)
    geom = TaskGeometry.from_points(obj.part_ids, np.stack(clouds), obj.target_poses, divisor, groups, settings)
    return geom, obj


def swap_identical(geom, poses: np.ndarray, a: int, b: int) -> np.ndarray:
    """Poses in which identical parts ``a`` and ``b`` trade places: part ``a`` is put exactly where
    ``poses`` put part ``b`` and vice versa. Needs clouds that are translates of each other in the
    assembled frame (as :func:`make_points_geometry` builds identical legs)."""
    t = geom.target_poses
    ca = apply_pose(t[a], geom.clouds[a]).mean(axis=0)
    cb = apply_pose(t[b], geom.clouds[b]).mean(axis=0)
    out = np.array(poses, dtype=np.float64, copy=True)
    for src, dst, d in ((a, b, cb - ca), (b, a, ca - cb)):
        shift = np.concatenate([d, [1.0, 0.0, 0.0, 0.0]])
        out[src] = compose_poses(poses[dst], compose_poses(invert_pose(t[dst]), compose_poses(shift, t[src])))
    return out


def synthetic_trajectory(obj: SyntheticObject, n_steps: int, seed: int = 0) -> np.ndarray:
    """``(n_steps + 1, P, 7)`` checkpoints of an agent-like episode: it starts from the baked
    layout (identity poses); each step moves one part (or, sometimes, nudges or rotates a placed
    one) towards its place in an assembly built at a random offset and orientation, with
    placement errors from tiny to small and occasional gross mistakes."""
    rng = np.random.default_rng(seed)
    p = len(obj.meshes)
    centres = np.stack([_assembled_centre(m, t) for m, t in zip(obj.meshes, obj.target_poses, strict=True)])
    g = np.concatenate([rng.uniform(-1.5, 1.5, 3), random_rotation_quat(rng)])
    poses = np.tile(IDENTITY_POSE, (p, 1))
    out = [poses.copy()]
    order = rng.permutation(p)
    placed: list[int] = []
    for _ in range(n_steps):
        if len(placed) < p and (rng.random() < 0.7 or not placed):
            i = int(order[len(placed)])
            placed.append(i)
        else:
            i = int(placed[rng.integers(len(placed))])
        kind = rng.choice(["tiny", "near", "small", "medium", "far"], p=[0.3, 0.35, 0.2, 0.1, 0.05])
        poses[i] = compose_poses(g, perturb(obj.target_poses[i], str(kind), rng, centres[i]))
        out.append(poses.copy())
    return np.stack(out)


def trajectory_checkpoints(obj: SyntheticObject, n: int, seed: int) -> np.ndarray:
    """``n`` checkpoints ``(n, P, 7)`` from consecutive synthetic trajectories (about 3 edits per
    part each, seeds ``seed, seed + 1, ...``). Prefix-stable: the first ``k`` rows do not depend
    on ``n >= k``."""
    p = len(obj.meshes)
    out: list[np.ndarray] = []
    k = 0
    while sum(len(t) for t in out) < n:
        out.append(synthetic_trajectory(obj, 3 * p, seed=seed + k))
        k += 1
    return np.concatenate(out)[:n]
