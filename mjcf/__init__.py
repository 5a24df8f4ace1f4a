"""CAD → simulation: the default parametric robot (URDF + meshes), URDF → MJCF through MjSpec, tracks,
and world assembly."""

from mjcf.design import RobotDesign
from mjcf.errors import MjcfError
from mjcf.robot_config import RobotConfig

__all__ = ["MjcfError", "RobotDesign", "RobotConfig"]
