"""Common model space: ports, relations, addresses, change costs, and the twin's rebuild rule."""

import json
import subprocess
import sys

import pytest

from line_sensor import SensorArray
from motors.actuator import read_fields
from twin import TwinError
from twin.core import DigitalTwin
from twin.model import ChangeCost
from twin.model.partial_models import default_space


@pytest.mark.quick
def test_every_parameter_has_one_address_and_a_unit():
    space = default_space()
    assert len(space.addresses) == len(set(space.addresses))
    for a in ("cad.L", "cad.R", "cad.S", "cad.m_c", "cad.m_w", "cad.d", "motion.mu", "motor.R_M", "motor.K"):
        assert a in space.addresses and space.parameter(a).unit


@pytest.mark.quick
def test_io_relations_are_derived_from_matching_ports():
    rel = {(r.source, r.port, r.target) for r in default_space().io_relations()}
    assert rel == {
        ("cad", "robot_description", "motion"),
        ("environment", "floor_texture", "motion"),
        ("environment", "floor_texture", "sensor"),
        ("motor", "wheel_torque", "motion"),
        ("motion", "wheel_speed", "motor"),
        ("motion", "pose", "sensor"),
        ("sensor", "sensor_readings", "control"),
        ("sensor", "sensor_readings", "timing"),  # the read lasts as long as the slowest line's reading
        ("control", "motor_command", "timing"),  # the firmware's command reaches the motors when the robot's
        ("timing", "motor_voltage", "motor"),    # timing says
        ("control", "motor_command", "power"),   # the duties and the motors' current load the supply, which
        ("motor", "motor_current", "power"),     # sags (or a regulator holds it), and the supply under load is
        ("power", "bus_voltage", "timing"),      # what duty 1 gives when the duties reach the motors
    }
    # the loop is closed: the only input from outside is the track itself
    assert default_space().unconnected_inputs() == [("environment", "track_definition")]


@pytest.mark.quick
def test_change_costs_follow_the_influences_relation():
    space = default_space()
    assert space.set("cad.L", 0.05) is ChangeCost.REBUILD
    assert space.set("motion.mu", 0.6) is ChangeCost.MODEL_FIELD
    assert space.set("motor.R_M", 5.0) is ChangeCost.MODEL_FIELD
    assert space.set("control.kp", 20.0) is ChangeCost.CONTROLLER
    assert space.set("sensor.noise", 0.0) is ChangeCost.CONTROLLER
    assert space.set("sensor.count", 6) is ChangeCost.REBUILD


@pytest.mark.quick
def test_integer_parameters_refuse_fractions():
    with pytest.raises(TwinError, match="sensor.count: must be a whole number"):
        default_space().set("sensor.count", 6.5)


@pytest.mark.quick
@pytest.mark.parametrize("address,value,match", [
    ("motion.muu", 0.5, "unknown parameter address; did you mean motion.mu"),
    ("motion.mu", float("nan"), "must be finite"),
    ("motion.mu", 5.0, "outside"),
    ("cad.m_c", 0.0, "must be > 0"),
    ("motor.K", "abc", "not a number"),
])
def test_bad_values_name_the_address(address, value, match):
    with pytest.raises(TwinError, match=match):
        default_space().set(address, value)


@pytest.mark.quick
def test_update_is_all_or_nothing():
    space = default_space()
    with pytest.raises(TwinError):
        space.update({"motion.mu": 0.5, "motor.R_M": -1})
    assert space.get("motion.mu") == 0.9


@pytest.mark.quick
def test_field_change_edits_the_model_and_cad_change_rebuilds_it():
    twin = DigitalTwin(track="oval")
    model = twin.model()
    twin.set("motion.mu", 0.55)
    twin.set("motor.R_M", 12.0)
    assert twin.model() is model and twin.rebuilds == 1
    assert model.geom(twin.info.tyre_geoms[0]).friction[0] == 0.55
    assert read_fields(model, model.actuator("left_motor").id).R_M == 12.0
    twin.set("cad.L", 0.055)
    rebuilt = twin.model()
    assert twin.rebuilds == 2 and rebuilt is not model
    assert twin.info.half_track == pytest.approx(0.055)
    assert rebuilt.geom(twin.info.tyre_geoms[0]).friction[0] == 0.55  # field values survive a rebuild


@pytest.mark.quick
def test_cad_parameters_do_not_apply_to_a_given_urdf(third_party_urdf):
    twin = DigitalTwin(robot_urdf=third_party_urdf)
    with pytest.raises(TwinError, match="of the CAD parameters only cad.S"):
        twin.set("cad.L", 0.05)


