"""URDF → MJCF: the generated robot and a third-party-style URDF, save/reload, and bad input."""

import math
import re
import os
import subprocess
import sys

import mujoco
import numpy as np
import pytest
import yourdfpy

from conftest import minimal_urdf, yaw_of
from mjcf import MjcfError, RobotConfig, RobotDesign
from mjcf.cad import write_robot
from mjcf.urdf_to_mjcf import convert
from mjcf.world import MOTORS, save_xml
from twin.core.digital_twin import DigitalTwin


@pytest.mark.quick
def test_inertials_are_kept_exactly(tmp_path):
    path = write_robot(RobotDesign(), str(tmp_path / "robot"))
    spec, info = convert(path)
    model = spec.compile()
    urdf = yourdfpy.URDF.load(path, build_scene_graph=False, load_meshes=False)
    for link in urdf.robot.links:
        body = model.body(link.name)
        if link.inertial is None:
            assert body.mass[0] == 0.0
            continue
        assert body.mass[0] == pytest.approx(link.inertial.mass, rel=1e-12)
        eig = np.sort(np.linalg.eigvalsh(link.inertial.inertia))
        assert np.sort(body.inertia) == pytest.approx(eig, rel=1e-9)
        assert body.ipos == pytest.approx(link.inertial.origin[:3, 3], abs=1e-12)
    assert info.wheel_radius == pytest.approx(0.016)
    assert info.half_track == pytest.approx(RobotDesign().L)


@pytest.mark.quick
def test_saved_xml_reloads_with_same_masses_inertias_and_axes(tmp_path):
    twin = DigitalTwin(track="oval")
    model = twin.model()
    (tmp_path / "out").mkdir()
    out = save_xml(twin.spec(), str(tmp_path / "out" / "world.xml"))
    assert os.path.isfile(tmp_path / "out" / "world_assets" / os.path.basename(twin.spec().textures[0].file))
    reloaded = mujoco.MjModel.from_xml_path(out)
    assert reloaded.nbody == model.nbody
    np.testing.assert_allclose(reloaded.body_mass, model.body_mass, rtol=1e-6)
    np.testing.assert_allclose(reloaded.body_inertia, model.body_inertia, rtol=1e-5)  # MJCF text: 6 digits
    np.testing.assert_allclose(reloaded.jnt_axis, model.jnt_axis, atol=1e-12)
    np.testing.assert_array_equal(reloaded.tex_data, model.tex_data)


@pytest.mark.quick
def test_third_party_urdf_converts(third_party_urdf):
    spec, info = convert(third_party_urdf)
    model = spec.compile()
    assert info.root_body == "base_footprint"
    assert model.body("base_footprint").mass[0] == 0.0  # massless dummy root keeps its frame
    assert model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    assert info.wheel_joints == ("wheel_left_joint", "wheel_right_joint")
    assert info.wheel_directions == (1.0, -1.0)  # rpy −90° and +90° about x with axis z: ±y
    assert info.wheel_radius == pytest.approx(0.033) and info.half_track == pytest.approx(0.08)
    assert info.sensor_body == "line_sensor_link"
    assert set(info.caster_geoms) == {"caster_link/collision0", "caster_back_link/collision0"}
    assert any("caster_link has no <inertial>" in n for n in info.notes)
    # inertia from the 1 cm caster sphere at 1000 kg/m³
    assert model.body("caster_link").mass[0] == pytest.approx(1000 * 4 / 3 * math.pi * 0.01**3, rel=1e-6)
    for g in info.caster_geoms + info.tyre_geoms:
        assert model.geom(g).contype[0] == 1
    visuals = [i for i in range(model.ngeom) if model.geom_group[i] == 2]
    assert visuals and all(model.geom_contype[i] == 0 and model.geom_conaffinity[i] == 0 for i in visuals)


@pytest.mark.quick
def test_third_party_robot_drives_straight_on_equal_voltages(third_party_urdf):
    twin = DigitalTwin(track="oval", robot_urdf=third_party_urdf)
    model = twin.model()
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("start").id)
    yaw0, xy0 = yaw_of(data.qpos[3:7]), data.qpos[:2].copy()
    data.ctrl[[model.actuator(n).id for n in MOTORS]] = 3.0
    for _ in range(2000):
        mujoco.mj_step(model, data)
    travelled = data.qpos[:2] - xy0
    heading = np.array([math.cos(yaw0), math.sin(yaw0)])
    assert travelled @ heading > 0.5  # forward, metres in 2 s
    assert abs(travelled @ np.array([-heading[1], heading[0]])) < 1e-3  # lateral drift
    assert abs(yaw_of(data.qpos[3:7]) - yaw0) < math.radians(0.1)


@pytest.mark.quick
@pytest.mark.parametrize("text,match", [
    ("<robot name='x'><link name='a'></robot>", "not a well-formed URDF"),
    ("<robt name='x'/>", "expected <robot>"),
    (minimal_urdf(wheels=1), "cannot tell the two drive wheels .*--wheel-joints LEFT,RIGHT"),
    (minimal_urdf(extra="<link name='lost'/>"), "expected one root link"),
    (minimal_urdf(extra="<joint name='j' type='fixed'><parent link='base'/><child link='m'/></joint>"
                        "<link name='m'><visual><geometry><mesh filename='package://nope/m.stl'/></geometry></visual></link>"),
     "package://nope/m.stl: package 'nope' not found.*--package nope=DIR"),
    (minimal_urdf(extra="<joint name='j' type='continuous'><parent link='base'/><child link='m'/></joint><link name='m'/>"),
     "cannot tell the two drive wheels|has no mass"),
])
def test_bad_urdf_is_one_clear_error(tmp_path, text, match):
    path = tmp_path / "robot.urdf"
    path.write_text(text)
    with pytest.raises(MjcfError, match=match):
        convert(str(path))


