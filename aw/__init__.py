"""AssemblyWorld core: pose math, scene state, formats, task preparation, sources, rendering."""

from aw.camera import Camera
from aw.pose import Pose
from aw.scene import PartInfo, Scene, SceneError

__all__ = ["Camera", "PartInfo", "Pose", "Scene", "SceneError"]
__version__ = "0.1.0"
