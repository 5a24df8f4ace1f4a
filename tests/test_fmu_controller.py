"""A third-party controller FMU in the twin's loop (``lap --controller-fmu``): built here from C with the firmware's
control law, it drives the lap the firmware drives, bit for bit; variables map by name, by common spellings, or by
``--map``; a broken FMU or an incomplete mapping is one line and exit 2."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

pytest.importorskip("fmpy")

from fmu_helpers import broken_fmu, build_controller, controller_processes, have_compiler  # noqa: E402
from twin.cli import main as front_door  # noqa: E402
from twin.core import DigitalTwin, run_laps  # noqa: E402
from twin.errors import TwinError  # noqa: E402
from twin.fmi import ControllerFmu, run_controller_lap  # noqa: E402

pytestmark = pytest.mark.skipif(not have_compiler(), reason="the controller FMU is compiled from C (gcc)")
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="module")
def twin():
    return DigitalTwin()


@pytest.fixture(scope="module")
def lap(twin):
    """The firmware's own lap, its compute timed as an outside controller's is: one time (timing.compute) whatever
    path the control law takes (the firmware's own laps time each path as the MCU does: twin.model.timing)."""
    general_us = twin.space.get("timing.compute")
    return run_laps(twin, [{"timing.compute_centred": general_us, "timing.compute_lost": general_us}], seed=3)[0]


@pytest.fixture(scope="module")
def controllers(twin, tmp_path_factory):
    folder = tmp_path_factory.mktemp("controllers")
    return {
        "angle": build_controller(twin, str(folder / "angle.fmu")),
        "position": build_controller(twin, str(folder / "position.fmu"), position_input=True, speed_outputs=True),
        "aliases": build_controller(twin, str(folder / "aliases.fmu"), names=("e", "u_left", "u_right"), step=0.01),
        "odd": build_controller(twin, str(folder / "odd.fmu"), names=("x", "y1", "y2")),
    }


def controller(twin, path, mapping=None) -> ControllerFmu:
    return ControllerFmu(path, mapping, int(twin.space.get("sensor.count")), twin.space.get("control.dt"))


def test_the_firmware_as_a_controller_fmu_drives_the_firmwares_lap(twin, lap, controllers):
    c = controller(twin, controllers["angle"])
    assert c.sense == {"line_angle": "line_angle"} and c.actuation == "voltage" and c.sample_time == 0.005
    r = run_controller_lap(twin, c, seed=3)
    assert r.completed and r.lap_time_s == pytest.approx(lap.lap_time_s, rel=1e-12)
    assert r.energy_j == pytest.approx(lap.energy_j, rel=1e-12)
    assert r.calibration_min_us == lap.calibration_min_us and r.calibration_max_us == lap.calibration_max_us
    # the same trace, tick by tick: voltages, pose and the sensor side
    for name in ("u_left_v", "u_right_v", "x_m", "yaw_rad", "position", "e_rad"):
        n = min(len(r.trace.records), len(lap.trace.records))
        assert (r.trace.column(name)[:n] == lap.trace.column(name)[:n]).all(), name
    again = run_controller_lap(twin, c, seed=3)
    assert again.trace.records.tobytes() == r.trace.records.tobytes()  # same seed, bit for bit


def test_one_process_serves_a_controllers_laps_and_ends_with_close(twin, controllers):
    c = controller(twin, controllers["angle"])
    first = run_controller_lap(twin, c, seed=3, keep_trace=False)
    process = controller_processes(os.getpid())
    assert len(process) == 1  # the FMU runs in a process of its own
    again = run_controller_lap(twin, c, seed=3, keep_trace=False)
    assert controller_processes(os.getpid()) == process  # the same one, a fresh instance: the same lap
    assert (again.lap_time_s, again.energy_j) == (first.lap_time_s, first.energy_j)
    c.close()
    assert not controller_processes(os.getpid())


def test_position_in_and_wheel_speed_set_points_out(twin, lap, controllers):
    c = controller(twin, controllers["position"])
    assert c.sense == {"line_position": "line_position"} and c.actuation == "setpoint"
    r = run_controller_lap(twin, c, seed=3, keep_trace=False)
    assert r.completed and r.lap_time_s == pytest.approx(lap.lap_time_s, rel=1e-3)


def test_common_spellings_and_the_fmus_own_sample_time(twin, controllers):
    c = controller(twin, controllers["aliases"])
    assert c.sense == {"e": "line_angle"} and c.drive == {"voltage_left": "u_left", "voltage_right": "u_right"}
    assert c.sample_time == 0.01  # its DefaultExperiment's stepSize
    r = run_controller_lap(twin, c, keep_trace=True)
    assert r.completed
    ticks = r.trace.column("time_s")
    assert ticks[1] - ticks[0] == pytest.approx(0.01)


def test_an_incomplete_mapping_lists_the_fmus_variables(twin, controllers):
    with pytest.raises(TwinError) as e:
        controller(twin, controllers["odd"])
    text = str(e.value)
    assert "incomplete" in text and "its inputs: x; its outputs: y1, y2" in text and "--map" in text
    assert "\n" not in text
    c = controller(twin, controllers["odd"], {"x": "line_angle", "y1": "voltage_left", "y2": "voltage_right"})
    assert c.drive == {"voltage_left": "y1", "voltage_right": "y2"}
    with pytest.raises(TwinError, match="no input or output 'z'"):
        controller(twin, controllers["odd"], {"z": "line_angle"})
    with pytest.raises(TwinError, match="not a twin port for an FMU input"):
        controller(twin, controllers["odd"], {"x": "voltage_left"})


def run_cli(argv, capsys) -> tuple[int, str, str]:
    code = front_door.main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.parametrize("what, needle", [
    ("not-zip", "not an FMU (not a zip archive)"),
    ("no-binary", "no binary for this platform"),
    ("model-exchange", "Model Exchange only"),
    ("fmi1", "FMI 1.0 is not supported"),
])
@pytest.mark.quick
def test_a_broken_fmu_is_one_line(tmp_path, capsys, what, needle):
    path = broken_fmu(str(tmp_path / f"{what}.fmu"), what)
    code, out, err = run_cli(["lap", "--controller-fmu", path], capsys)
    assert code == 2 and err.startswith("error: --controller-fmu") and err.count("\n") == 1 and needle in err, err


@pytest.mark.quick
def test_the_library_refuses_an_fmi_1_controller(tmp_path):
    path = broken_fmu(str(tmp_path / "old.fmu"), "fmi1")
    with pytest.raises(TwinError, match="FMI 1.0 is not supported"):
        ControllerFmu(path)


@pytest.mark.parametrize("argv, needle", [
    (["--map", "x=line_angle"], "--map: maps the variables of a --controller-fmu"),
    (["--controller-fmu", "{odd}", "--map", "x"], "expected FMU_VARIABLE=[-][SCALE*]TWIN_PORT"),
    (["--controller-fmu", "{odd}"], "its inputs: x; its outputs: y1, y2"),
    (["--controller-fmu", "{angle}", "--firmware", "avr"], "leave out --firmware"),
    (["--controller-fmu", "missing.fmu"], "no such file"),
])
def test_bad_controller_options_are_one_line(controllers, capsys, argv, needle):
    argv = [a.format(**controllers) for a in argv]
    code, out, err = run_cli(["lap", *argv], capsys)
    assert code == 2 and err.count("\n") == 1 and needle in err, err


def test_lap_with_a_controller_fmu_on_the_command_line(controllers, lap):
    done = subprocess.run([sys.executable, "-m", "twin.run", "lap", "--controller-fmu", controllers["odd"], "--map",
                           "x=line_angle", "--map", "y1=voltage_left", "--map", "y2=voltage_right", "--seed", "3",
                           "--json"], capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert done.returncode == 0, done.stderr
    doc = json.loads(done.stdout)
    assert doc["completed"] and doc["lap_time_s"] == pytest.approx(lap.lap_time_s, rel=1e-12)
    assert doc["controller"]["inputs"] == {"x": "line_angle"} and doc["controller"]["actuation"] == "voltage"
    assert doc["controller"]["outputs"] == {"y1": "voltage_left", "y2": "voltage_right"}