@pytest.mark.quick
def test_sensor_array_geometry_is_centred():
    offsets = SensorArray().lateral_offsets()
    assert offsets.sum() == pytest.approx(0.0, abs=1e-15)
    assert offsets[0] == pytest.approx(3.5 * 0.009525)  # sensor 0 on the left, as on a QTR-8


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "twin.run", *args], capture_output=True, text=True, timeout=120)


def test_graph_cli_exports_json():
    r = run_cli("graph", "--json", "--set", "motion.mu=0.6")
    assert r.returncode == 0, r.stderr
    data = json.loads(r.stdout)
    params = {p["address"]: p for m in data["models"] for p in m["parameters"]}
    assert params["motion.mu"]["value"] == 0.6 and params["cad.L"]["unit"] == "m"
    assert params["cad.L"]["change_cost"] == "rebuild"
    assert any({"kind": "influences", "source": "cad", "target": "motion"}.items() <= r.items() for r in data["relations"])


def test_graph_cli_text_lists_models_and_relations():
    r = run_cli("graph")
    assert r.returncode == 0
    assert "motion.mu = 0.9 -" in r.stdout and "cad --robot_description--> motion" in r.stdout


@pytest.mark.parametrize("setting", ["motion.mu=nan", "nope.x=1", "motion.mu"])
def test_graph_cli_bad_set_is_exit_2_one_line(setting):
    r = run_cli("graph", "--set", setting)
    assert r.returncode == 2
    assert r.stderr.startswith("error: ") and r.stderr.count("\n") == 1


def test_build_cli_builds_the_world_with_settings(tmp_path):
    out = tmp_path / "world.xml"
    r = run_cli("build", "--track", "oval", "--set", "cad.L=0.05", "--set", "motion.mu=0.7", "-o", str(out), "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["half_track_m"] == pytest.approx(0.05)
    assert summary["robot_mass_kg"] == pytest.approx(0.21)
    assert summary["parameters"]["motion.mu"] == 0.7
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(out))
    assert model.nu == 2 and model.na == 2


def test_build_cli_unknown_track_is_exit_2():
    r = run_cli("build", "--track", "nurburgring")
    assert r.returncode == 2 and "unknown track" in r.stderr and r.stderr.count("\n") == 1


def test_a_ratio_out_of_range_is_said_without_a_stray_unit_and_grid_examples_are_in_range():
    """A dimensionless parameter's unit is "-": messages give its value alone, never "got -1 -"; a grid's example
    values lie inside the parameter's range."""
    from twin.cli.options import parse_grid

    space = default_space()
    with pytest.raises(TwinError, match=r"motion\.mu: must be > 0, got -1$"):
        space.parameter("motion.mu").check("motion.mu", -1)
    with pytest.raises(TwinError) as e:
        parse_grid(["cad.L=abc"])
    example = str(e.value).rsplit("cad.L=", 1)[1]
    p = space.parameter("cad.L")
    assert all(p.lower <= float(v) <= p.upper for v in example.split(",")), str(e.value)


@pytest.mark.quick
def test_a_parameter_the_step_cannot_represent_is_named_not_identifiable():
    """motor.L_M: its lag L_M/R_M = 0.5 mH / 8.955 Ω = 55.8 µs (by hand) lies below the 1 ms step, so align refuses it,
    graph --learn leaves it out and diagnose skips it, each saying why; at a step below the lag it is offered again."""
    from tuner.align.diagnose import diagnose
    from tuner.align.lap_time import align_lap_time
    from tuner.search.space import TunerError
    from tuner.sensitivity.ranges import default_factors
    from twin.core.digital_twin import DigitalTwin
    from twin.model.identifiability import unresolved

    twin = DigitalTwin()
    why = unresolved(twin.space.values, "motor.L_M")
    assert "56 µs" in why and "1 ms physics step" in why
    with pytest.raises(TunerError, match="motor.L_M: not identifiable"):
        align_lap_time(twin, 13.0, "motor.L_M")
    factors, left_out = default_factors(twin.space)
    assert "motor.L_M" not in [f.address for f in factors] and "not identifiable" in left_out["motor.L_M"]
    report = diagnose(twin, 20.0, candidates=("motor.L_M",))
    assert not report.candidates and "not identifiable" in report.skipped[0]
    assert unresolved({**twin.space.values, "motion.timestep": 2.5e-5}, "motor.L_M") is None
