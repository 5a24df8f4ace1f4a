"""What the robot rolls and rests on: which joints drive it (``--wheel-joints``, else the diff-drive plugin its
description names (Gazebo or ros2_control), else the two continuous joints across the robot that are not a caster's),
a named ``fixed`` hub made a hinge, the wheels' radius and track, which collisions are casters, and how high the
robot stands on its wheels and casters."""

from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np
import trimesh

from mjcf.errors import MjcfError
from mjcf.urdf_meshes import scaled_vertices
from mjcf.urdf_parse import UrdfTree, origin

# the converter speaks through one logger, named for its entry point (the CLI prints the name)
log = logging.getLogger("mjcf.urdf_to_mjcf")

MIN_WHEEL_RADIUS, MAX_WHEEL_RADIUS = 0.002, 0.5  # [m] from a micro robot's to a service robot's
CASTER_BELOW_M = 0.002  # [m] a caster reaching further below the wheels' contact plane pitches the robot


@dataclasses.dataclass(frozen=True)
class Wheels:
    """The drive wheels as the twin sees them; lengths in [m], in the root frame.

    Attributes:
      directions: (left, right) ±1 so that positive joint speed × direction rolls forward.
      radius: R, the mean of the two wheels' radii.
      half_track: L, half the distance between the wheels' anchors across the robot.
      axle: (3,) the axle midpoint.
    """

    directions: tuple[float, float]
    radius: float
    half_track: float
    axle: np.ndarray


def make_hub_a_wheel(tree: UrdfTree, joint, why: str) -> None:
    """A ``fixed`` hub joint → a hinge about its wheel's own axis (a cylinder's, or a mesh's thinnest
    direction), turned so it points left (+y of the root)."""
    link = tree.links[joint.child]
    axis = None
    for el in list(link.collisions) or list(link.visuals):
        T = origin(el)
        if el.geometry.cylinder is not None:
            axis = T[:3, :3] @ np.array([0.0, 0.0, 1.0])
        elif el.geometry.mesh is not None:
            extent = np.ptp(scaled_vertices(el.geometry.mesh, tree.resolve, tree.path), axis=0)
            axis = T[:3, :3] @ np.eye(3)[int(np.argmin(extent))]
        if axis is not None:
            break
    if axis is None:
        raise MjcfError(f"{tree.path}: fixed joint {joint.name} is named as a wheel but link {link.name} has no "
                        "cylinder or mesh to take the wheel's axis from")
    if (tree.link_T[joint.child][:3, :3] @ axis)[1] < 0:
        axis = -axis
    tree.hub_axes[joint.name] = axis
    tree.notes.append(f"fixed joint {joint.name} is a drive wheel ({why}): simulated as a hinge")
    log.info("%s: %s", tree.path, tree.notes[-1])


def _is_caster_joint(joint) -> bool:
    names = (joint.name + " " + joint.child).lower()
    return any(word in names for word in ("caster", "castor", "swivel"))


def drive_wheels(tree: UrdfTree) -> tuple:
    """(left, right) URDF joints of the drive wheels: named by the user, else by the description's diff-drive
    plugin, else the two continuous joints with horizontal axes that are not a caster's. Named fixed joints
    become hinges; call this before any body is built."""
    path, config = tree.path, tree.config
    if config.wheel_joints is not None:
        for n in config.wheel_joints:
            if n not in tree.joints:
                raise MjcfError(f"{path}: wheel joint {n!r} not in the URDF")
        named, why = list(config.wheel_joints), "named by --wheel-joints"
    elif tree.description.drive_joints is not None and all(n in tree.joints for n in tree.description.drive_joints):
        named, why = list(tree.description.drive_joints), "named by the description's diff-drive plugin"
    else:
        named = None
    if named is not None:
        if named[0] == named[1]:
            raise MjcfError(f"{path}: the two wheel joints are one joint, {named[0]!r}")
        for n in named:
            j = tree.joints[n]
            if j.type == "fixed":
                make_hub_a_wheel(tree, j, why)
            elif j.type not in ("continuous", "revolute"):
                raise MjcfError(f"{path}: wheel joint {n!r} is {j.type}, not a joint a wheel turns on")
        if config.wheel_joints is not None:
            return tree.joints[named[0]], tree.joints[named[1]]
        pair = named  # a plugin's left/right are checked by position like the auto-detected ones
    else:
        cont = [j for j in tree.robot.joints if j.type == "continuous"]
        cand = [j for j in cont if abs(tree.joint_frame(j)[1][2]) < 0.1 and not _is_caster_joint(j)]
        if len(cand) != 2:
            found = ", ".join(j.name for j in cont) or "none"
            raise MjcfError(f"{path}: cannot tell the two drive wheels (continuous joints: {found}); name their joints "
                            "with --wheel-joints LEFT,RIGHT (a fixed hub joint is turned into a wheel)")
        pair = [j.name for j in cand]
    pair = sorted(pair, key=lambda n: -tree.joint_frame(tree.joints[n])[0][1])
    return tree.joints[pair[0]], tree.joints[pair[1]]


