"""CAD model: design parameters → URDF with meshes; mass properties from the meshes."""

import math
import os

import numpy as np
import pytest
import trimesh
import yourdfpy

from lf_common.files import output_dir
from mjcf import MjcfError, RobotDesign
from mjcf.cad import mesh_inertial, write_robot

pytestmark = pytest.mark.quick  # the whole module is in the quick tier (tests/test_tiers.py)


def test_urdf_has_stated_masses_and_geometric_inertias(tmp_path):
    design = RobotDesign()
    urdf = yourdfpy.URDF.load(write_robot(design, str(tmp_path / "robot")), build_scene_graph=False, load_meshes=False)
    links = {link.name: link for link in urdf.robot.links}
    assert links["base_link"].inertial.mass == pytest.approx(design.m_c)
    assert links["base_link"].inertial.origin[0, 3] == pytest.approx(design.d, abs=1e-9)  # COG d ahead of the axle
    wheel = links["left_wheel"].inertial
    assert wheel.mass == pytest.approx(design.m_w)
    # a solid cylinder: I_axis = m r²/2, I_across = m (3 r² + h²)/12; 64-gon mesh within 0.5 %
    r, h, m = design.R, design.wheel_width, design.m_w
    assert wheel.inertia[1, 1] == pytest.approx(m * r * r / 2, rel=0.005)
    assert wheel.inertia[0, 0] == pytest.approx(m * (3 * r * r + h * h) / 12, rel=0.005)
    joints = {j.name: j for j in urdf.robot.joints}
    assert joints["left_wheel_joint"].origin[1, 3] == pytest.approx(design.L)
    assert joints["sensor_bar_joint"].origin[0, 3] == pytest.approx(design.S)
    for part in ("chassis", "wheel", "sensor_bar"):
        assert os.path.isfile(tmp_path / "robot" / "meshes" / f"{part}.stl")


def test_rewriting_our_robot_folder_is_atomic_and_leaves_no_temporaries(tmp_path):
    for design in (RobotDesign(), RobotDesign(L=0.05)):  # the second replaces the first: it is ours
        with output_dir(str(tmp_path / "robot")) as tmp:
            write_robot(design, tmp)
    assert sorted(os.listdir(tmp_path)) == ["robot"]
    urdf = yourdfpy.URDF.load(str(tmp_path / "robot" / "robot.urdf"), build_scene_graph=False, load_meshes=False)
    assert {j.name: j for j in urdf.robot.joints}["left_wheel_joint"].origin[1, 3] == pytest.approx(0.05)


@pytest.mark.parametrize("field,value,match", [
    ("R", 0.0, "cad.R"), ("m_c", -0.1, "cad.m_c"), ("L", math.nan, "cad.L"),
    ("d", 0.05, "cad.d"), ("L", 0.01, "cad.L"),
])
def test_bad_design_is_refused_by_name(field, value, match):
    with pytest.raises(MjcfError, match=match):
        RobotDesign(**{field: value})


def test_non_watertight_mesh_has_no_inertia():
    box = trimesh.creation.box([0.1, 0.1, 0.1])
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-2])  # two triangles missing
    with pytest.raises(MjcfError, match="not watertight"):
        mesh_inertial(open_box, 0.1, "open_box")
    assert np.isfinite(mesh_inertial(box, 0.1, "box").inertia).all()
