"""Bring your own robot: a description in the common ROS styles (xacro, $(find), package:// meshes, fixed hubs
driven by a diff-drive plugin, a swivel caster, a visual-only moving link, links without <inertial>, no sensor
link), written by tests/ros_style.py, converts, mounts its line array, tunes and laps without an edit; each
way it can go wrong is one line naming the fix, exit 2. Hand values: masses of cylinders and spheres at the
stated density, the URDF's own numbers."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import mujoco
import numpy as np
import pytest

import ros_style as rs
from mjcf.errors import MjcfError
from mjcf.robot_config import RobotConfig
from mjcf.robot_source import read_description
from mjcf.ros_packages import find_package
from mjcf.urdf_to_mjcf import DEFAULT_DENSITY, convert
from twin.core.digital_twin import DigitalTwin
from twin.errors import TwinError

RUN = [sys.executable, "-m", "twin.run"]
MOUNT = rs.SENSOR_MOUNT.split(":")[0], tuple(float(v) for v in rs.SENSOR_MOUNT.split(":")[1].split(","))


@pytest.fixture
def xacro_path(tmp_path):
    return rs.write_package(tmp_path)


def run(*args, cwd=None, timeout=600):
    return subprocess.run([*RUN, *map(str, args)], capture_output=True, text=True, timeout=timeout, cwd=cwd)


def one_line_exit_2(r) -> str:
    assert r.returncode == 2, r.stderr
    errors = [line for line in r.stderr.strip().splitlines() if not line.startswith("WARNING ")]  # (the notes)
    assert len(errors) == 1 and errors[0].startswith("error: ") and "Traceback" not in r.stderr, r.stderr
    return errors[0]


# --- descriptions as published ----------------------------------------------------------------------------

@pytest.mark.quick
def test_xacro_expands_with_find_and_arguments(xacro_path):
    d = read_description(xacro_path, (("prefix", "lf_"),))
    assert b"lf_wheel_left_joint" in d.xml and b"${" not in d.xml and b"$(" not in d.xml
    assert d.drive_joints == ("lf_wheel_left_joint", "lf_wheel_right_joint")
    spec, info = convert(xacro_path, RobotConfig(xacro_args=(("prefix", "lf_"),)))
    assert info.wheel_joints == ("lf_wheel_left_joint", "lf_wheel_right_joint")


@pytest.mark.quick
def test_packages_are_found_above_the_description_or_named(tmp_path, xacro_path):
    pkg = os.path.dirname(os.path.dirname(xacro_path))
    assert find_package(rs.PACKAGE, os.path.dirname(xacro_path)) == pkg
    assert find_package(rs.PACKAGE, str(tmp_path / "ws")) == pkg  # a workspace's src/<repo>/<pkg>
    moved = tmp_path / "a" / "b" / "c" / "d" / "elsewhere"  # beyond the search's depth from the copy below
    moved.parent.mkdir(parents=True)
    shutil.move(pkg, moved)
    description = moved / "urdf" / "lfbot.urdf.xacro"
    lonely = tmp_path.joinpath("x1", "x2", "x3", "x4", "x5", "x6", "lonely")  # deeper than the search goes up
    lonely.mkdir(parents=True)
    shutil.copy(description, lonely / "robot.urdf.xacro")  # no package above it any more
    with pytest.raises(MjcfError, match=rf"\$\(find {rs.PACKAGE}\).*--package {rs.PACKAGE}=DIR"):
        read_description(str(lonely / "robot.urdf.xacro"))
    _, info = convert(str(lonely / "robot.urdf.xacro"), RobotConfig(package_dirs=((rs.PACKAGE, str(moved)),)))
    assert info.wheel_radius == pytest.approx(rs.WHEEL_RADIUS)


@pytest.mark.quick
def test_fixed_hubs_named_by_the_plugin_become_wheels(xacro_path):
    spec, info = convert(xacro_path)
    model = spec.compile()
    assert info.wheel_joints == ("wheel_left_joint", "wheel_right_joint")  # not the caster's swivel and axle
    for name in info.wheel_joints:
        j = model.joint(name)
        assert j.type[0] == mujoco.mjtJoint.mjJNT_HINGE
        assert abs(model.jnt_axis[j.id] @ [0, 0, 1]) == pytest.approx(1.0)  # the cylinder's axis, in the wheel's frame
    assert info.wheel_radius == pytest.approx(rs.WHEEL_RADIUS) and info.half_track == pytest.approx(rs.WHEEL_Y)
    assert any("fixed joint wheel_left_joint is a drive wheel" in n for n in info.notes)
    assert any("caster" in g for g in info.caster_geoms)


@pytest.mark.quick
def test_masses_and_inertias_are_the_urdfs_or_its_geometrys(xacro_path):
    spec, info = convert(xacro_path)
    model = spec.compile()
    base = model.body("base_link")
    assert base.mass[0] == pytest.approx(rs.CHASSIS_MASS, rel=1e-6)
    assert sorted(base.inertia) == pytest.approx(sorted(rs.CHASSIS_INERTIA), rel=1e-6)
    # no <inertial>: a solid cylinder of the URDF's size (not the ellipsoid the tyre contact is simulated with)
    wheel = model.body("wheel_left_link")
    m = rs.cylinder_mass(rs.WHEEL_RADIUS, rs.WHEEL_WIDTH, DEFAULT_DENSITY)
    assert wheel.mass[0] == pytest.approx(m, rel=1e-6)
    axial, radial = m * rs.WHEEL_RADIUS**2 / 2, m * (3 * rs.WHEEL_RADIUS**2 + rs.WHEEL_WIDTH**2) / 12
    assert sorted(wheel.inertia) == pytest.approx(sorted([radial, radial, axial]), rel=1e-6)
    # a moving link with visuals only: its collision and mass from its visual sphere
    caster = model.body("caster_wheel_link")
    assert caster.mass[0] == pytest.approx(rs.sphere_mass(rs.CASTER_WHEEL_RADIUS), rel=1e-6)
    assert any("caster_wheel_link moves but has visuals only" in n for n in info.notes)
    assert any("wheel_left_link has no <inertial>: 0.01508 kg" in n for n in info.notes)
    # a fixed visual-only decoration stays a decoration: no mass, no contact
    assert model.body("lidar_link").mass[0] == 0.0
    # and the same in the world the twin simulates, where the tyres have become ellipsoids
    twin = DigitalTwin(track="oval", robot_urdf=xacro_path, robot_config=RobotConfig(sensor_mount=MOUNT))
    assert twin.model().body("wheel_left_link").mass[0] == pytest.approx(m, rel=1e-6)


@pytest.mark.quick
def test_unexpanded_xacro_named_urdf_is_refused_with_the_fix(tmp_path):
    path = tmp_path / "robot.urdf"
    path.write_text('<robot name="r"><link name="${prefix}base"/></robot>')
    with pytest.raises(MjcfError, match=r"unexpanded xacro '\$\{prefix\}'.*\.xacro"):
        read_description(str(path))


@pytest.mark.quick
def test_named_fixed_hubs_without_a_plugin(tmp_path, xacro_path):
    xml = read_description(xacro_path).xml.decode()
    start, end = xml.index("<gazebo"), xml.index("</gazebo>") + len("</gazebo>")
    plain = tmp_path / "plain.urdf"
    plain.write_text(xml[:start] + xml[end:])
    with pytest.raises(MjcfError, match="cannot tell the two drive wheels .*--wheel-joints"):
        convert(str(plain), RobotConfig(package_dirs=((rs.PACKAGE, os.path.dirname(os.path.dirname(xacro_path))),)))
    _, info = convert(str(plain), RobotConfig(wheel_joints=("wheel_left_joint", "wheel_right_joint"),
                                              package_dirs=((rs.PACKAGE, os.path.dirname(os.path.dirname(xacro_path))),)))
    assert info.wheel_joints == ("wheel_left_joint", "wheel_right_joint")


@pytest.mark.quick
def test_a_caster_below_the_wheels_is_reported(tmp_path, xacro_path):
    text = open(xacro_path).read().replace('<origin xyz="{0} 0 -0.004"/>'.format(rs.CASTER_X),
                                           '<origin xyz="{0} 0 -0.024"/>'.format(rs.CASTER_X))
    assert text != open(xacro_path).read()
    low = os.path.join(os.path.dirname(xacro_path), "low.urdf.xacro")
    open(low, "w").write(text)
    _, info = convert(low)
    note = [n for n in info.notes if "below the wheels' contact" in n]
    assert note and "20.0 mm" in note[0]  # 2 cm lower than the version that touches the floor with the tyres


# --- the sensor mount --------------------------------------------------------------------------------------

@pytest.mark.quick
def test_sensor_mount_places_the_array_and_cad_s_moves_it(xacro_path):
    twin = DigitalTwin(track="oval", robot_urdf=xacro_path, robot_config=RobotConfig(sensor_mount=MOUNT))
    twin.model()
    assert twin.sensor_distance == pytest.approx(MOUNT[1][0], abs=1e-9)  # base_link's origin is on the axle
    assert twin.sensor_height() == pytest.approx(rs.AXLE_HEIGHT + MOUNT[1][2], abs=1e-6)
    twin.set("cad.S", 0.06)
    twin.model()
    assert twin.sensor_distance == pytest.approx(0.06, abs=1e-9)
    other = twin.clone()
    other.model()
    assert other.sensor_distance == pytest.approx(0.06, abs=1e-9)
    with pytest.raises(TwinError, match="only cad.S"):
        twin.set("cad.L", 0.05)


@pytest.mark.quick
def test_a_sensor_too_high_or_missing_names_the_fix(xacro_path):
    high = DigitalTwin(track="oval", robot_urdf=xacro_path, robot_config=RobotConfig(sensor_mount=("base_link", (0.075, 0, 0.13))))
    with pytest.raises(TwinError, match=r"150\.0 mm above the floor.*--sensor-mount LINK:X,Y,Z"):
        high.model()
    none = DigitalTwin(track="oval", robot_urdf=xacro_path)  # no sensor link: the root's origin, on the axle
    with pytest.raises(TwinError, match="ahead of the axle.*--sensor-mount"):
        none.model()


# --- the front door, as a new user would -------------------------------------------------------------------

def test_your_robot_in_five_minutes(tmp_path, xacro_path):
    """The README's steps: convert, tune, lap with the tuned gains, on the default track, no edit."""
    mount = ["--sensor-mount", rs.SENSOR_MOUNT]
    r = run("convert", xacro_path, "-o", tmp_path / "lfbot.xml", *mount, "--json")
    assert r.returncode == 0, r.stderr
    assert mujoco.MjModel.from_xml_path(json.loads(r.stdout)["xml"]).nu == 2
    r = run("tune", "--robot", xacro_path, *mount, "-q", "--held-out", "0", "-o", tmp_path / "g.json", "--json")
    assert r.returncode == 0, r.stderr
    tuned = json.loads(r.stdout)
    r = run("lap", "--robot", xacro_path, *mount, "--gains", tmp_path / "g.json", "--json")
    lap = json.loads(r.stdout)
    assert r.returncode == 0 and lap["completed"], r.stderr
    # tuning improved the lap: the start is the default gains' lap, the tuned gains' lap is faster, and the
    # written gains, raced again by lap, give the lap time tuning reported
    r = run("lap", "--robot", xacro_path, *mount, "--json")
    start = json.loads(r.stdout)
    assert r.returncode == 0 and start["completed"], r.stderr
    assert tuned["initial_lap_time_s"] == start["lap_time_s"]
    assert lap["lap_time_s"] == tuned["final_lap_time_s"] < tuned["initial_lap_time_s"]


