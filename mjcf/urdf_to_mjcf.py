"""Any differential-drive robot description (URDF or xacro, :mod:`mjcf.robot_source`) → an MjSpec robot: the entry
point :func:`convert` and the writer of the robot's bodies, joints, geoms and inertials.

MuJoCo's own URDF import welds the root to the world, drops visuals and does not resolve ``package://``,
so the URDF is read with yourdfpy (:mod:`mjcf.urdf_parse`) and each link becomes a body built through
``mujoco.MjSpec``:

* the root link gets a free joint; massless dummy links (``base_footprint``) stay as massless bodies;
* continuous and revolute joints become hinges, prismatic joints slides, whatever their rpy/axis;
* the drive wheels are the joints named by the user, else by a diff-drive plugin in the description, else
  the two continuous joints across the robot that are not a caster's; a named ``fixed`` hub joint (Gazebo
  plugins drive such wheels) becomes a hinge about its wheel's axis (:mod:`mjcf.urdf_wheels`);
* visual geoms are kept but never collide and carry no mass (group 2); collisions are group 3; a link with
  visuals only gets collision geoms from them; meshes are resolved and converted by :mod:`mjcf.urdf_meshes`;
* an ``<inertial>`` is kept exactly (tensor rotated into the body frame); a link without one gets its mass and
  inertia from its URDF geometry at ``DEFAULT_DENSITY`` (computed by MuJoCo before any contact shape is changed,
  and then fixed), and the converter says so;
* the drive wheels' tyres are marked for tyre friction, the caster given contact priority (its rolling resistance:
  :mod:`mjcf.world`); the line array's place is :mod:`mjcf.urdf_sensor_mount`'s.
"""

from __future__ import annotations

import dataclasses
import logging
import os

import mujoco
import numpy as np

from mjcf.errors import MjcfError
from mjcf.robot_config import RobotConfig
from mjcf.urdf_meshes import MeshAssets, load_mesh
from mjcf.urdf_parse import UrdfTree, origin, pos_quat
from mjcf.urdf_sensor_mount import sensor_mount
from mjcf.urdf_wheels import casters, drive_wheels, ground_height, measure_wheels

log = logging.getLogger(__name__)

DEFAULT_DENSITY = 1000.0  # [kg/m³], MuJoCo's default; used only for links without <inertial>
VISUAL_GROUP, COLLISION_GROUP = 2, 3


@dataclasses.dataclass(frozen=True)
class RobotInfo:
    """What the converter learned about the robot; lengths in [m].

    Attributes:
      root_body: name of the free-floating root body.
      wheel_joints: (left, right) hinge names.
      wheel_directions: (left, right) ±1 so that positive joint speed × direction rolls forward.
      wheel_radius: R, from the tyre's collision geometry.
      half_track: L, half the distance between the wheels' contact planes' centres.
      axle_centre: (x, y, z) of the axle midpoint in the root frame.
      tyre_geoms: collision geoms of the two wheels.
      caster_geoms: collision geoms of the caster(s).
      sensor_body: body carrying the sensor array.
      sensor_pos: the array's centre in ``sensor_body``'s frame [m].
      sensor_quat: the array's orientation in ``sensor_body``'s frame: its x ahead and z down in the root frame.
      ground_height: root-frame height of the root origin above the floor when standing.
      mesh_files: mesh asset name → source file path (for saving).
      notes: what the converter inferred or changed, one line each.
    """

    root_body: str
    wheel_joints: tuple[str, str]
    wheel_directions: tuple[float, float]
    wheel_radius: float
    half_track: float
    axle_centre: tuple[float, float, float]
    tyre_geoms: tuple[str, ...]
    caster_geoms: tuple[str, ...]
    sensor_body: str
    sensor_pos: tuple[float, float, float]
    sensor_quat: tuple[float, float, float, float]
    ground_height: float
    mesh_files: dict
    notes: tuple[str, ...]


