"""CAD partial model: design parameters → a URDF with mesh files.

Meshes are made with trimesh; each link's mass properties are trimesh's for a watertight mesh at the
stated mass (density = mass / volume), so inertias follow the geometry. The URDF is written by yourdfpy.
Frames follow REP-103: x forward, y left, z up; ``base_link`` sits at the axle midpoint (the centre of
rotation, paper Fig. 3).
"""

from __future__ import annotations

import logging
import math
import os

import numpy as np
import trimesh
import yourdfpy
from yourdfpy import (
    Collision, Color, Cylinder, Geometry, Inertial, Joint, Link, Material, Mesh, Robot, Sphere, Visual,
)

from mjcf.design import RobotDesign
from mjcf.errors import MjcfError

log = logging.getLogger(__name__)

BASE_LINK = "base_link"
SENSOR_LINK = "sensor_bar"
WHEEL_JOINTS = ("left_wheel_joint", "right_wheel_joint")
CASTER_GEOMS = ("caster_front", "caster_rear")
REAR_CASTER_CLEARANCE = 0.001  # [m] the rear ball clears the floor at rest: 3-point support, it only stops wheelies


def _origin(xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)) -> np.ndarray:
    return trimesh.transformations.compose_matrix(angles=rpy, translate=xyz)


def mesh_inertial(mesh: trimesh.Trimesh, mass: float, name: str) -> Inertial:
    """URDF inertial of a watertight mesh at ``mass`` [kg] (density = mass / volume): about its centre of mass, in
    the link frame; ``name`` names the mesh in the error when it is not watertight."""
    if not mesh.is_watertight:
        raise MjcfError(f"mesh {name}: not watertight, so it has no volume to take mass properties from")
    mesh = mesh.copy()
    mesh.density = mass / mesh.volume
    return Inertial(origin=_origin(mesh.center_mass), mass=float(mesh.mass), inertia=np.array(mesh.moment_inertia))


def meshes(design: RobotDesign) -> dict[str, trimesh.Trimesh]:
    """The robot's meshes, each in its own link's frame."""
    p = design
    chassis = trimesh.creation.cylinder(radius=p.chassis_radius, height=p.chassis_thickness, sections=64)
    chassis.apply_translation([p.d, 0.0, 0.0])  # the puck's centre of mass is d ahead of the axle
    wheel = trimesh.creation.cylinder(radius=p.R, height=p.wheel_width, sections=64)
    wheel.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [1, 0, 0]))  # axis along y
    bar_depth = 0.012
    bar = trimesh.creation.box([bar_depth, p.sensor_bar_width, 0.0016])
    # strut from the chassis rim to the bar, on the bar's link frame (bar at the origin)
    rim_to_bar = p.S - (p.d + p.chassis_radius * 0.8)
    parts = [bar]
    if rim_to_bar > 0:
        strut_height = (p.R - p.sensor_height)
        strut = trimesh.creation.box([rim_to_bar, 0.02, 0.0016])
        strut.apply_translation([-rim_to_bar / 2, 0.0, strut_height])
        post = trimesh.creation.box([0.004, 0.02, strut_height])
        post.apply_translation([0.0, 0.0, strut_height / 2])
        parts += [strut, post]
    sensor_bar = trimesh.util.concatenate(parts)
    return {"chassis": chassis, "wheel": wheel, "sensor_bar": sensor_bar}


def robot_description(design: RobotDesign, mesh_dir: str = "meshes") -> Robot:
    """The URDF robot; mesh filenames are ``mesh_dir/<part>.stl`` relative to the URDF."""
    p = design
    parts = meshes(design)
    grey = Material(name="chassis_green", color=Color(np.array([0.1, 0.45, 0.25, 1.0])))
    black = Material(name="tyre_black", color=Color(np.array([0.08, 0.08, 0.08, 1.0])))
    pcb = Material(name="pcb_blue", color=Color(np.array([0.15, 0.2, 0.55, 1.0])))

    def mesh_visual(part: str, material: Material) -> Visual:
        return Visual(name=part, origin=_origin(), geometry=Geometry(mesh=Mesh(filename=f"{mesh_dir}/{part}.stl")), material=material)

    base = Link(
        name=BASE_LINK,
        inertial=mesh_inertial(parts["chassis"], p.m_c, "chassis"),
        visuals=[mesh_visual("chassis", grey)],
        collisions=[
            Collision(name="chassis", origin=_origin(), geometry=Geometry(mesh=Mesh(filename=f"{mesh_dir}/chassis.stl"))),
            Collision(
                name=CASTER_GEOMS[0],
                origin=_origin([p.caster_x, 0.0, p.caster_radius - p.R]),
                geometry=Geometry(sphere=Sphere(radius=p.caster_radius)),
            ),
            Collision(
                name=CASTER_GEOMS[1],
                origin=_origin([-p.caster_x, 0.0, p.caster_radius - p.R + REAR_CASTER_CLEARANCE]),
                geometry=Geometry(sphere=Sphere(radius=p.caster_radius)),
            ),
        ],
    )
    links = [base]
    joints = []
    for side, joint_name in zip((1.0, -1.0), WHEEL_JOINTS):
        link_name = joint_name.replace("_joint", "")
        links.append(
            Link(
                name=link_name,
                inertial=mesh_inertial(parts["wheel"], p.m_w, "wheel"),
                visuals=[mesh_visual("wheel", black)],
                collisions=[
                    Collision(
                        name=f"{link_name}_tyre",
                        origin=_origin(rpy=(math.pi / 2, 0.0, 0.0)),
                        geometry=Geometry(cylinder=Cylinder(radius=p.R, length=p.wheel_width)),
                    )
                ],
            )
        )
        joints.append(
            Joint(name=joint_name, type="continuous", parent=BASE_LINK, child=link_name,
                  origin=_origin([0.0, side * p.L, 0.0]), axis=np.array([0.0, 1.0, 0.0]))
        )
    # the sensor bar's mass is part of m_c: a visual-only link with no inertial
    links.append(Link(name=SENSOR_LINK, visuals=[mesh_visual("sensor_bar", pcb)]))
    joints.append(
        Joint(name="sensor_bar_joint", type="fixed", parent=BASE_LINK, child=SENSOR_LINK,
              origin=_origin([p.S, 0.0, p.sensor_height - p.R]))
    )
    return Robot(name="line_follower", links=links, joints=joints, materials=[grey, black, pcb])


def write_robot(design: RobotDesign, folder: str) -> str:
    """Write ``robot.urdf`` and ``meshes/*.stl`` into ``folder``; returns the URDF path.

    ``folder`` is a fresh private folder that the caller publishes whole (``lf_common.files.output_dir`` for a
    user's folder, ``lf_common.cache.cached_folder`` for the cache): nothing already there is replaced.
    """
    os.makedirs(os.path.join(folder, "meshes"))
    for part, mesh in meshes(design).items():
        mesh.export(os.path.join(folder, "meshes", f"{part}.stl"))
    yourdfpy.URDF(
        robot=robot_description(design), build_scene_graph=False, load_meshes=False,
        filename_handler=yourdfpy.filename_handler_null,
    ).write_xml_file(os.path.join(folder, "robot.urdf"))
    log.info("wrote robot URDF to %s", folder)
    return os.path.join(folder, "robot.urdf")