@pytest.mark.parametrize("args,fix", [
    (["--sensor-mount", "base_link:0.075,0"], "expected LINK:X,Y,Z"),
    (["--sensor-mount", "nope:0.075,0,-0.016"], "sensor mount link 'nope' not in the URDF"),
    (["--sensor-mount", "base_link:0.075,0,0.13"], "--sensor-mount LINK:X,Y,Z"),
    (["--wheel-joints", "nope,wheel_right_joint"], "wheel joint 'nope' not in the URDF"),
    (["--package", "x=/no/such/dir"], "is not a folder"),
    (["--xacro-arg", "prefix"], "expected ADDRESS=VALUE|NAME=VALUE"),
])
def test_bad_robot_options_are_one_line_exit_2(xacro_path, args, fix):
    line = one_line_exit_2(run("lap", "--track", "oval", "--robot", xacro_path, *args))
    assert __import__("re").search(fix, line), line


def test_robot_options_without_a_robot_are_refused():
    line = one_line_exit_2(run("lap", "--track", "oval", "--sensor-mount", rs.SENSOR_MOUNT))
    assert "--robot" in line


# --- motors and gains for the robot -------------------------------------------------------------------------

@pytest.mark.quick
def test_motor_choice_by_hand():
    """The default motor fits the default robot (hand: 2·½·0.0324 N·m / 16 mm = 2.02 N against 0.21 kg·g = 2.06 N,
    0.98 g); a 10 kg robot on 33 mm wheels gets a sized motor with τ_stall = m·g·R = 3.236 N·m and 1 m/s."""
    from motors.catalogue import CATALOGUE
    from motors.choice import choose

    from motors.choice import push_g, top_speed

    assert push_g(CATALOGUE["pololu-mp-6v-30"], 0.21, 0.016, 6.0) == pytest.approx(0.98, abs=0.005)
    c = choose(CATALOGUE, 0.21, 0.016, 6.0)  # its own motor: 720 rpm × 16 mm = 1.206 m/s, the target itself
    assert c.name == "pololu-mp-6v-30"
    assert top_speed(c.datasheet, 0.016, 6.0) == pytest.approx(1.206, abs=1e-3)
    heavy = choose(CATALOGUE, 10.0, 0.033, 6.0)
    assert heavy.name == "sized"
    assert heavy.datasheet.stall_torque == pytest.approx(10.0 * 9.80665 * 0.033, rel=1e-12)
    assert heavy.datasheet.no_load_speed * 0.033 == pytest.approx(1.0, rel=1e-12)
    m = heavy.datasheet.constants()  # a motor the model space accepts
    DigitalTwin().space.update({"motor.R_M": m.R_M, "motor.K": m.K, "motor.b_M": m.b_M, "motor.gear": m.gear,
                                "motor.L_M": m.L_M, "motor.J_rotor": m.J_rotor, "motor.efficiency": m.efficiency,
                                "motor.friction": m.friction})