class _Writer:
    """Builds one robot's bodies, joints, geoms and inertials into ``spec`` from a :class:`UrdfTree`, names
    prefixed by ``prefix``."""

    def __init__(self, tree: UrdfTree, spec: mujoco.MjSpec, prefix: str):
        self.tree = tree
        self.path = tree.path
        self.spec = spec
        self.prefix = prefix
        self.meshes = MeshAssets(spec, tree.resolve, tree.path, prefix)
        self.geoms: dict[str, list[tuple[str, object]]] = {}  # link → [(geom name, urdf collision)]
        self.derived_inertia: list[str] = []  # links whose mass and inertia come from their geometry

    def name(self, s: str) -> str:
        return self.prefix + s

    def write(self) -> mujoco.MjsBody:
        """The root body, with a free joint, and everything below it."""
        body = self.spec.worldbody.add_body(name=self.name(self.tree.root))
        body.add_freejoint(name=self.name("root"))
        self._fill_body(body, self.tree.root, moving=True)
        return body

    def _fill_body(self, body: mujoco.MjsBody, link_name: str, moving: bool) -> None:
        tree = self.tree
        link = tree.links[link_name]
        self._inertial(body, link, moving)
        self.geoms[link_name] = []
        for i, vis in enumerate(link.visuals):
            self._geom(body, link_name, vis, f"{link_name}/visual{i}", visual=True)
        shapes = tree.shapes(link)  # (the visuals of a moving link that has no collisions)
        from_visuals = bool(shapes) and not link.collisions
        collisions = [(f"{link_name}/from_visual{i}" if from_visuals else
                       f"{link_name}/{c.name}" if c.name else f"{link_name}/collision{i}", c) for i, c in enumerate(shapes)]
        if from_visuals:
            tree.notes.append(f"link {link_name} moves but has visuals only: its visuals are its collision shape too")
            log.warning("%s: %s", self.path, tree.notes[-1])
        for i, (gname, col) in enumerate(collisions):
            if self.spec.geom(self.name(gname)) is not None:
                gname = f"{gname}{i}"
            self._geom(body, link_name, col, gname, visual=False)
            self.geoms[link_name].append((gname, col))
        for j in tree.children.get(link_name, []):
            pos, quat = pos_quat(origin(j))
            child = body.add_body(name=self.name(j.child), pos=pos, quat=quat)
            joint_moves = tree.joint_moves(j)
            if joint_moves:
                jt = mujoco.mjtJoint.mjJNT_SLIDE if j.type == "prismatic" else mujoco.mjtJoint.mjJNT_HINGE
                mj = child.add_joint(name=self.name(j.name), type=jt, axis=tree.axis(j))
                if j.type == "revolute" and j.limit is not None and j.limit.lower is not None and j.limit.upper is not None:
                    if j.limit.lower < j.limit.upper:
                        mj.limited = mujoco.mjtLimited.mjLIMITED_TRUE
                        mj.range = [j.limit.lower, j.limit.upper]
                if j.dynamics is not None:  # MuJoCo 4's damping is a polynomial [a, b, c]: URDF's is linear
                    mj.damping = [float(j.dynamics.damping or 0.0), 0.0, 0.0]
                    mj.frictionloss = float(j.dynamics.friction or 0.0)
            elif j.type != "fixed":
                raise MjcfError(f"{self.path}: joint {j.name} has unsupported type {j.type!r}")
            self._fill_body(child, j.child, moving=joint_moves)

    def _inertial(self, body: mujoco.MjsBody, link, moving: bool) -> None:
        inertial = link.inertial
        if inertial is not None and inertial.mass is not None:
            mass = float(inertial.mass)  # its numbers are checked where the description is read (urdf_numbers)
            if mass > 0:
                T = origin(inertial)
                I = np.asarray(inertial.inertia if inertial.inertia is not None else np.zeros((3, 3)), dtype=float)
                Rm = T[:3, :3]
                Ib = Rm @ I @ Rm.T  # URDF gives the tensor in the inertial frame; MuJoCo wants the body frame
                body.explicitinertial = True
                body.mass = mass
                body.ipos = T[:3, 3]
                body.fullinertia = [Ib[0, 0], Ib[1, 1], Ib[2, 2], Ib[0, 1], Ib[0, 2], Ib[1, 2]]
                return
        shapes = self.tree.shapes(link)
        if shapes:
            for col in shapes:
                if col.geometry is not None and col.geometry.mesh is not None:
                    source = self.tree.resolve(col.geometry.mesh.filename)
                    if os.path.isfile(source) and not load_mesh(source, self.path).is_watertight:
                        raise MjcfError(
                            f"{self.path}: link {link.name} has no <inertial> and its mesh "
                            f"{col.geometry.mesh.filename!r} is not watertight, so it has no volume to take inertia from; "
                            "add an <inertial> to the link"
                        )
            self.derived_inertia.append(link.name)
        elif moving and link.name != self.tree.root:
            raise MjcfError(f"{self.path}: link {link.name} moves on a joint but has no mass (no inertial, no geometry)")
        else:
            self.tree.notes.append(f"link {link.name} is massless (dummy frame)")

    def fix_derived_inertia(self) -> None:
        """Give each link without ``<inertial>`` the mass and inertia of its URDF geometry at DEFAULT_DENSITY,
        as MuJoCo computes them now, fixed before any contact shape is changed (a cylinder tyre is later
        simulated as an ellipsoid, which holds ⅔ of its volume)."""
        if not self.derived_inertia:
            return
        try:
            model = self.spec.compile()
        except ValueError as e:
            raise MjcfError(f"{self.path}: MuJoCo cannot compile the robot ({str(e).splitlines()[0]})") from None
        for link in self.derived_inertia:
            b = model.body(self.name(link))
            body = self.spec.body(self.name(link))
            body.explicitinertial = True
            body.mass = float(b.mass[0])
            body.ipos = b.ipos.copy()
            body.iquat = b.iquat.copy()
            body.inertia = b.inertia.copy()
            for g in self.geoms.get(link, []):
                self.spec.geom(self.name(g[0])).density = 0.0  # the mass is the body's now, whatever the shape
            self.tree.notes.append(f"link {link} has no <inertial>: {float(b.mass[0]):.4g} kg and its inertia from "
                                   f"its URDF geometry at {DEFAULT_DENSITY:g} kg/m³")
            log.warning("%s: %s", self.path, self.tree.notes[-1])

    def _geom(self, body: mujoco.MjsBody, link_name: str, el, gname: str, visual: bool) -> None:
        geo = el.geometry
        if geo is None:
            raise MjcfError(f"{self.path}: link {link_name} has a {'visual' if visual else 'collision'} without geometry")
        pos, quat = pos_quat(origin(el))
        g = body.add_geom(name=self.name(gname), pos=pos, quat=quat)
        if geo.box is not None:
            g.type = mujoco.mjtGeom.mjGEOM_BOX
            g.size = np.asarray(geo.box.size, dtype=float) / 2
        elif geo.cylinder is not None:
            g.type = mujoco.mjtGeom.mjGEOM_CYLINDER
            g.size = [geo.cylinder.radius, geo.cylinder.length / 2, 0.0]
        elif geo.sphere is not None:
            g.type = mujoco.mjtGeom.mjGEOM_SPHERE
            g.size = [geo.sphere.radius, 0.0, 0.0]
        elif geo.mesh is not None:
            g.type = mujoco.mjtGeom.mjGEOM_MESH
            g.meshname = self.meshes.add(link_name, geo.mesh)
        else:
            raise MjcfError(f"{self.path}: link {link_name} has an empty <geometry>")
        if visual:
            g.contype = g.conaffinity = 0
            g.group = VISUAL_GROUP
            g.density = 0.0  # visuals never add mass
            mat = el.material
            rgba = None
            if mat is not None and mat.color is not None:
                rgba = mat.color.rgba
            elif mat is not None and mat.name:
                named = {m.name: m for m in self.tree.robot.materials}.get(mat.name)
                rgba = named.color.rgba if named is not None and named.color is not None else None
            if rgba is not None:
                g.rgba = np.asarray(rgba, dtype=float)
        else:
            g.group = COLLISION_GROUP
            g.density = DEFAULT_DENSITY
            g.rgba = [0.5, 0.5, 0.5, 0.3]


