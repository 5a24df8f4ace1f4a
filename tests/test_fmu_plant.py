"""The plant FMU (voltages in; pose, wheel speeds, sensors, line position out) in fmpy: driven at equal voltages it
moves forward; in fmpy's own co-simulation master (its container FMU, C) with a controller FMU built here from C, it
completes a lap."""

from __future__ import annotations

import math

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")
from fmpy import simulate_fmu  # noqa: E402

from fmu_helpers import Slave, build_controller, container, have_compiler  # noqa: E402
from twin.core import DigitalTwin, run_laps  # noqa: E402
from twin.fmi import PLANT, export_fmu  # noqa: E402

pytestmark = pytest.mark.skipif(not have_compiler(), reason="exporting an FMU compiles its library (gcc)")


@pytest.fixture(scope="module")
def twin():
    return DigitalTwin()


@pytest.fixture(scope="module")
def plants(twin, tmp_path_factory):
    folder = tmp_path_factory.mktemp("plants")
    return {v: export_fmu(twin, str(folder / f"plant{v}.fmu"), PLANT, v).path for v in (2, 3)}


@pytest.mark.parametrize("version", [2, 3])
def test_equal_voltages_drive_it_forward(plants, twin, version):
    inputs = np.array([(0.0, 3.0, 3.0), (1.0, 3.0, 3.0)],
                      dtype=[("time", float), ("voltage_left", float), ("voltage_right", float)])
    r = simulate_fmu(plants[version], stop_time=0.5, output_interval=0.01, input=inputs,
                     output=["pose.x", "pose.y", "pose.theta", "wheel_speed_left", "wheel_speed_right",
                             "line_position", "line_seen", "sensor.calibrated[4]", "energy", "lap_distance"])
    start = twin.track.start_pose()
    heading = np.array([math.cos(start.yaw), math.sin(start.yaw)])
    moved = np.array([r["pose.x"][-1] - r["pose.x"][0], r["pose.y"][-1] - r["pose.y"][0]])
    assert moved @ heading > 0.15  # ~0.5 m/s after the motors spin up
    assert abs(heading[0] * moved[1] - heading[1] * moved[0]) < 1e-3 and abs(r["pose.theta"][-1] - start.yaw) < 1e-3  # straight on
    assert r["wheel_speed_left"][-1] > 10 and r["wheel_speed_left"][-1] == pytest.approx(r["wheel_speed_right"][-1])
    assert r["energy"][-1] > 0 and np.all(np.diff(r["energy"]) >= 0)
    assert r["lap_distance"][-1] == pytest.approx(moved @ heading, abs=0.01)  # the start line runs straight ahead
    # calibrated on the start line: the line under the middle of the array from the first output on
    assert r["line_seen"][0] and abs(r["line_position"][0] - 3500) < 500 and r["sensor.calibrated[4]"][0] > 500


def test_no_voltage_no_motion(plants):
    s = Slave(plants[2]).initialise()
    x0 = s.get("pose.x")
    s.run_until(0.2, 0.005)
    assert abs(s.get("pose.x") - x0) < 1e-4 and s.get("lap_status") == 0
    s.close()


@pytest.mark.parametrize("version", [2, 3])
def test_a_controller_fmu_drives_it_round_the_lap_in_fmpys_master(plants, twin, tmp_path, version):
    controller = build_controller(twin, str(tmp_path / "controller.fmu"))
    loop = container(plants[version], controller, str(tmp_path / "loop.fmu"), step=0.005, stop=16.0)
    r = simulate_fmu(loop, stop_time=16.0, output_interval=0.005)
    lap = run_laps(twin, [{}], keep_traces=False)[0]
    assert r["lap_status"][-1] == 1, r[-1]
    # the master passes each output on at the next communication point: one control period late, close to the lap
    assert r["lap_time"][-1] == pytest.approx(lap.lap_time_s, rel=0.02)
    assert r["lap_distance"][-1] == pytest.approx(twin.track.length_m)
