"""The orbit camera that ``capture_scene`` renders from.

The camera looks at ``target`` from ``distance`` away, at azimuth ``yaw`` about world +Z and
elevation ``pitch`` (degrees). Its axes are ``right``, ``up`` and ``forward`` (forward points
from the camera into the scene); ``right = forward x Z`` normalized, ``up = right x forward``.
Image: 1024x768 pixels, 38 degree vertical field of view.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

IMAGE_WIDTH = 1024
IMAGE_HEIGHT = 768
VERTICAL_FOV_DEG = 38.0
PITCH_LIMIT_DEG = 85.0
DEFAULT_YAW_DEG = -60.0
DEFAULT_PITCH_DEG = 35.0


def wrap_degrees(angle: float) -> float:
    """Wrap to (-180, 180]."""
    a = (angle + 180.0) % 360.0 - 180.0
    return 180.0 if a == -180.0 else a


@dataclass
class Camera:
    target: np.ndarray = field(default_factory=lambda: np.zeros(3))
    yaw: float = DEFAULT_YAW_DEG
    pitch: float = DEFAULT_PITCH_DEG
    distance: float = 3.0

    def __post_init__(self) -> None:
        # Validate once here so that every derived axis is finite (pitch +-90 has no "right").
        try:
            target = np.array(self.target, dtype=np.float64).reshape(3)
            yaw, pitch, distance = float(self.yaw), float(self.pitch), float(self.distance)
        except (TypeError, ValueError):
            raise ValueError("camera needs a target of 3 numbers and numeric yaw, pitch, distance") from None
        if not (np.all(np.isfinite(target)) and np.isfinite([yaw, pitch, distance]).all()):
            raise ValueError("camera target, yaw, pitch and distance must be finite")
        if not abs(pitch) < 90.0:
            raise ValueError(f"camera pitch must lie strictly between -90 and 90 degrees, got {pitch:g}")
        if not distance > 0:
            raise ValueError(f"camera distance must be positive, got {distance:g}")
        self.target, self.yaw, self.pitch, self.distance = target, yaw, pitch, distance

    @classmethod
    def framing(cls, lo: np.ndarray, hi: np.ndarray, margin: float = 1.15) -> Camera:
        """Default view that fits the axis-aligned box ``[lo, hi]`` in the frame."""
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        centre = 0.5 * (lo + hi)
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-3)
        half_fov = np.radians(VERTICAL_FOV_DEG) / 2
        # The horizontal half-FOV is wider (4:3), so the vertical one bounds the fit.
        return cls(target=centre, distance=margin * radius / np.sin(half_fov))

    @property
    def forward(self) -> np.ndarray:
        y, p = np.radians(self.yaw), np.radians(self.pitch)
        # Camera sits at target - distance * forward.
        return -np.array([np.cos(p) * np.cos(y), np.cos(p) * np.sin(y), np.sin(p)])

    @property
    def right(self) -> np.ndarray:
        r = np.cross(self.forward, [0.0, 0.0, 1.0])
        return r / np.linalg.norm(r)

    @property
    def up(self) -> np.ndarray:
        return np.cross(self.right, self.forward)

    @property
    def position(self) -> np.ndarray:
        return self.target - self.distance * self.forward

    def axes(self) -> np.ndarray:
        """``(3, 3)`` with columns right, up, forward (world coordinates)."""
        return np.stack([self.right, self.up, self.forward], axis=1)

    def pose_matrix(self) -> np.ndarray:
        """4x4 camera-to-world matrix in the OpenGL convention (camera looks along its -Z)."""
        m = np.eye(4)
        m[:3, 0] = self.right
        m[:3, 1] = self.up
        m[:3, 2] = -self.forward
        m[:3, 3] = self.position
        return m

    def copy(self) -> Camera:
        return Camera(self.target.copy(), self.yaw, self.pitch, self.distance)

    def to_dict(self) -> dict:
        return {
            "target": [float(v) for v in self.target],
            "yaw": float(self.yaw),
            "pitch": float(self.pitch),
            "distance": float(self.distance),
        }

    def describe(self) -> dict:
        """State for agents: the dict form plus the derived position and axes."""
        d = self.to_dict()
        d.update(
            position=[float(v) for v in self.position],
            right=[float(v) for v in self.right],
            up=[float(v) for v in self.up],
            forward=[float(v) for v in self.forward],
            vertical_fov_deg=VERTICAL_FOV_DEG,
            image_size=[IMAGE_WIDTH, IMAGE_HEIGHT],
        )
        return d

    @classmethod
    def from_dict(cls, d: dict) -> Camera:
        return cls(np.asarray(d["target"], float), float(d["yaw"]), float(d["pitch"]), float(d["distance"]))
