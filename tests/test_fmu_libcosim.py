"""The plant FMU with a controller FMU in a second importer: libcosim (the Open Simulation Platform's co-simulation
library, C++, through its Python binding libcosimpy; FMI 2 only). Its fixed-step master passes each output on at
the next communication point, as a Jacobi master written here with fmpy does: the two give the same lap, bit for
bit, and it is the twin's own lap to within the one control period of delay."""

from __future__ import annotations

import pytest

pytest.importorskip("fmpy")
pytest.importorskip("libcosimpy")

from fmpy import read_model_description  # noqa: E402
from libcosimpy.CosimExecution import CosimExecution  # noqa: E402
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level  # noqa: E402
from libcosimpy.CosimObserver import CosimObserver  # noqa: E402
from libcosimpy.CosimSlave import CosimLocalSlave  # noqa: E402

from fmu_helpers import Slave, build_controller, have_compiler  # noqa: E402
from twin.core import DigitalTwin, run_laps  # noqa: E402
from twin.fmi import PLANT, export_fmu  # noqa: E402

pytestmark = pytest.mark.skipif(not have_compiler(), reason="the FMUs are compiled from C (gcc)")
STEP_S, LIMIT_S = 0.005, 16.0  # communication step and the simulated time allowed for the lap [s]
STEP_NS = 5_000_000  # libcosim counts time in ns
CHUNK = 100  # steps between looks at the lap's status


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    twin = DigitalTwin()
    d = tmp_path_factory.mktemp("pair")
    return twin, export_fmu(twin, str(d / "plant.fmu"), PLANT, 2).path, build_controller(twin, str(d / "ctl.fmu"))


def refs(path: str) -> dict[str, int]:
    return {v.name: v.valueReference for v in read_model_description(path).modelVariables}


def libcosim_lap(plant: str, controller: str) -> tuple[int, float, float]:
    """(lap_status, lap_time [s], lap_distance [m]) of the pair in libcosim's fixed-step master."""
    log_output_level(CosimLogLevel.WARNING)  # its debug lines would flood the test's output
    p, c = refs(plant), refs(controller)
    execution = CosimExecution.from_step_size(STEP_NS)
    ip = execution.add_local_slave(CosimLocalSlave(plant, "plant"))
    ic = execution.add_local_slave(CosimLocalSlave(controller, "controller"))
    assert execution.connect_real_variables(ip, p["line_angle"], ic, c["line_angle"]) == 0
    for side in ("voltage_left", "voltage_right"):
        assert execution.connect_real_variables(ic, c[side], ip, p[side]) == 0
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    status, steps = 0, 0
    while status == 0 and steps * STEP_S < LIMIT_S:
        assert execution.step(CHUNK)
        steps += CHUNK
        (status,) = observer.last_integer_values(ip, [p["lap_status"]])
    lap_time, distance = observer.last_real_values(ip, [p["lap_time"], p["lap_distance"]])
    return status, lap_time, distance


def jacobi_lap(plant: str, controller: str) -> tuple[int, float, float]:
    """The same in a master written here with fmpy: at each communication point both FMUs take the outputs the other
    had at that point, then both step."""
    p, c = Slave(plant, "plant").initialise(), Slave(controller, "controller").initialise()
    try:
        while p.get("lap_status") == 0 and p.time < LIMIT_S - 1e-9:
            angle, left, right = p.get("line_angle"), c.get("voltage_left"), c.get("voltage_right")
            c.set({"line_angle": angle})
            p.set({"voltage_left": left, "voltage_right": right})
            p.step(STEP_S)
            c.step(STEP_S)
        return p.get("lap_status"), p.get("lap_time"), p.get("lap_distance")
    finally:
        p.close()
        c.close()


def test_libcosim_runs_the_plant_with_a_controller_fmu_round_the_lap(pair):
    twin, plant, controller = pair
    status, lap_time, distance = libcosim_lap(plant, controller)
    assert status == 1 and distance == pytest.approx(twin.track.length_m)
    assert (status, lap_time, distance) == jacobi_lap(plant, controller)  # another master, the same lap, bit for bit
    lap = run_laps(twin, [{}], keep_traces=False)[0]
    assert lap_time == pytest.approx(lap.lap_time_s, rel=0.02)  # the outputs one control period late