@pytest.mark.quick
def test_named_wheels_must_exist(tmp_path):
    path = tmp_path / "robot.urdf"
    path.write_text(minimal_urdf())
    with pytest.raises(MjcfError, match="wheel joint 'nope'"):
        convert(str(path), RobotConfig(wheel_joints=("nope", "w1")))


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, timeout=300)


def test_convert_cli_writes_xml_that_reloads(third_party_urdf, tmp_path):
    out = tmp_path / "robot.xml"
    r = run_cli("mjcf", "convert", third_party_urdf, "-o", str(out), "--track", "oval")
    assert r.returncode == 0, r.stderr
    model = mujoco.MjModel.from_xml_path(str(out))
    assert model.nu == 2 and model.body("base_link").mass[0] == pytest.approx(0.8)


def test_convert_cli_bad_input_is_one_line_exit_2_and_writes_nothing(tmp_path):
    bad = tmp_path / "robot.urdf"
    bad.write_text("<robot name='x'><link name='a'></robot>")
    out = tmp_path / "out.xml"
    r = run_cli("mjcf", "convert", str(bad), "-o", str(out))
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "Traceback" not in r.stderr
    assert "robot.urdf" in r.stderr and "well-formed" in r.stderr
    assert not out.exists() and sorted(os.listdir(tmp_path)) == ["robot.urdf"]


@pytest.mark.parametrize("damping, friction", [(1e-6, 0.0), (0.0, 2e-5), (1e-6, 2e-5)])
def test_joint_dynamics_spin_a_free_wheel_down_as_the_closed_form_says(tmp_path, damping, friction):
    """A wheel on its hinge, base held, nothing to touch: I dω/dt = −(c ω + f sign ω), so from ω0 it runs down as
    ω(t) = (ω0 + f/c) e^(−c t / I) − f/c (c = 0: ω0 − f t / I) and stops for good at t* where that reaches 0.
    I = 2e-6 kg·m² is the wheel's izz in minimal_urdf (its axis is the link's z); MuJoCo's implicit damping and soft
    friction-loss constraint stay within 0.1 % of ω0 of it (measured: 0.08 % around the stop, 0.03 % before)."""
    c, f, inertia, w0 = damping, friction, 2e-6, 50.0
    path = tmp_path / "robot.urdf"
    path.write_text(minimal_urdf().replace('<axis xyz="0 0 1"/></joint>',
                                           f'<axis xyz="0 0 1"/><dynamics damping="{c}" friction="{f}"/></joint>'))
    spec, info = convert(str(path))
    spec.delete(spec.joint("root"))  # the base welded to the world: the wheel is a body on a hinge
    model = spec.compile()
    data = mujoco.MjData(model)
    dof = model.joint(info.wheel_joints[0]).dofadr[0]
    data.qvel[dof] = w0
    t, w = [], []
    while data.time < 4.0:
        mujoco.mj_step(model, data)
        t.append(data.time)
        w.append(data.qvel[dof])
    t = np.array(t)
    if c > 0:
        exact = (w0 + f / c) * np.exp(-c * t / inertia) - f / c
        t_stop = inertia / c * math.log1p(c * w0 / f) if f > 0 else math.inf
    else:
        exact = w0 - f * t / inertia
        t_stop = w0 * inertia / f
    exact = np.where(t < t_stop, exact, 0.0)
    np.testing.assert_allclose(w, exact, rtol=0, atol=1e-3 * w0)


def test_a_calibration_braked_by_the_wheel_joints_dynamics_names_them(tmp_path):
    """Wheel joints damped at 0.01 N·m·s/rad (plus 0.001 N·m friction loss) take 0.01 × ω + 0.001 N·m a wheel at the
    calibration turn's planned wheel speed ω = cal_duty × full_speed, more than the motor's stall torque: the lap fails
    its calibration and the reason names the joints' <dynamics> with that torque; without them the robot laps."""
    from twin.core.closed_loop import run_laps
    from twin.core.digital_twin import DigitalTwin

    damped = os.path.join(os.path.dirname(__file__), "damped_wheels.urdf")
    free = tmp_path / "free.urdf"
    free.write_text(re.sub(r"\s*<dynamics[^>]*/>", "", open(damped).read()))
    config = RobotConfig(sensor_mount=("base_link", (0.04, 0.0, -0.008)))
    twin = DigitalTwin(track="oval", robot_urdf=damped, robot_config=config)
    lap = run_laps(twin, [{}], keep_traces=False)[0]
    omega = twin.space.get("control.cal_duty") * twin.space.get("control.full_speed")
    assert not lap.completed and lap.failure == "calibration", lap.detail
    assert f"take {0.01 * omega + 0.001:.3g} N·m a wheel" in lap.detail and "<dynamics>" in lap.detail, lap.detail
    assert run_laps(DigitalTwin(track="oval", robot_urdf=str(free), robot_config=config), [{}], keep_traces=False)[0].completed