def convert(
    path: str,
    config: RobotConfig = RobotConfig(),
    spec: mujoco.MjSpec | None = None,
    prefix: str = "",
) -> tuple[mujoco.MjSpec, RobotInfo]:
    """Add the description's robot to ``spec`` (a new one by default); returns the spec and what was learned.

    Raises:
      MjcfError: the description does not parse or expand, a mesh or package is missing, or the drive wheels
        cannot be identified.
    """
    spec = spec if spec is not None else mujoco.MjSpec()
    spec.compiler.degree = False  # everything here is in radians
    tree = UrdfTree(path, config)
    writer = _Writer(tree, spec, prefix)
    left, right = drive_wheels(tree)  # before the bodies are built: a fixed hub may become a hinge
    writer.write()
    writer.fix_derived_inertia()
    wheels = measure_wheels(tree, left, right)
    tyres = tuple(writer.name(g) for link in (left.child, right.child) for g, _ in writer.geoms[link])
    caster_geoms = casters(tree, writer.geoms)
    sensor, sensor_pos, sensor_quat = sensor_mount(tree, wheels.axle)
    height = ground_height(tree, writer.geoms, caster_geoms, wheels)
    info = RobotInfo(
        root_body=writer.name(tree.root),
        wheel_joints=(writer.name(left.name), writer.name(right.name)),
        wheel_directions=wheels.directions,
        wheel_radius=wheels.radius,
        half_track=wheels.half_track,
        axle_centre=tuple(float(v) for v in wheels.axle),
        tyre_geoms=tyres,
        caster_geoms=tuple(writer.name(g) for g in caster_geoms),
        sensor_body=writer.name(sensor),
        sensor_pos=tuple(float(v) for v in sensor_pos),
        sensor_quat=tuple(float(v) for v in sensor_quat),
        ground_height=height,
        mesh_files=dict(writer.meshes.files),
        notes=tuple(tree.notes),
    )
    for g in info.caster_geoms:
        # a ball caster rolls: no tangential friction here (mjcf.world gives it its rolling resistance). MuJoCo
        # takes the larger condim and friction of two geoms unless one has priority, so the caster has priority.
        spec.geom(g).condim = 1
        spec.geom(g).priority = 1
    return spec, info
