"""A robot description in the common ROS styles, written by the tests themselves (no third-party files):
a ``*_description`` package with ``package.xml``, a ``.urdf.xacro`` that includes a macro file through
``$(find PKG)`` and takes a ``prefix`` argument, ``package://`` meshes, wheels on ``fixed`` hub joints driven
by a Gazebo diff-drive plugin, a caster on a swivel and an axle (continuous joints), a moving link with visuals
only, a link without ``<inertial>``, and no sensor link.
"""

from __future__ import annotations

import os

import numpy as np
import trimesh

PACKAGE = "lfbot_description"
WHEEL_RADIUS = 0.02  # [m]
WHEEL_WIDTH = 0.012  # [m]
WHEEL_Y = 0.05  # [m] half the wheel separation
CHASSIS_MASS = 0.30  # [kg]
CHASSIS_INERTIA = (4e-4, 5e-4, 8e-4)  # [kg m²] ixx, iyy, izz
AXLE_HEIGHT = WHEEL_RADIUS  # base_link sits on the axle
CASTER_X = 0.07  # [m] ahead of the axle
CASTER_WHEEL_RADIUS = 0.008  # [m]
SENSOR_MOUNT = "base_link:0.075,0,-0.016"  # the line array 4 mm above the floor, 75 mm ahead of the axle

WHEEL_MACRO = """\
<?xml version="1.0"?>
<robot xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:macro name="wheel" params="prefix side y">
    <joint name="${prefix}wheel_${side}_joint" type="fixed">
      <parent link="${prefix}base_link"/><child link="${prefix}wheel_${side}_link"/>
      <origin xyz="0 ${y} 0" rpy="${-pi/2} 0 0"/>
    </joint>
    <link name="${prefix}wheel_${side}_link">
      <visual><geometry><mesh filename="package://lfbot_description/meshes/wheel.stl"/></geometry></visual>
      <collision><geometry><cylinder radius="${wheel_radius}" length="${wheel_width}"/></geometry></collision>
    </link>
  </xacro:macro>
</robot>
"""

ROBOT = """\
<?xml version="1.0"?>
<robot name="lfbot" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:arg name="prefix" default=""/>
  <xacro:property name="prefix" value="$(arg prefix)"/>
  <xacro:property name="wheel_radius" value="{wheel_radius}"/>
  <xacro:property name="wheel_width" value="{wheel_width}"/>
  <xacro:include filename="$(find lfbot_description)/urdf/wheel.xacro"/>

  <link name="${{prefix}}base_footprint"/>
  <joint name="${{prefix}}base_joint" type="fixed">
    <parent link="${{prefix}}base_footprint"/><child link="${{prefix}}base_link"/>
    <origin xyz="0 0 {axle}"/>
  </joint>
  <link name="${{prefix}}base_link">
    <visual><origin xyz="0.02 0 0.01"/>
      <geometry><mesh filename="package://lfbot_description/meshes/chassis.stl"/></geometry></visual>
    <collision><origin xyz="0.02 0 0.01"/>
      <geometry><mesh filename="package://lfbot_description/meshes/chassis.stl"/></geometry></collision>
    <inertial><origin xyz="0.015 0 0.01"/><mass value="{mass}"/>
      <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/></inertial>
  </link>

  <xacro:wheel prefix="${{prefix}}" side="left" y="{wheel_y}"/>
  <xacro:wheel prefix="${{prefix}}" side="right" y="-{wheel_y}"/>

  <joint name="${{prefix}}caster_swivel_joint" type="continuous">
    <parent link="${{prefix}}base_link"/><child link="${{prefix}}caster_swivel_link"/>
    <origin xyz="{caster_x} 0 -0.004"/><axis xyz="0 0 1"/>
  </joint>
  <link name="${{prefix}}caster_swivel_link">
    <inertial><mass value="0.002"/><inertia ixx="1e-8" ixy="0" ixz="0" iyy="1e-8" iyz="0" izz="1e-8"/></inertial>
  </link>
  <joint name="${{prefix}}caster_swivel_hubcap_joint" type="continuous">
    <parent link="${{prefix}}caster_swivel_link"/><child link="${{prefix}}caster_wheel_link"/>
    <origin xyz="-0.004 0 {caster_drop}"/><axis xyz="0 1 0"/>
  </joint>
  <link name="${{prefix}}caster_wheel_link">
    <visual><geometry><sphere radius="{caster_r}"/></geometry></visual>
  </link>

  <joint name="${{prefix}}lidar_joint" type="fixed">
    <parent link="${{prefix}}base_link"/><child link="${{prefix}}lidar_link"/>
    <origin xyz="0 0 0.03"/>
  </joint>
  <link name="${{prefix}}lidar_link">
    <visual><geometry><cylinder radius="0.015" length="0.01"/></geometry></visual>
  </link>

  <gazebo>
    <plugin name="diff_drive" filename="libgazebo_ros_diff_drive.so">
      <left_joint>${{prefix}}wheel_left_joint</left_joint>
      <right_joint>${{prefix}}wheel_right_joint</right_joint>
      <wheel_separation>{separation}</wheel_separation>
    </plugin>
  </gazebo>
</robot>
"""


def write_package(root) -> str:
    """Write ``<root>/ws/src/lfbot/lfbot_description/`` (a colcon workspace layout); returns the xacro's path."""
    pkg = os.path.join(str(root), "ws", "src", "lfbot", PACKAGE)
    for sub in ("urdf", "meshes"):
        os.makedirs(os.path.join(pkg, sub), exist_ok=True)
    with open(os.path.join(pkg, "package.xml"), "w") as f:
        f.write(f'<?xml version="1.0"?>\n<package format="3"><name>{PACKAGE}</name><version>0.1.0</version></package>\n')
    with open(os.path.join(pkg, "urdf", "wheel.xacro"), "w") as f:
        f.write(WHEEL_MACRO)
    caster_drop = -(AXLE_HEIGHT - 0.004 - CASTER_WHEEL_RADIUS)  # the caster wheel touches the floor with the tyres
    with open(os.path.join(pkg, "urdf", "lfbot.urdf.xacro"), "w") as f:
        f.write(ROBOT.format(wheel_radius=WHEEL_RADIUS, wheel_width=WHEEL_WIDTH, axle=AXLE_HEIGHT, mass=CHASSIS_MASS,
                             ixx=CHASSIS_INERTIA[0], iyy=CHASSIS_INERTIA[1], izz=CHASSIS_INERTIA[2], wheel_y=WHEEL_Y,
                             caster_x=CASTER_X, caster_drop=f"{caster_drop:.6f}", caster_r=CASTER_WHEEL_RADIUS,
                             separation=2 * WHEEL_Y))
    chassis = trimesh.creation.box(extents=(0.14, 0.07, 0.012))
    chassis.export(os.path.join(pkg, "meshes", "chassis.stl"))
    wheel = trimesh.creation.cylinder(radius=WHEEL_RADIUS, height=WHEEL_WIDTH, sections=48)
    wheel.export(os.path.join(pkg, "meshes", "wheel.stl"))
    return os.path.join(pkg, "urdf", "lfbot.urdf.xacro")


def cylinder_mass(radius: float, length: float, density: float = 1000.0) -> float:
    """Hand value: a solid cylinder's mass [kg]."""
    return density * np.pi * radius**2 * length


def sphere_mass(radius: float, density: float = 1000.0) -> float:
    return density * 4.0 / 3.0 * np.pi * radius**3

