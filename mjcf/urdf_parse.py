"""Reading a robot description: the URDF parsed by yourdfpy, its links and joints checked to form one tree, each
link's frame in the root frame, the joints' axes, and the origins of its elements as positions and quaternions."""

from __future__ import annotations

import io
import logging

import mujoco
import numpy as np
import yourdfpy

from mjcf.errors import MjcfError
from mjcf.robot_config import RobotConfig
from mjcf.robot_source import Description, read_description
from mjcf.urdf_meshes import MeshResolver

MOVING_JOINTS = ("continuous", "revolute", "prismatic")


def origin(element) -> np.ndarray:
    """A URDF element's ``<origin>`` as a 4×4 transform; the identity when it has none."""
    return element.origin if element.origin is not None else np.eye(4)


def pos_quat(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position, quaternion w x y z) of a 4×4 transform."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(T[:3, :3]).ravel())
    return T[:3, 3].copy(), quat


def load_urdf(path: str, config: RobotConfig = RobotConfig()) -> tuple[yourdfpy.URDF, Description]:
    """The description at ``path`` (URDF or xacro) parsed, and what reading it found."""
    description = read_description(path, config.xacro_args, config.package_dirs)  # well-formed, <robot> root
    try:
        # yourdfpy logs a warning per unresolved file; we report missing meshes ourselves
        logging.getLogger("yourdfpy").setLevel(logging.ERROR)
        urdf = yourdfpy.URDF.load(io.BytesIO(description.xml), build_scene_graph=False, load_meshes=False,
                                  filename_handler=lambda f: f, mesh_dir=description.folder)
    except Exception as e:  # yourdfpy raises assorted errors for bad attributes
        raise MjcfError(f"{path}: invalid URDF ({e})") from None
    return urdf, description


class UrdfTree:
    """A robot description read as one tree of links, rooted at the link no joint has as its child.

    Attributes:
      path: the description's file, as given (errors name it).
      config: how the user described the robot (wheels, caster, sensor mount, xacro arguments, packages).
      robot: yourdfpy's robot (links, joints, materials).
      description: what reading the file found (:class:`mjcf.robot_source.Description`).
      resolve: URDF mesh filename → file.
      links, joints: by name.
      children: link name → the joints that have it as parent.
      root: the root link's name.
      link_T: link name → the link's 4×4 frame in the root frame.
      hub_axes: fixed joints made wheel hinges → unit axis in the child's frame.
      notes: what the converter inferred or changed, one line each (the description's own notes first).
    """

    def __init__(self, path: str, config: RobotConfig):
        self.path = path
        self.config = config
        urdf, self.description = load_urdf(path, config)
        self.notes: list[str] = list(self.description.notes)
        self.resolve = MeshResolver(self.description, config.package_dirs, self.notes)
        self.robot = urdf.robot
        self.links = {link.name: link for link in self.robot.links}
        self.joints = {j.name: j for j in self.robot.joints}
        self.children: dict[str, list] = {}
        self.parent_joint = {j.child: j for j in self.robot.joints}
        for j in self.robot.joints:
            if j.parent not in self.links or j.child not in self.links:
                raise MjcfError(f"{path}: joint {j.name} connects unknown link(s) {j.parent!r} → {j.child!r}")
            self.children.setdefault(j.parent, []).append(j)
        child_links = {j.child for j in self.robot.joints}
        roots = [name for name in self.links if name not in child_links]
        if len(roots) != 1:
            raise MjcfError(f"{path}: expected one root link, found {len(roots)} ({', '.join(roots) or 'a cycle'})")
        self.root = roots[0]
        self.link_T: dict[str, np.ndarray] = {self.root: np.eye(4)}
        self._kinematics(self.root)
        self.hub_axes: dict[str, np.ndarray] = {}

    def _kinematics(self, link_name: str) -> None:
        for j in self.children.get(link_name, []):
            if j.child in self.link_T:
                raise MjcfError(f"{self.path}: link {j.child} has more than one parent")
            self.link_T[j.child] = self.link_T[link_name] @ origin(j)
            self._kinematics(j.child)

    def joint_moves(self, joint) -> bool:
        """Whether a joint becomes a hinge or a slide: a moving URDF type, or a fixed hub made a wheel."""
        return joint.type in MOVING_JOINTS or joint.name in self.hub_axes

    def moves(self, link_name: str) -> bool:
        """Whether the link moves on a joint of its own (the root moves freely)."""
        j = self.parent_joint.get(link_name)
        return j is None or self.joint_moves(j)

    def shapes(self, link) -> list:
        """The link's collision elements; for a moving link with visuals only (it needs mass and, as a wheel,
        something to roll on), its visuals. A fixed visual-only link is a decoration: its parent carries it."""
        return list(link.collisions) or (list(link.visuals) if self.moves(link.name) else [])

    def axis(self, joint) -> np.ndarray:
        """A joint's unit axis in its child's frame (a hub made a hinge: its wheel's axis)."""
        if joint.name in self.hub_axes:
            return self.hub_axes[joint.name]
        axis = np.asarray(joint.axis if joint.axis is not None else [1.0, 0.0, 0.0], dtype=float)
        if np.linalg.norm(axis) == 0:  # finite and sane: checked where the description is read (urdf_numbers)
            raise MjcfError(f"{self.path}: joint {joint.name} has a zero axis")
        return axis / np.linalg.norm(axis)

    def joint_frame(self, joint) -> tuple[np.ndarray, np.ndarray]:
        """(anchor, unit axis) of a joint in the root frame."""
        T = self.link_T[joint.child]
        return T[:3, 3], T[:3, :3] @ self.axis(joint)