def wheel_radius(tree: UrdfTree, joint) -> float:
    """Radius of the wheel's geometry about its joint axis [m]."""
    link = tree.links[joint.child]
    shapes = tree.shapes(link)
    if not shapes:
        raise MjcfError(f"{tree.path}: wheel link {link.name} has no geometry to roll on")
    axis = tree.axis(joint)
    radii = []
    for col in shapes:
        geo = col.geometry
        T = origin(col)
        if geo.sphere is not None:
            radii.append(geo.sphere.radius)
        elif geo.cylinder is not None:
            # the cylinder's own axis must be the joint axis for it to be a wheel
            if abs(abs(axis @ T[:3, 2]) - 1.0) > 1e-3:
                raise MjcfError(f"{tree.path}: wheel {link.name}'s cylinder is not aligned with joint {joint.name}'s axis")
            radii.append(geo.cylinder.radius)
        elif geo.mesh is not None:
            v = trimesh.transform_points(scaled_vertices(geo.mesh, tree.resolve, tree.path), T)
            radii.append(float(np.max(np.linalg.norm(v - np.outer(v @ axis, axis), axis=1))))
        else:
            radii.append(float(np.linalg.norm(np.asarray(geo.box.size)[:2]) / 2))
    return max(radii)


def measure_wheels(tree: UrdfTree, left, right) -> Wheels:
    """The drive wheels' directions, radius, track and axle, checked: left of right (REP-103: +y is left), axes
    across the robot, a radius a wheel of this twin can have. Unequal radii are noted and averaged."""
    path = tree.path
    (pl, al), (pr, ar) = tree.joint_frame(left), tree.joint_frame(right)
    if pl[1] <= pr[1]:
        raise MjcfError(f"{path}: wheel {left.name} is not left of {right.name} (REP-103: +y is left)")
    for j, a in ((left, al), (right, ar)):
        if abs(a[1]) < 0.99:
            raise MjcfError(f"{path}: wheel joint {j.name}'s axis {a.round(3)} is not across the robot (±y)")
    # positive rotation about +y rolls a wheel forward (+x) on the floor
    directions = (float(np.sign(al[1])), float(np.sign(ar[1])))
    radius_l, radius_r = wheel_radius(tree, left), wheel_radius(tree, right)
    if abs(radius_l - radius_r) > 1e-6:
        tree.notes.append(f"wheel radii differ: {radius_l:.5f} / {radius_r:.5f} m; using the mean")
    radius = (radius_l + radius_r) / 2
    if not MIN_WHEEL_RADIUS <= radius <= MAX_WHEEL_RADIUS:
        raise MjcfError(f"{path}: wheel radius {radius:.3g} m is not a wheel's for this twin (expected {MIN_WHEEL_RADIUS * 1000:g} mm "
                        f"to {MAX_WHEEL_RADIUS:g} m); check the wheels' collision geometry and the URDF's units (metres)")
    return Wheels(directions=directions, radius=float(radius), half_track=float(abs(pl[1] - pr[1]) / 2),
                  axle=(pl + pr) / 2)


def casters(tree: UrdfTree, geoms: dict[str, list[tuple[str, object]]]) -> list[str]:
    """The caster(s) among ``geoms`` (link → [(geom name, URDF collision)]): ``--caster`` names a link or a
    collision, else every geom whose link or name holds *caster*."""
    config, caster_key = tree.config, (tree.config.caster or "caster").lower()
    found = []
    for link, link_geoms in geoms.items():
        for g, col in link_geoms:
            name_hit = caster_key in link.lower() or caster_key in g.lower()
            if (config.caster is not None and (link == config.caster or (col.name or "") == config.caster)) or (
                config.caster is None and name_hit
            ):
                found.append(g)
    if config.caster is not None and not found:
        raise MjcfError(f"{tree.path}: caster {config.caster!r} is neither a link nor a collision name")
    if not found:
        tree.notes.append("no caster found by name: the robot rests on its wheels and any other collision geometry")
    return found


def _lowest_point(tree: UrdfTree, link: str, col) -> np.ndarray | None:
    """Root-frame lowest point of a caster's sphere (or a small box or cylinder), or None for other shapes."""
    T = tree.link_T[link] @ origin(col)
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


def ground_height(tree: UrdfTree, geoms: dict[str, list[tuple[str, object]]], caster_geoms: list[str],
                  wheels: Wheels) -> float:
    """Height of the root origin above the floor when the robot stands: the lowest point of its tyres and casters
    in the root frame [m]. A caster reaching below the wheels' contact pitches the robot, and is noted."""
    axle = wheels.axle
    contact_z = axle[2] - wheels.radius
    lows = [contact_z]
    for link, link_geoms in geoms.items():
        for g, col in link_geoms:
            low = _lowest_point(tree, link, col) if g in caster_geoms else None
            if low is None:
                continue
            lows.append(low[2])
            below = contact_z - low[2]
            if below > CASTER_BELOW_M:
                pitch = math.degrees(math.atan2(below, max(abs(low[0] - axle[0]), 1e-9)))
                tree.notes.append(f"caster {g} reaches {below * 1000:.1f} mm below the wheels' contact: the robot "
                                  f"stands pitched by {pitch:.0f}° with its wheels lifted; check the caster's origin "
                                  "and the wheels' radius")
                log.warning("%s: %s", tree.path, tree.notes[-1])
    return float(-min(lows))