def test_a_heavy_robot_gets_a_motor_that_moves_it_and_says_so(tmp_path, third_party_urdf):
    r = run("lap", "--robot", third_party_urdf, "--track", "oval", "--json")
    assert r.returncode in (0, 1), r.stderr
    # hand: 100:1 HP, 17 kg·mm = 0.1667 N·m → 2·½·0.1667 / 0.033 m / (0.869 kg · g) = 0.59 g at 310 rpm × 33 mm =
    # 1.07 m/s; the 50:1 HP pushes only 0.30 g, the 100:1 MP 0.33 g
    assert "motor: pololu-hp-6v-100: the catalogue motor nearest 1.206 m/s that fits 0.869 kg on 33 mm wheels: " \
           "pushes 0.59 g" in r.stderr, r.stderr
    assert json.loads(r.stdout)["distance_m"] > 1.0  # it drives (the 3pi's motor barely moved it)


@pytest.mark.quick
def test_tuner_bounds_follow_the_robot(xacro_path):
    from tuner.search.space import DEFAULT_BOUNDS, robot_bounds

    twin = DigitalTwin(track="oval", robot_urdf=xacro_path, robot_config=RobotConfig(sensor_mount=MOUNT))
    b = robot_bounds(twin)
    v_top = twin.space.get("control.full_speed") * rs.WHEEL_RADIUS
    assert b["control.v_max"][1] == pytest.approx(DEFAULT_BOUNDS["control.v_max"][1] * v_top / 1.206)
    assert b["control.kp"][1] == pytest.approx(DEFAULT_BOUNDS["control.kp"][1] * v_top / 1.206 * 0.075 / 0.040)
    assert robot_bounds(DigitalTwin(track="oval")) == DEFAULT_BOUNDS


