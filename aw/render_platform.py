"""Choice of the offscreen OpenGL platform (EGL or OSMesa) for :mod:`aw.render`.

PyOpenGL binds every GL function to one platform when ``OpenGL`` is first imported, so the
choice must be made before that and cannot change afterwards in the same process:

- ``PYOPENGL_PLATFORM`` set to ``egl`` or ``osmesa``: respected as is.
- unset, OpenGL not imported yet: EGL if a child process can create an EGL context with
  pyrender, else OSMesa; the choice is written to ``PYOPENGL_PLATFORM``.
- unset, OpenGL already imported: whichever platform PyOpenGL picked, if it is EGL or OSMesa.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading

PLATFORMS = ("egl", "osmesa")
SYSTEM_PACKAGES = "libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1 libopengl0 libgl1 libosmesa6"

_lock = threading.Lock()
_chosen: str | None = None

# Creates and deletes one tiny EGL context, exactly as the renderer will.
_EGL_PROBE = """
import os
os.environ["PYOPENGL_PLATFORM"] = "egl"
import pyrender
r = pyrender.OffscreenRenderer(8, 8)
r.delete()
"""


class RenderError(RuntimeError):
    """Offscreen rendering is unavailable or failed; the message says what to install or set."""


def egl_available(timeout_s: float = 120.0) -> bool:
    """Whether a child process can create a pyrender EGL context (the environment is inherited)."""
    env = dict(os.environ, PYOPENGL_PLATFORM="egl")
    try:
        proc = subprocess.run(
            [sys.executable, "-c", _EGL_PROBE], env=env, capture_output=True, timeout=timeout_s, check=False
        )
    except (OSError, subprocess.TimeoutExpired):
        return False
    return proc.returncode == 0


def _platform_of_loaded_opengl() -> str | None:
    import OpenGL.platform  # already imported by someone else; this import is free

    name = type(getattr(OpenGL.platform, "PLATFORM", None)).__name__.lower()
    for p in PLATFORMS:
        if p in name:
            return p
    return None


def select_platform() -> str:
    """Return ``"egl"`` or ``"osmesa"`` and make sure ``PYOPENGL_PLATFORM`` says so."""
    global _chosen
    with _lock:
        env = os.environ.get("PYOPENGL_PLATFORM", "").strip().lower()
        if env:
            if env not in PLATFORMS:
                raise RenderError(
                    f"PYOPENGL_PLATFORM={env!r} is not supported for offscreen rendering; use 'egl' or 'osmesa'"
                )
            os.environ["PYOPENGL_PLATFORM"] = env
            _chosen = env
            return env
        if _chosen is not None:
            os.environ["PYOPENGL_PLATFORM"] = _chosen
            return _chosen
        if "OpenGL" in sys.modules:
            found = _platform_of_loaded_opengl()
            if found is None:
                raise RenderError(
                    "OpenGL was imported before aw.render chose an offscreen platform; set "
                    "PYOPENGL_PLATFORM=egl (or osmesa) before anything imports OpenGL"
                )
            choice = found
        else:
            choice = "egl" if egl_available() else "osmesa"
        os.environ["PYOPENGL_PLATFORM"] = choice
        _chosen = choice
        return choice
