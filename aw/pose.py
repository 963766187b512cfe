"""Rigid-pose math: positions + unit quaternions (w, x, y, z), matrices, Euler angles, PCA frames.

Conventions (the paper's): right-handed, world up +Z, quaternions scalar-first (w, x, y, z),
a pose on the wire is ``[x, y, z, qw, qx, qy, qz]``. Intrinsic XYZ Euler angles mean
``R = Rx(a) @ Ry(b) @ Rz(c)``; the same matrix is the extrinsic (world-frame) rotation that
applies Z first, then Y, then X. ``rotate_objects`` applies X, then Y, then Z *about world (or
camera) axes*, which is the matrix ``Rz(c) @ Ry(b) @ Rx(a)`` (see :func:`matrix_from_xyz_sequence`).

Every function validates its input: degenerate data (zero or non-finite quaternions, non-finite
numbers, wrong shapes) raises ``ValueError`` with a message that says what was wrong; nothing
silently returns NaN. Batched functions accept any leading shape.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Pose",
    "as_finite",
    "normalize_quaternion",
    "quat_multiply",
    "quat_conjugate",
    "quat_to_matrix",
    "matrix_to_quat",
    "quat_from_axis_angle",
    "quat_to_axis_angle",
    "matrix_from_euler_xyz",
    "euler_xyz_from_matrix",
    "matrix_from_xyz_sequence",
    "rotation_about_axis",
    "apply_pose",
    "compose_poses",
    "invert_pose",
    "poses_to_matrices",
    "matrices_to_poses",
    "pca_frame",
    "cube_rotations",
    "rotation_angle_deg",
    "IDENTITY_POSE",
]

IDENTITY_POSE = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
# Unit-norm tolerance for quaternions that claim to be normalized already.
_QUAT_EPS = 1e-12


def as_finite(values, shape_tail: tuple[int, ...] | None = None, name: str = "array") -> np.ndarray:
    """Return ``values`` as a float64 array, raising ``ValueError`` if non-finite or misshapen.

    ``shape_tail``: required trailing shape, e.g. ``(3,)`` or ``(4,)``.
    """
    if values is None:
        raise ValueError(f"{name} must be numeric, got None")
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be numeric, got {type(values).__name__}") from exc
    if shape_tail is not None:
        k = len(shape_tail)
        if arr.ndim < k or tuple(arr.shape[arr.ndim - k :]) != tuple(shape_tail):
            raise ValueError(f"{name} must have trailing shape {shape_tail}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains non-finite values (NaN or infinity)")
    return arr


def normalize_quaternion(q, name: str = "quaternion") -> np.ndarray:
    """Unit quaternion(s) (w, x, y, z) from ``q: (..., 4)``; zero or non-finite input raises."""
    q = as_finite(q, (4,), name)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm < 1e-9):
        raise ValueError(f"{name} has zero length; a rotation needs a non-zero (w, x, y, z)")
    return q / norm


def quat_conjugate(q) -> np.ndarray:
    """Conjugate (inverse for unit quaternions). ``q: (..., 4)``."""
    q = as_finite(q, (4,), "quaternion")
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_multiply(a, b) -> np.ndarray:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``). ``a, b: (..., 4)``."""
    a = as_finite(a, (4,), "quaternion")
    b = as_finite(b, (4,), "quaternion")
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_to_matrix(q) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` from quaternions ``(..., 4)`` (normalized here)."""
    q = normalize_quaternion(q)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    # entries written in place (stacking small arrays cost more than the arithmetic)
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - w * z)
    m[..., 0, 2] = 2 * (x * z + w * y)
    m[..., 1, 0] = 2 * (x * y + w * z)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - w * x)
    m[..., 2, 0] = 2 * (x * z - w * y)
    m[..., 2, 1] = 2 * (y * z + w * x)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return m


def _check_rotation(m: np.ndarray, name: str) -> None:
    eye = np.eye(3)
    err = np.abs(np.einsum("...ji,...jk->...ik", m, m) - eye).max() if m.size else 0.0
    if err > 1e-6 or np.any(np.linalg.det(m) < 0):
        raise ValueError(f"{name} is not a proper rotation matrix (orthonormal, determinant +1)")


def matrix_to_quat(m) -> np.ndarray:
    """Quaternions ``(..., 4)`` with w >= 0 from rotation matrices ``(..., 3, 3)``."""
    m = as_finite(m, (3, 3), "rotation matrix")
    _check_rotation(m, "rotation matrix")
    flat = m.reshape(-1, 3, 3)
    out = np.empty((flat.shape[0], 4))
    for k, r in enumerate(flat):
        tr = np.trace(r)
        # Shepperd's method: pick the largest diagonal term for numerical stability.
        cands = np.array([tr, r[0, 0], r[1, 1], r[2, 2]])
        i = int(np.argmax(cands))
        if i == 0:
            s = np.sqrt(1.0 + tr) * 2
            q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
        elif i == 1:
            s = np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2
            q = [(r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
        elif i == 2:
            s = np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2
            q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s]
        else:
            s = np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2
            q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s]
        quat = np.asarray(q)
        quat /= np.linalg.norm(quat)
        out[k] = -quat if quat[0] < 0 else quat
    return out.reshape(m.shape[:-2] + (4,))


def quat_from_axis_angle(axis, angle_rad) -> np.ndarray:
    """Quaternion ``(..., 4)`` for a rotation of ``angle_rad`` about ``axis: (..., 3)``."""
    axis = as_finite(axis, (3,), "axis")
    angle = as_finite(angle_rad, None, "angle")
    n = np.linalg.norm(axis, axis=-1, keepdims=True)
    if np.any(n < 1e-12):
        raise ValueError("axis has zero length")
    half = 0.5 * angle[..., None]
    vec = np.sin(half) * axis / n
    w = np.broadcast_to(np.cos(half), vec.shape[:-1] + (1,))
    return np.concatenate([w, vec], axis=-1)


def quat_to_axis_angle(q) -> tuple[np.ndarray, np.ndarray]:
    """(axis ``(..., 3)``, angle ``(...)`` in [0, pi]) of quaternions; axis is +X for no rotation."""
    q = normalize_quaternion(q)
    q = np.where(q[..., :1] < 0, -q, q)
    vec = q[..., 1:]
    s = np.linalg.norm(vec, axis=-1)
    angle = 2 * np.arctan2(s, q[..., 0])
    safe = np.where(s[..., None] > 1e-15, vec / np.maximum(s, 1e-300)[..., None], [1.0, 0.0, 0.0])
    return safe, angle


def rotation_angle_deg(q) -> np.ndarray:
    """Rotation angle in degrees in [0, 180] of quaternions ``(..., 4)``."""
    return np.degrees(quat_to_axis_angle(q)[1])


def rotation_about_axis(axis_index: int, angle_rad: float) -> np.ndarray:
    """3x3 rotation about the X (0), Y (1) or Z (2) axis."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    if axis_index == 0:
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=np.float64)
    if axis_index == 1:
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=np.float64)
    if axis_index == 2:
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=np.float64)
    raise ValueError(f"axis_index must be 0, 1 or 2, got {axis_index}")


def matrix_from_euler_xyz(angles_rad) -> np.ndarray:
    """Intrinsic XYZ Euler angles ``(..., 3)`` (radians) to ``R = Rx @ Ry @ Rz``, ``(..., 3, 3)``."""
    a = as_finite(angles_rad, (3,), "Euler angles")
    flat = a.reshape(-1, 3)
    out = np.stack(
        [rotation_about_axis(0, x) @ rotation_about_axis(1, y) @ rotation_about_axis(2, z) for x, y, z in flat]
    )
    return out.reshape(a.shape[:-1] + (3, 3))


def euler_xyz_from_matrix(m) -> np.ndarray:
    """Intrinsic XYZ Euler angles ``(..., 3)`` in radians with ``R = Rx @ Ry @ Rz``.

    Angles lie in (-pi, pi] for X and Z and [-pi/2, pi/2] for Y; at gimbal lock (|Y| = 90 deg)
    the Z angle is set to 0 and X absorbs the rest.
    """
    m = as_finite(m, (3, 3), "rotation matrix")
    _check_rotation(m, "rotation matrix")
    # R = Rx Ry Rz: R[0,2] = sin(b); R[1,2] = -sin(a)cos(b); R[2,2] = cos(a)cos(b);
    # R[0,1] = -cos(b)sin(c); R[0,0] = cos(b)cos(c).
    sb = np.clip(m[..., 0, 2], -1.0, 1.0)
    b = np.arcsin(sb)
    cb = np.sqrt(np.maximum(0.0, 1 - sb * sb))
    locked = cb < 1e-9
    a = np.where(locked, np.arctan2(m[..., 2, 1], m[..., 1, 1]), np.arctan2(-m[..., 1, 2], m[..., 2, 2]))
    c = np.where(locked, 0.0, np.arctan2(-m[..., 0, 1], m[..., 0, 0]))
    return np.stack([a, b, c], axis=-1)


def matrix_from_xyz_sequence(angles_deg) -> np.ndarray:
    """Rotation applying X, then Y, then Z angles (degrees) about *fixed* axes: ``Rz @ Ry @ Rx``."""
    a = np.radians(as_finite(angles_deg, (3,), "angles"))
    return rotation_about_axis(2, a[2]) @ rotation_about_axis(1, a[1]) @ rotation_about_axis(0, a[0])


@dataclass(frozen=True)
class Pose:
    """A rigid pose: ``position (3,)`` and unit ``quaternion (4,)`` in (w, x, y, z)."""

    position: np.ndarray
    quaternion: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", as_finite(self.position, (3,), "position").reshape(3))
        object.__setattr__(self, "quaternion", normalize_quaternion(np.reshape(self.quaternion, 4)))

    @classmethod
    def identity(cls) -> Pose:
        return cls(np.zeros(3), np.array([1.0, 0, 0, 0]))

    @classmethod
    def from_array(cls, values) -> Pose:
        """From the wire form ``[x, y, z, qw, qx, qy, qz]``."""
        arr = as_finite(values, (7,), "pose").reshape(7)
        return cls(arr[:3], arr[3:])

    @classmethod
    def from_matrix(cls, m) -> Pose:
        """From a 4x4 homogeneous matrix."""
        m = as_finite(m, (4, 4), "pose matrix")
        return cls(m[:3, 3], matrix_to_quat(m[:3, :3]))

    def to_array(self) -> np.ndarray:
        return np.concatenate([self.position, self.quaternion])

    def to_list(self) -> list[float]:
        return [float(v) for v in self.to_array()]

    @property
    def rotation(self) -> np.ndarray:
        return quat_to_matrix(self.quaternion)

    def to_matrix(self) -> np.ndarray:
        m = np.eye(4)
        m[:3, :3] = self.rotation
        m[:3, 3] = self.position
        return m

    def apply(self, points) -> np.ndarray:
        """Transform ``points: (..., 3)``."""
        return as_finite(points, (3,), "points") @ self.rotation.T + self.position

    def compose(self, other: Pose) -> Pose:
        """``self * other``: apply ``other`` first, then ``self``."""
        return Pose(self.apply(other.position), quat_multiply(self.quaternion, other.quaternion))

    def inverse(self) -> Pose:
        qi = quat_conjugate(self.quaternion)
        return Pose(-(quat_to_matrix(qi) @ self.position), qi)


def apply_pose(poses, points, rotations: np.ndarray | None = None) -> np.ndarray:
    """Apply wire-form ``poses: (..., 7)`` to ``points: (..., n, 3)`` (broadcast over leading dims).
    ``rotations``: ``quat_to_matrix`` of the poses' quaternions, where the caller has them."""
    poses = as_finite(poses, (7,), "poses")
    pts = as_finite(points, (3,), "points")
    rot = quat_to_matrix(poses[..., 3:]) if rotations is None else rotations
    return np.einsum("...ij,...nj->...ni", rot, pts) + poses[..., None, :3]


def compose_poses(a, b) -> np.ndarray:
    """Wire-form composition ``a * b`` (apply ``b`` first). ``a, b: (..., 7)``."""
    a = as_finite(a, (7,), "pose")
    b = as_finite(b, (7,), "pose")
    rot_a = quat_to_matrix(a[..., 3:])
    pos = np.einsum("...ij,...j->...i", rot_a, b[..., :3]) + a[..., :3]
    q = quat_multiply(normalize_quaternion(a[..., 3:]), normalize_quaternion(b[..., 3:]))
    return np.concatenate([pos, q], axis=-1)


def invert_pose(p) -> np.ndarray:
    """Wire-form inverse. ``p: (..., 7)``."""
    p = as_finite(p, (7,), "pose")
    qi = quat_conjugate(normalize_quaternion(p[..., 3:]))
    pos = -np.einsum("...ij,...j->...i", quat_to_matrix(qi), p[..., :3])
    return np.concatenate([pos, qi], axis=-1)


def poses_to_matrices(p) -> np.ndarray:
    """Wire-form poses ``(..., 7)`` to homogeneous matrices ``(..., 4, 4)``."""
    p = as_finite(p, (7,), "pose")
    m = np.zeros(p.shape[:-1] + (4, 4))
    m[..., :3, :3] = quat_to_matrix(p[..., 3:])
    m[..., :3, 3] = p[..., :3]
    m[..., 3, 3] = 1.0
    return m


def matrices_to_poses(m) -> np.ndarray:
    """Homogeneous matrices ``(..., 4, 4)`` to wire-form poses ``(..., 7)``."""
    m = as_finite(m, (4, 4), "pose matrix")
    return np.concatenate([m[..., :3, 3], matrix_to_quat(m[..., :3, :3])], axis=-1)


def _fix_sign(axis: np.ndarray, centred: np.ndarray, tol: float, abs_tol: float) -> np.ndarray:
    """Flip ``axis`` so the centred points' third moment along it is positive.

    Symmetric sets (third moment ~ 0) use the first point, in order, with a clearly non-zero
    projection: deterministic and computed from the points themselves. If every projection is
    below ``abs_tol`` (the points have no extent along ``axis``) the axis is kept as given.
    """
    proj = centred @ axis
    scale = float(np.abs(proj).max())
    if scale <= abs_tol:
        return axis
    m3 = float(np.mean((proj / scale) ** 3))
    if abs(m3) > tol:
        return axis if m3 > 0 else -axis
    idx = np.flatnonzero(np.abs(proj) > tol * scale)
    if idx.size:
        return axis if proj[idx[0]] > 0 else -axis
    return axis


def _first_component(centred: np.ndarray, basis: np.ndarray, min_norm: float) -> np.ndarray | None:
    """Unit direction of the first point (in order) whose component in span(``basis`` columns)
    is longer than ``min_norm``; None if there is none."""
    comp = centred @ basis
    norms = np.linalg.norm(comp, axis=1)
    idx = np.flatnonzero(norms > min_norm)
    if not idx.size:
        return None
    v = basis @ comp[idx[0]]
    return v / np.linalg.norm(v)


def _fixed_orthogonal(e1: np.ndarray) -> np.ndarray:
    """A unit vector orthogonal to ``e1`` by a fixed rule: the world axis least aligned with it
    (first of X, Y, Z on ties), orthogonalized. Used only when the points give no direction."""
    c = np.eye(3)[int(np.argmin(np.abs(e1)))]
    v = c - (c @ e1) * e1
    return v / np.linalg.norm(v)


def pca_frame(points, rel_tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Right-handed PCA frame of ``points: (n, 3)``.

    Returns ``(origin (3,), axes (3, 3))`` where ``origin`` is the mean, ``axes[:, k]`` is the
    k-th principal axis in descending eigenvalue order (so the smallest-variance axis is local
    Z), and ``axes = [e1, e2, e1 x e2]`` is always a proper rotation. Local coordinates of a
    point ``p`` are ``axes.T @ (p - origin)``.

    Determinism (all from the centred points, in order, so the frame moves with the points):

    - signs: e1, then e2, point so that the third moment of the projections is positive; if it
      vanishes (symmetric sets), so that the first point with a non-zero projection is positive;
    - eigenvalues equal within ``1e3 * rel_tol`` of the largest are a repeated eigenspace: inside
      it, the first axis is the direction of the first point with a non-zero component there,
      and (for a 3D eigenspace) the second is the first point's component orthogonal to it.

    Degenerate sets: coincident points (no extent) give the identity axes; for collinear points
    e1 is the line and e2 follows a fixed rule (the world axis least aligned with e1,
    orthogonalized), since the points do not define it.
    """
    pts = as_finite(points, (3,), "points")
    if pts.ndim != 2 or pts.shape[0] < 1:
        raise ValueError(f"points must have shape (n, 3) with n >= 1, got {pts.shape}")
    origin = pts.mean(axis=0)
    centred = pts - origin
    spread = float(np.sqrt(np.mean(np.sum(centred**2, axis=1))))
    # Below this the points have no extent (rounding of the mean alone is ~1e-16 * |origin|).
    floor = 1e-12 * max(1.0, float(np.abs(pts).max()))
    if spread <= floor:
        return origin, np.eye(3)
    min_norm = 1e-6 * spread

    evals, evecs = np.linalg.eigh(centred.T @ centred)
    order = np.argsort(-evals, kind="stable")
    evals, evecs = evals[order], evecs[:, order]
    tie = 1e3 * rel_tol * float(evals[0])
    e1, e2 = evecs[:, 0], evecs[:, 1]
    if evals[0] - evals[1] <= tie:
        # Repeated leading eigenvalues: the basis inside the eigenspace comes from the points.
        span = evecs[:, :2] if evals[1] - evals[2] > tie else np.eye(3)
        v = _first_component(centred, span, min_norm)
        e1 = v if v is not None else e1
        if span.shape[1] == 2:
            e2 = np.cross(evecs[:, 2], e1)
        else:
            rest = centred - np.outer(centred @ e1, e1)
            v = _first_component(rest, np.eye(3), min_norm)
            e2 = v if v is not None else _fixed_orthogonal(e1)
    elif evals[1] - evals[2] <= tie:
        # Repeated trailing eigenvalues (collinear sets included): e2 from the first point with a
        # component orthogonal to e1, else the fixed rule.
        rest = centred - np.outer(centred @ e1, e1)
        v = _first_component(rest, np.eye(3), min_norm)
        e2 = v if v is not None else _fixed_orthogonal(e1)
    e1 = _fix_sign(e1 / np.linalg.norm(e1), centred, 1e-6, min_norm)
    e2 = e2 - (e2 @ e1) * e1
    e2 = _fix_sign(e2 / np.linalg.norm(e2), centred, 1e-6, min_norm)
    axes = np.stack([e1, e2, np.cross(e1, e2)], axis=1)
    return origin, axes


def cube_rotations() -> np.ndarray:
    """The 24 proper rotations of the cube group, ``(24, 3, 3)``, in a fixed order.

    Order: permutations of the axes in ``itertools.permutations`` order, then sign patterns in
    ``itertools.product((1, -1), repeat=3)`` order, keeping determinant +1. The identity is first.
    """
    mats = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            for row, (col, s) in enumerate(zip(perm, signs, strict=True)):
                m[row, col] = s
            if np.linalg.det(m) > 0:
                mats.append(m)
    return np.stack(mats)