def test_unknown_motor_lists_the_catalogue(xacro_path):
    line = one_line_exit_2(run("lap", "--track", "oval", "--motor", "nope"))
    assert "not in the motor catalogue" in line and "pololu-mp-6v-30" in line


@pytest.mark.quick
@pytest.mark.parametrize("changes,cause", [
    ({"cad.sensor_height": 0.028}, "likely sensor height: 28.0 mm above the floor"),  # above the working range
    # hand: outer sensor 3.5 × 9.525 mm + half the 19 mm line at S = 40 mm: atan(0.04284 / 0.04) = 0.82 rad
    ({"control.cal_sweep": 0.25}, r"likely turn too short: .* ±0\.82 rad, the turn goes ±0\.25 rad"),
])
def test_calibration_failures_name_their_cause(changes, cause):
    from twin.core.closed_loop import run_laps

    twin = DigitalTwin(track="oval")
    twin.update(changes)
    r = run_laps(twin, [{}], seed=0)[0]
    assert r.failure == "calibration" and __import__("re").search(cause, r.detail), r.detail


def test_a_motor_too_weak_for_the_robot_is_named(third_party_urdf):
    r = run("lap", "--robot", third_party_urdf, "--motor", "pololu-mp-6v-30", "--track", "oval", "--json")
    d = json.loads(r.stdout)
    assert d["failure"] == "calibration" and "likely turn fell short of its plan" in d["detail"], d["detail"]
    assert "too weak" in d["detail"]


def test_a_fast_motor_that_cannot_get_up_to_speed_in_a_short_sweep_is_told_to_lengthen_it():
    """The 3pi+ Hyper's 15:1 motors: the default turn is planned for 220 rad/s wheels, 0.08 s a quarter sweep, too
    short to get up to speed; the named fix (a longer sweep) makes the lap."""
    r = run("lap", "--motor", "3pi+-hyper", "--track", "oval", "--json")
    d = json.loads(r.stdout)
    assert d["failure"] == "calibration" and "raise control.cal_sweep" in d["detail"], d["detail"]
    fixed = json.loads(run("lap", "--motor", "3pi+-hyper", "--track", "oval", "--set", "control.cal_sweep=2",
                           "--json").stdout)
    assert fixed["completed"], fixed["detail"]
