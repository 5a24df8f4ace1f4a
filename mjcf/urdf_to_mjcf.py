"""Any differential-drive robot description (URDF or xacro, :mod:`mjcf.robot_source`) → an MjSpec robot.

MuJoCo's own URDF import welds the root to the world, drops visuals and does not resolve ``package://``,
so the URDF is read with yourdfpy and each link becomes a body built through ``mujoco.MjSpec``:

* the root link gets a free joint; massless dummy links (``base_footprint``) stay as massless bodies;
* continuous and revolute joints become hinges, prismatic joints slides, whatever their rpy/axis;
* the drive wheels are the joints named by the user, else by a diff-drive plugin in the description, else
  the two continuous joints across the robot that are not a caster's; a named ``fixed`` hub joint (Gazebo
  plugins drive such wheels) becomes a hinge about its wheel's axis;
* visual geoms are kept but never collide and carry no mass (group 2); collisions are group 3; a link with
  visuals only gets collision geoms from them;
* an ``<inertial>`` is kept exactly (tensor rotated into the body frame); a link without one gets its mass and
  inertia from its URDF geometry at ``DEFAULT_DENSITY`` (computed by MuJoCo before any contact shape is changed,
  and then fixed), and the converter says so;
* the drive wheels' tyres are marked for tyre friction, the caster made frictionless.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import logging
import math
import os
import re

import mujoco
import numpy as np
import trimesh
import yourdfpy

from lf_common.cache import cache_dir, cached_folder
from lf_common.errors import InputTooLarge
from mjcf.errors import MjcfError
from mjcf.robot_config import RobotConfig
from mjcf.robot_source import Description, find_package, read_description

log = logging.getLogger(__name__)

MAX_MESH_BYTES = 64_000_000  # a mesh file larger than this is a render model, not a collision shape
MAX_MESH_FACES = 500_000  # trimesh needs ~1.5 kB a face to load and check one (a 2.6M-face OBJ took 3.9 GB)
MIN_WHEEL_RADIUS, MAX_WHEEL_RADIUS = 0.002, 0.5  # [m] from a micro robot's to a service robot's
DEFAULT_DENSITY = 1000.0  # [kg/m³], MuJoCo's default; used only for links without <inertial>
VISUAL_GROUP, COLLISION_GROUP = 2, 3
MUJOCO_MESH_FORMATS = (".stl", ".obj", ".msh")
CASTER_BELOW_M = 0.002  # [m] a caster reaching further below the wheels' contact plane pitches the robot
SENSOR_DOWN = (0.0, 1.0, 0.0, 0.0)  # quaternion: half a turn about x, so a site's z axis (its ray) points down


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


def _pos_quat(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(T[:3, :3]).ravel())
    return T[:3, 3].copy(), quat


class _Resolver:
    """URDF mesh filename → file: relative to the description's folder, absolute, or ``package://NAME/…``
    through :func:`mjcf.robot_source.find_package` (the ``--package`` map, then the folders above)."""

    def __init__(self, description: Description, package_dirs: tuple[tuple[str, str], ...]):
        self.path = description.path
        self.folder = description.folder
        self.package_dirs = package_dirs

    def __call__(self, fname: str) -> str:
        m = re.match(r"package://([^/]+)/(.*)", fname)
        if m:
            folder = find_package(m.group(1), self.folder, self.package_dirs)
            if folder is None:
                raise MjcfError(f"{self.path}: {fname}: package {m.group(1)!r} not found beside the description or "
                                f"above it; give --package {m.group(1)}=DIR")
            return os.path.join(folder, m.group(2))
        if fname.startswith("file://"):
            fname = fname[len("file://") :]
        return fname if os.path.isabs(fname) else os.path.join(self.folder, fname)


def load_urdf(path: str, config: RobotConfig = RobotConfig()) -> tuple[yourdfpy.URDF, _Resolver, Description]:
    """The description at ``path`` (URDF or xacro) parsed, its mesh resolver, and what reading it found."""
    description = read_description(path, config.xacro_args, config.package_dirs)  # well-formed, <robot> root
    resolver = _Resolver(description, config.package_dirs)
    try:
        # yourdfpy logs a warning per unresolved file; we report missing meshes ourselves
        logging.getLogger("yourdfpy").setLevel(logging.ERROR)
        urdf = yourdfpy.URDF.load(io.BytesIO(description.xml), build_scene_graph=False, load_meshes=False,
                                  filename_handler=lambda f: f, mesh_dir=description.folder)
    except Exception as e:  # yourdfpy raises assorted errors for bad attributes
        raise MjcfError(f"{path}: invalid URDF ({e})") from None
    return urdf, resolver, description


class _Converter:
    def __init__(self, path: str, config: RobotConfig, spec: mujoco.MjSpec, prefix: str):
        self.path = path
        self.config = config
        self.spec = spec
        self.prefix = prefix
        self.urdf, self.resolve, self.description = load_urdf(path, config)
        self.robot = self.urdf.robot
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
        self.mesh_files: dict[str, str] = {}  # asset name → file MuJoCo reads
        self._mesh_keys: dict[str, tuple] = {}  # asset name → (URDF source file, scale), to share assets
        self.notes: list[str] = list(self.description.notes)
        self.link_T: dict[str, np.ndarray] = {self.root: np.eye(4)}  # link frame in the root frame
        self._kinematics(self.root)
        self.hub_axes: dict[str, np.ndarray] = {}  # fixed joints made wheel hinges → axis in the child's frame
        self.geoms: dict[str, list[tuple[str, object]]] = {}  # link → [(geom name, urdf collision)]
        self.derived_inertia: list[str] = []  # links whose mass and inertia come from their geometry

    def name(self, s: str) -> str:
        return self.prefix + s

    def _kinematics(self, link_name: str) -> None:
        for j in self.children.get(link_name, []):
            if j.child in self.link_T:
                raise MjcfError(f"{self.path}: link {j.child} has more than one parent")
            self.link_T[j.child] = self.link_T[link_name] @ (j.origin if j.origin is not None else np.eye(4))
            self._kinematics(j.child)

    def moves(self, link_name: str) -> bool:
        """Whether the link moves on a joint of its own (the root moves freely)."""
        j = self.parent_joint.get(link_name)
        return j is None or j.type in ("continuous", "revolute", "prismatic") or j.name in self.hub_axes

    def shapes(self, link) -> list:
        """The link's collision elements; for a moving link with visuals only (it needs mass and, as a wheel,
        something to roll on), its visuals. A fixed visual-only link is a decoration: its parent carries it."""
        return list(link.collisions) or (list(link.visuals) if self.moves(link.name) else [])

    def axis(self, joint) -> np.ndarray:
        """A joint's unit axis in its child's frame (a hub made a hinge: its wheel's axis)."""
        if joint.name in self.hub_axes:
            return self.hub_axes[joint.name]
        axis = np.asarray(joint.axis if joint.axis is not None else [1.0, 0.0, 0.0], dtype=float)
        if not np.all(np.isfinite(axis)) or np.linalg.norm(axis) == 0:
            raise MjcfError(f"{self.path}: joint {joint.name} has a zero or invalid axis")
        return axis / np.linalg.norm(axis)

    def make_hub_a_wheel(self, joint, why: str) -> None:
        """A ``fixed`` hub joint → a hinge about its wheel's own axis (a cylinder's, or a mesh's thinnest
        direction), turned so it points left (+y of the root)."""
        link = self.links[joint.child]
        axis = None
        for el in list(link.collisions) or list(link.visuals):
            T = el.origin if el.origin is not None else np.eye(4)
            if el.geometry.cylinder is not None:
                axis = T[:3, :3] @ np.array([0.0, 0.0, 1.0])
            elif el.geometry.mesh is not None:
                m = load_mesh(self.resolve(el.geometry.mesh.filename), self.path)
                v = m.vertices * (1.0 if el.geometry.mesh.scale is None else np.asarray(el.geometry.mesh.scale))
                extent = np.ptp(v, axis=0)
                axis = T[:3, :3] @ np.eye(3)[int(np.argmin(extent))]
            if axis is not None:
                break
        if axis is None:
            raise MjcfError(f"{self.path}: fixed joint {joint.name} is named as a wheel but link {link.name} has no "
                            "cylinder or mesh to take the wheel's axis from")
        if (self.link_T[joint.child][:3, :3] @ axis)[1] < 0:
            axis = -axis
        self.hub_axes[joint.name] = axis
        self.notes.append(f"fixed joint {joint.name} is a drive wheel ({why}): simulated as a hinge")
        log.info("%s: %s", self.path, self.notes[-1])

    def convert(self) -> mujoco.MjsBody:
        body = self.spec.worldbody.add_body(name=self.name(self.root))
        body.add_freejoint(name=self.name("root"))
        self._fill_body(body, self.root, moving=True)
        return body

    def _fill_body(self, body: mujoco.MjsBody, link_name: str, moving: bool) -> None:
        link = self.links[link_name]
        self._inertial(body, link, moving)
        self.geoms[link_name] = []
        for i, vis in enumerate(link.visuals):
            self._geom(body, link_name, vis, f"{link_name}/visual{i}", visual=True)
        shapes = self.shapes(link)  # (the visuals of a moving link that has no collisions)
        from_visuals = bool(shapes) and not link.collisions
        collisions = [(f"{link_name}/from_visual{i}" if from_visuals else
                       f"{link_name}/{c.name}" if c.name else f"{link_name}/collision{i}", c) for i, c in enumerate(shapes)]
        if from_visuals:
            self.notes.append(f"link {link_name} moves but has visuals only: its visuals are its collision shape too")
            log.warning("%s: %s", self.path, self.notes[-1])
        for i, (gname, col) in enumerate(collisions):
            if self.spec.geom(self.name(gname)) is not None:
                gname = f"{gname}{i}"
            self._geom(body, link_name, col, gname, visual=False)
            self.geoms[link_name].append((gname, col))
        for j in self.children.get(link_name, []):
            T = j.origin if j.origin is not None else np.eye(4)
            pos, quat = _pos_quat(T)
            child = body.add_body(name=self.name(j.child), pos=pos, quat=quat)
            joint_moves = j.type in ("continuous", "revolute", "prismatic") or j.name in self.hub_axes
            if joint_moves:
                jt = mujoco.mjtJoint.mjJNT_SLIDE if j.type == "prismatic" else mujoco.mjtJoint.mjJNT_HINGE
                mj = child.add_joint(name=self.name(j.name), type=jt, axis=self.axis(j))
                if j.type == "revolute" and j.limit is not None and j.limit.lower is not None and j.limit.upper is not None:
                    if j.limit.lower < j.limit.upper:
                        mj.limited = mujoco.mjtLimited.mjLIMITED_TRUE
                        mj.range = [j.limit.lower, j.limit.upper]
                if j.dynamics is not None:
                    mj.damping = float(j.dynamics.damping or 0.0)
                    mj.frictionloss = float(j.dynamics.friction or 0.0)
            elif j.type != "fixed":
                raise MjcfError(f"{self.path}: joint {j.name} has unsupported type {j.type!r}")
            self._fill_body(child, j.child, moving=joint_moves)

    def _inertial(self, body: mujoco.MjsBody, link, moving: bool) -> None:
        inertial = link.inertial
        if inertial is not None and inertial.mass is not None:
            mass = float(inertial.mass)
            if not math.isfinite(mass) or mass < 0:
                raise MjcfError(f"{self.path}: link {link.name} has invalid mass {inertial.mass!r}")
            if mass > 0:
                T = inertial.origin if inertial.origin is not None else np.eye(4)
                I = np.asarray(inertial.inertia if inertial.inertia is not None else np.zeros((3, 3)), dtype=float)
                if not np.all(np.isfinite(I)):
                    raise MjcfError(f"{self.path}: link {link.name} has a non-finite inertia")
                Rm = T[:3, :3]
                Ib = Rm @ I @ Rm.T  # URDF gives the tensor in the inertial frame; MuJoCo wants the body frame
                body.explicitinertial = True
                body.mass = mass
                body.ipos = T[:3, 3]
                body.fullinertia = [Ib[0, 0], Ib[1, 1], Ib[2, 2], Ib[0, 1], Ib[0, 2], Ib[1, 2]]
                return
        shapes = self.shapes(link)
        if shapes:
            for col in shapes:
                if col.geometry is not None and col.geometry.mesh is not None:
                    source = self.resolve(col.geometry.mesh.filename)
                    if os.path.isfile(source) and not load_mesh(source, self.path).is_watertight:
                        raise MjcfError(
                            f"{self.path}: link {link.name} has no <inertial> and its mesh "
                            f"{col.geometry.mesh.filename!r} is not watertight, so it has no volume to take inertia from; "
                            "add an <inertial> to the link"
                        )
            self.derived_inertia.append(link.name)
        elif moving and link.name != self.root:
            raise MjcfError(f"{self.path}: link {link.name} moves on a joint but has no mass (no inertial, no geometry)")
        else:
            self.notes.append(f"link {link.name} is massless (dummy frame)")

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
            self.notes.append(f"link {link} has no <inertial>: {float(b.mass[0]):.4g} kg and its inertia from its "
                              f"URDF geometry at {DEFAULT_DENSITY:g} kg/m³")
            log.warning("%s: %s", self.path, self.notes[-1])

    def _geom(self, body: mujoco.MjsBody, link_name: str, el, gname: str, visual: bool) -> None:
        geo = el.geometry
        if geo is None:
            raise MjcfError(f"{self.path}: link {link_name} has a {'visual' if visual else 'collision'} without geometry")
        T = el.origin if el.origin is not None else np.eye(4)
        pos, quat = _pos_quat(T)
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
            g.meshname = self._mesh(link_name, geo.mesh)
        else:
            raise MjcfError(f"{self.path}: link {link_name} has an empty <geometry>")
        if any(s < 0 or not math.isfinite(s) for s in np.asarray(g.size).ravel()) or (
            g.type != mujoco.mjtGeom.mjGEOM_MESH and g.size[0] <= 0
        ):
            raise MjcfError(f"{self.path}: link {link_name} has a geometry with a non-positive size")
        if visual:
            g.contype = g.conaffinity = 0
            g.group = VISUAL_GROUP
            g.density = 0.0  # visuals never add mass
            mat = el.material
            rgba = None
            if mat is not None and mat.color is not None:
                rgba = mat.color.rgba
            elif mat is not None and mat.name:
                named = {m.name: m for m in self.robot.materials}.get(mat.name)
                rgba = named.color.rgba if named is not None and named.color is not None else None
            if rgba is not None:
                g.rgba = np.asarray(rgba, dtype=float)
        else:
            g.group = COLLISION_GROUP
            g.density = DEFAULT_DENSITY
            g.rgba = [0.5, 0.5, 0.5, 0.3]

    def _mesh(self, link_name: str, mesh) -> str:
        source = self.resolve(mesh.filename)
        if not os.path.isfile(source):
            raise MjcfError(f"{self.path}: mesh {mesh.filename!r} of link {link_name} not found")
        scale = np.ones(3) if mesh.scale is None else np.broadcast_to(np.asarray(mesh.scale, dtype=float), (3,))
        key = (os.path.abspath(source), tuple(scale))
        for name, (src, sc) in self._mesh_keys.items():
            if (src, sc) == key:
                return name
        ext = os.path.splitext(source)[1].lower()
        if ext not in MUJOCO_MESH_FORMATS:
            source = _converted_mesh(source, self.path)  # e.g. COLLADA: MuJoCo reads STL/OBJ/MSH only
        else:
            load_mesh(source, self.path)  # the limits and a readable file, before MuJoCo reads it
        name = self.name(f"mesh{len(self._mesh_keys)}_{os.path.splitext(os.path.basename(source))[0]}")
        self.spec.add_mesh(name=name, file=source, scale=scale)
        self._mesh_keys[name] = key
        self.mesh_files[name] = source
        return name


def load_mesh(source: str, urdf: str) -> trimesh.Trimesh:
    """A mesh file as one trimesh, within the size limits; errors name the file and what to do."""
    try:
        size = os.path.getsize(source)
    except OSError as e:
        raise MjcfError(f"{urdf}: mesh {source}: cannot read it ({e.strerror or e})") from None
    if size > MAX_MESH_BYTES:
        raise InputTooLarge(f"{urdf}: mesh {source} is {size / 1e6:.0f} MB, more than the {MAX_MESH_BYTES / 1e6:g} MB "
                            f"limit; simplify it (e.g. decimate to under {MAX_MESH_FACES // 1000}k faces in Blender or "
                            "MeshLab): a collision shape needs far less")
    try:
        mesh = trimesh.load(source, force="mesh")
    except Exception as e:  # trimesh raises assorted errors for files it cannot parse
        raise MjcfError(f"{urdf}: mesh {source} is unreadable ({type(e).__name__})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MjcfError(f"{urdf}: mesh {source} holds no triangles")
    if len(mesh.faces) > MAX_MESH_FACES:
        raise InputTooLarge(f"{urdf}: mesh {source} has {len(mesh.faces)} faces, more than the {MAX_MESH_FACES} limit; "
                            "simplify it (decimate in Blender or MeshLab)")
    return mesh


def _converted_mesh(source: str, urdf: str) -> str:
    """A mesh MuJoCo cannot read (e.g. COLLADA), converted by trimesh to an STL in the verified cache, keyed by the
    source file's content."""
    mesh = load_mesh(source, urdf)
    with open(source, "rb") as f:
        digest = hashlib.sha256(f.read()).hexdigest()[:16]
    name = os.path.basename(source) + ".stl"  # keeps the source's name: assets are saved by file name
    folder = cached_folder(os.path.join(cache_dir(), "meshes", digest),
                           lambda tmp: mesh.export(os.path.join(tmp, name), file_type="stl"), "converted mesh")
    return os.path.join(folder, name)


def _joint_frame(conv: _Converter, joint) -> tuple[np.ndarray, np.ndarray]:
    """(anchor, unit axis) of a joint in the root frame."""
    T = conv.link_T[joint.child]
    return T[:3, 3], T[:3, :3] @ conv.axis(joint)


def _wheel_radius(conv: _Converter, joint) -> float:
    """Radius of the wheel's geometry about its joint axis."""
    link = conv.links[joint.child]
    shapes = conv.shapes(link)
    if not shapes:
        raise MjcfError(f"{conv.path}: wheel link {link.name} has no geometry to roll on")
    axis = conv.axis(joint)
    radii = []
    for col in shapes:
        geo = col.geometry
        T = col.origin if col.origin is not None else np.eye(4)
        if geo.sphere is not None:
            radii.append(geo.sphere.radius)
        elif geo.cylinder is not None:
            # the cylinder's own axis must be the joint axis for it to be a wheel
            if abs(abs(axis @ T[:3, 2]) - 1.0) > 1e-3:
                raise MjcfError(f"{conv.path}: wheel {link.name}'s cylinder is not aligned with joint {joint.name}'s axis")
            radii.append(geo.cylinder.radius)
        elif geo.mesh is not None:
            m = load_mesh(conv.resolve(geo.mesh.filename), conv.path)
            v = m.vertices * (1.0 if geo.mesh.scale is None else np.asarray(geo.mesh.scale))
            v = trimesh.transform_points(v, T)
            radii.append(float(np.max(np.linalg.norm(v - np.outer(v @ axis, axis), axis=1))))
        else:
            radii.append(float(np.linalg.norm(np.asarray(geo.box.size)[:2]) / 2))
    return max(radii)


def _is_caster_joint(conv: _Converter, joint) -> bool:
    names = (joint.name + " " + joint.child).lower()
    return any(word in names for word in ("caster", "castor", "swivel"))


def _drive_wheels(conv: _Converter) -> tuple:
    """(left, right) URDF joints of the drive wheels: named by the user, else by the description's diff-drive
    plugin, else the two continuous joints with horizontal axes that are not a caster's. Named fixed joints
    become hinges."""
    path, config = conv.path, conv.config
    if config.wheel_joints is not None:
        for n in config.wheel_joints:
            if n not in conv.joints:
                raise MjcfError(f"{path}: wheel joint {n!r} not in the URDF")
        named, why = list(config.wheel_joints), "named by --wheel-joints"
    elif conv.description.drive_joints is not None and all(n in conv.joints for n in conv.description.drive_joints):
        named, why = list(conv.description.drive_joints), "named by the description's diff-drive plugin"
    else:
        named = None
    if named is not None:
        if named[0] == named[1]:
            raise MjcfError(f"{path}: the two wheel joints are one joint, {named[0]!r}")
        for n in named:
            j = conv.joints[n]
            if j.type == "fixed":
                conv.make_hub_a_wheel(j, why)
            elif j.type not in ("continuous", "revolute"):
                raise MjcfError(f"{path}: wheel joint {n!r} is {j.type}, not a joint a wheel turns on")
        if config.wheel_joints is not None:
            return conv.joints[named[0]], conv.joints[named[1]]
        pair = named  # a plugin's left/right are checked by position like the auto-detected ones
    else:
        cont = [j for j in conv.robot.joints if j.type == "continuous"]
        cand = [j for j in cont if abs(_joint_frame(conv, j)[1][2]) < 0.1 and not _is_caster_joint(conv, j)]
        if len(cand) != 2:
            found = ", ".join(j.name for j in cont) or "none"
            raise MjcfError(f"{path}: cannot tell the two drive wheels (continuous joints: {found}); name their joints "
                            "with --wheel-joints LEFT,RIGHT (a fixed hub joint is turned into a wheel)")
        pair = [j.name for j in cand]
    pair = sorted(pair, key=lambda n: -_joint_frame(conv, conv.joints[n])[0][1])
    return conv.joints[pair[0]], conv.joints[pair[1]]


def _casters(conv: _Converter) -> list[str]:
    config, caster_key = conv.config, (conv.config.caster or "caster").lower()
    casters = []
    for link, geoms in conv.geoms.items():
        for g, col in geoms:
            name_hit = caster_key in link.lower() or caster_key in g.lower()
            if (config.caster is not None and (link == config.caster or (col.name or "") == config.caster)) or (
                config.caster is None and name_hit
            ):
                casters.append(g)
    if config.caster is not None and not casters:
        raise MjcfError(f"{conv.path}: caster {config.caster!r} is neither a link nor a collision name")
    if not casters:
        conv.notes.append("no caster found by name: the robot rests on its wheels and any other collision geometry")
    return casters


def _lowest_point(conv: _Converter, link: str, col) -> np.ndarray | None:
    """Root-frame lowest point of a caster's sphere (or a small box or cylinder), or None for other shapes."""
    T = conv.link_T[link] @ (col.origin if col.origin is not None else np.eye(4))
    geo = col.geometry
    if geo.sphere is not None:
        return T[:3, 3] - np.array([0.0, 0.0, geo.sphere.radius])
    if geo.cylinder is not None or geo.box is not None:
        half = (np.asarray(geo.box.size) / 2 if geo.box is not None
                else np.array([geo.cylinder.radius, geo.cylinder.radius, geo.cylinder.length / 2]))
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
        pts = (T[:3, :3] @ corners.T).T + T[:3, 3]
        return pts[np.argmin(pts[:, 2])]
    return None


def _sensor_mount(conv: _Converter, axle: np.ndarray) -> tuple[str, np.ndarray, np.ndarray]:
    """(link, position in the link's frame, quaternion in the link's frame) of the line array: ``--sensor-mount``,
    else a link named *sensor* (``--sensor-link``), else the root link's origin; moved to ``sensor_ahead`` ahead of
    the axle when that is set. The array's rays point down and its row runs along y, in the root frame."""
    config, path = conv.config, conv.path
    if config.sensor_mount is not None:
        link, offset = config.sensor_mount
        if link not in conv.links:
            raise MjcfError(f"{path}: sensor mount link {link!r} not in the URDF (links: {', '.join(sorted(conv.links))})")
        pos = np.asarray(offset, dtype=float)
    elif config.sensor_link is not None:
        if config.sensor_link not in conv.links:
            raise MjcfError(f"{path}: sensor link {config.sensor_link!r} not in the URDF")
        link, pos = config.sensor_link, np.zeros(3)
    else:
        named = [n for n in conv.links if "sensor" in n.lower() and ("line" in n.lower() or "ir" in n.lower()
                                                                    or "reflect" in n.lower() or "qtr" in n.lower())]
        named = named or [n for n in conv.links if "sensor" in n.lower()]
        link, pos = (named[0] if len(named) == 1 else conv.root), np.zeros(3)
        if link == conv.root:
            conv.notes.append("no sensor link found by name: the line array mounts on the root link's origin "
                              "(--sensor-mount LINK:X,Y,Z places it)")
    T = conv.link_T[link]
    if config.sensor_ahead is not None:  # S given: on the root, S ahead of the axle centre, at the mount's height
        at = T[:3, :3] @ pos + T[:3, 3]
        return conv.root, np.array([axle[0] + config.sensor_ahead, at[1], at[2]]), np.asarray(SENSOR_DOWN)
    # rays down in the root frame, whatever the link's orientation: q_link⁻¹ ⊗ q_down
    q_link = np.zeros(4)
    mujoco.mju_mat2Quat(q_link, np.ascontiguousarray(T[:3, :3]).ravel())
    q_inv, quat = np.zeros(4), np.zeros(4)
    mujoco.mju_negQuat(q_inv, q_link)
    mujoco.mju_mulQuat(quat, q_inv, np.asarray(SENSOR_DOWN))
    return link, pos, quat


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
    conv = _Converter(path, config, spec, prefix)
    left, right = _drive_wheels(conv)  # before the bodies are built: a fixed hub may become a hinge
    conv.convert()
    conv.fix_derived_inertia()

    # --- drive wheels
    (pl, al), (pr, ar) = _joint_frame(conv, left), _joint_frame(conv, right)
    if pl[1] <= pr[1]:
        raise MjcfError(f"{path}: wheel {left.name} is not left of {right.name} (REP-103: +y is left)")
    for j, a in ((left, al), (right, ar)):
        if abs(a[1]) < 0.99:
            raise MjcfError(f"{path}: wheel joint {j.name}'s axis {a.round(3)} is not across the robot (±y)")
    # positive rotation about +y rolls a wheel forward (+x) on the floor
    directions = (float(np.sign(al[1])), float(np.sign(ar[1])))
    radius_l, radius_r = _wheel_radius(conv, left), _wheel_radius(conv, right)
    if abs(radius_l - radius_r) > 1e-6:
        conv.notes.append(f"wheel radii differ: {radius_l:.5f} / {radius_r:.5f} m; using the mean")
    radius = (radius_l + radius_r) / 2
    if not MIN_WHEEL_RADIUS <= radius <= MAX_WHEEL_RADIUS:
        raise MjcfError(f"{path}: wheel radius {radius:.3g} m is not a wheel's for this twin (expected {MIN_WHEEL_RADIUS * 1000:g} mm "
                        f"to {MAX_WHEEL_RADIUS:g} m); check the wheels' collision geometry and the URDF's units (metres)")
    axle = (pl + pr) / 2

    # --- tyres, caster, sensor mount
    tyres = tuple(conv.name(g) for link in (left.child, right.child) for g, _ in conv.geoms[link])
    casters = _casters(conv)
    sensor, sensor_pos, sensor_quat = _sensor_mount(conv, axle)

    # --- standing height: lowest point of tyres and casters, root frame; a caster below the wheels pitches it
    contact_z = axle[2] - radius
    lows = [contact_z]
    for link, geoms in conv.geoms.items():
        for g, col in geoms:
            low = _lowest_point(conv, link, col) if g in casters else None
            if low is None:
                continue
            lows.append(low[2])
            below = contact_z - low[2]
            if below > CASTER_BELOW_M:
                pitch = math.degrees(math.atan2(below, max(abs(low[0] - axle[0]), 1e-9)))
                conv.notes.append(f"caster {g} reaches {below * 1000:.1f} mm below the wheels' contact: the robot stands "
                                  f"pitched by {pitch:.0f}° with its wheels lifted; check the caster's origin and the "
                                  "wheels' radius")
                log.warning("%s: %s", path, conv.notes[-1])
    info = RobotInfo(
        root_body=conv.name(conv.root),
        wheel_joints=(conv.name(left.name), conv.name(right.name)),
        wheel_directions=directions,
        wheel_radius=float(radius),
        half_track=float(abs(pl[1] - pr[1]) / 2),
        axle_centre=tuple(float(v) for v in axle),
        tyre_geoms=tyres,
        caster_geoms=tuple(conv.name(g) for g in casters),
        sensor_body=conv.name(sensor),
        sensor_pos=tuple(float(v) for v in sensor_pos),
        sensor_quat=tuple(float(v) for v in sensor_quat),
        ground_height=float(-min(lows)),
        mesh_files=dict(conv.mesh_files),
        notes=tuple(conv.notes),
    )
    for g in info.caster_geoms:
        # a ball caster rolls: no tangential friction. MuJoCo takes the larger condim of two geoms unless
        # one has priority, so the caster needs priority for its condim=1 to govern.
        spec.geom(g).condim = 1
        spec.geom(g).priority = 1
    return spec, info
