"""The C boundary checks itself: layout at import, userdata against the model in the callback, counts and step
counts against the C limits before any C runs, a limit on every phase, MuJoCo's log kept out of the cwd.

Anything that could crash the interpreter if a check were missing runs in a subprocess."""

from __future__ import annotations

import ctypes
import json
import math
import os
import re
import subprocess
import sys
import time

import pytest

from line_sensor.geometry import MAX_SENSORS
from twin.model import control as ref
from twin.core import native as core
from twin.core.closed_loop import CHUNK_TICKS, MIN_CHUNK_TICKS, chunk_ticks, run_laps
from twin.core.digital_twin import DigitalTwin
from twin.errors import TwinError
from twin.core.lap import LapLimits
from twin.core.outcomes import REFUSALS, Outcome, c_names

CSRC = os.path.join(os.path.dirname(__file__), "..", "twin", "csrc")


def header_constants(path: str) -> dict[str, int]:
    """``NAME = value`` enumerators and ``#define NAME value`` integers of a C header, read from its text."""
    text = open(os.path.join(CSRC, path)).read()
    found = {m[0]: int(m[1]) for m in re.findall(r"\b(LF_\w+) = (\d+)", text)}
    found.update({m[0]: int(m[1]) for m in re.findall(r"#define (LF_\w+) (\d+)\b", text)})
    return found


STATUSES = header_constants("sim/lf_status.h")


@pytest.fixture(scope="module")
def twin():
    return DigitalTwin()


# --- layout: every mirrored field, checked when twin.core.native loads
@pytest.mark.quick
def test_the_library_layout_is_the_mirror():
    c = core.library_layout(core.lib)
    ours = core.mirrors()
    assert c == {f"{s}.{n}": at for s, fields in ours.items() for n, at in fields.items()}
    # trace records are rows of doubles: column k at byte 8k, in the order the header declares them
    assert c["lf_record.time_s"] == (0, 8) and c["lf_record.offset_abs_max_m"] == (8 * 19, 8)
    assert c["lf_record.raw_us"] == (8 * 20, 8 * MAX_SENSORS)


@pytest.mark.quick
@pytest.mark.parametrize("struct, cls", [("lf_sim", core.Sim), ("lf_params", core.Params), ("lf_state", core.FwState),
                                         ("lf_sensor_model", core.SensorModelC), ("lf_texture", core.Texture)])
def test_the_c_table_leaves_no_field_out(struct, cls):
    """Fields in offset order leave only alignment padding between them: a field missing from the table would
    leave a hole."""
    c = core.library_layout(core.lib)
    types = dict(cls._fields_)
    rows = sorted((off, size, name.split(".", 1)[1]) for name, (off, size) in c.items() if name.startswith(struct + "."))
    end = 0
    for off, size, name in rows:
        align = ctypes.alignment(types[name])
        assert off == -(-end // align) * align, name
        end = off + size
    assert ctypes.sizeof(cls) == -(-end // ctypes.alignment(cls)) * ctypes.alignment(cls)


@pytest.mark.quick
def test_a_mirror_that_drifted_fails_the_import_check():
    c = core.library_layout(core.lib)
    ours = core.mirrors()
    moved = {s: dict(f) for s, f in ours.items()}
    moved["lf_sim"]["nsensor"] = (moved["lf_sim"]["nsensor"][0] + 4, 4)
    with pytest.raises(ImportError, match="lf_sim.nsensor.*rebuild"):
        core.check_layout(c, moved)
    missing = {s: dict(f) for s, f in ours.items()}
    del missing["lf_state"]["tick"]
    with pytest.raises(ImportError, match="lf_state.tick"):
        core.check_layout(c, missing)
    with pytest.raises(ImportError, match="lf_params.extra"):
        core.check_layout({**c, "lf_params.extra": (200, 8)}, ours)


@pytest.mark.quick
def test_python_and_c_agree_on_the_limits():
    fw = header_constants("firmware/line_follower.h")
    assert MAX_SENSORS == fw["LF_MAX_SENSORS"]
    assert core.LAYOUT_VERSION == header_constants("sim/twin_core.h")["LF_LAYOUT_VERSION"]
    # every code lf_check returns (the misfits of a head) has its words for the lap's detail
    text = open(os.path.join(CSRC, "sim", "mujoco_glue.c")).read()
    check = text[text.index("int32_t lf_check("):]
    returned = set(re.findall(r"return (LF_ERR_\w+);", check[: check.index("\n}\n")]))
    assert {f"LF_{s.name}" for s in REFUSALS} == returned


# --- status codes: one enumeration in C (lf_status.h), named in each library's table, mirrored by Python
def test_the_status_codes_are_one_enumeration_in_c_and_python():
    assert STATUSES == core.library_statuses(core.lib) == c_names()  # the header's text, the library's table, Python


def test_a_status_code_on_one_side_only_fails_the_import_check():
    c = core.library_statuses(core.lib)
    with pytest.raises(ImportError, match="LF_STALLED: value C 10, Python 11.*rebuild"):
        core.check_same(c, {**c_names(), "LF_STALLED": 11}, "value")
    with pytest.raises(ImportError, match="LF_ERR_NEW: value C None, Python 12"):
        core.check_same(c, {**c_names(), "LF_ERR_NEW": 12}, "value")


def test_lap_outcomes_are_the_strings_results_carry():
    assert [o.value for o in Outcome] == ["completed", "off_track", "line_lost", "timeout", "diverged", "calibration",
                                          "refused", "wrong_way", "firmware_stalled", "power", "stopped"]
    assert all(type(o.value) is str for o in Outcome)  # LapResult.failure holds these, never the members


# --- the callback refuses userdata that does not fit its model
REFUSE = r"""
import json, sys
import mujoco
from twin.core import native as core
from twin.core.closed_loop import setup
from twin.core.digital_twin import DigitalTwin

case = sys.argv[1]
twin = DigitalTwin()
model = twin.model()
core.install_callback()
head = mujoco.MjData(model)
setup(head.userdata, model, twin, twin.control_params(), twin.sensor_model(), 0)
if case == "other_model":  # the head written for the default track's model, stepped on the oval's
    model = DigitalTwin(track="oval").model()
data = mujoco.MjData(model)
mujoco.mj_resetDataKeyframe(model, data, 0)  # (a reset clears userdata)
data.userdata[: core.SIM_WORDS] = head.userdata[: core.SIM_WORDS]
sim = core.sim_view(data.userdata)
if case == "centre_count":
    sim.centre_count = 10**9
elif case == "capacity":
    sim.record_capacity = 0
elif case == "layout":
    sim.layout_version = core.LAYOUT_VERSION - 1
elif case == "site":
    sim.sensor_site[3] = model.nsite
elif case == "actuator":
    sim.actuator_left = -1
elif case == "nsensor":
    sim.nsensor = sim.firmware.count = 17
elif case == "count":
    sim.firmware.count = 1000
elif case == "records":
    sim.records_written = -3
for _ in range(50):
    mujoco.mj_step(model, data)
print(json.dumps({"error": sim.error, "records": sim.records_written, "ctrl": data.ctrl.tolist(),
                  "why": core.refusal(sim)}))
"""


def refuse(case: str) -> dict:
    p = subprocess.run([sys.executable, "-c", REFUSE, case], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, f"{case}: exit {p.returncode}: {p.stderr[-2000:]}"
    return json.loads(p.stdout.strip().splitlines()[-1])


def test_a_head_that_fits_is_run():
    out = refuse("none")
    assert out["error"] == 0 and out["why"] is None
    assert out["records"] == 10  # 50 steps of 1 ms, a tick every 5 ms
    assert out["ctrl"] != [0.0, 0.0]  # the calibration turn drives the motors


@pytest.mark.parametrize("case, code", [
    ("other_model", "LF_ERR_MODEL"), ("centre_count", "LF_ERR_CENTRE"), ("capacity", "LF_ERR_CAPACITY"),
    ("layout", "LF_ERR_LAYOUT"), ("site", "LF_ERR_ID"), ("actuator", "LF_ERR_ID"), ("nsensor", "LF_ERR_SENSORS"),
    ("count", "LF_ERR_SENSORS"), ("records", "LF_ERR_STATE"),
])
def test_a_head_that_does_not_fit_is_refused_untouched(case, code):
    out = refuse(case)
    assert out["error"] == STATUSES[code]
    assert out["ctrl"] == [0.0, 0.0]  # refused before the first tick: the motors were never driven
    assert out["why"].startswith("the C loop refused the simulation: its userdata did not match the model")


FORGED_LAP = r"""
import json
from twin.core import closed_loop
from twin.core.digital_twin import DigitalTwin

setup = closed_loop.setup
def forged(row, model, *args):
    sim = setup(row, model, *args)
    sim.centre_count = 10**9  # would walk the centre line far outside numeric_data
    return sim
closed_loop.setup = forged
r = closed_loop.run_laps(DigitalTwin(), [{}, {"control.kp": 20.0}], keep_traces=False)
print(json.dumps([[x.failure, x.detail, x.simulated_s] for x in r]))
"""


def test_a_refused_simulation_is_a_failed_lap():
    p = subprocess.run([sys.executable, "-c", FORGED_LAP], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr[-2000:]
    for failure, detail, _ in json.loads(p.stdout.strip().splitlines()[-1]):
        assert failure == "refused" and "did not match the model" in detail and "centre line" in detail


# --- counts against the C arrays, before any C runs
def params(**kw) -> ref.ControlParams:
    base = dict(count=8, pitch_m=0.009525, sensor_distance_m=0.04, v_max=0.6, k_b=0.5, k_p=15.0, k_i=0.0, k_d=0.3,
                dt_s=0.005, wheel_radius_m=0.016, half_track_m=0.0425, wheel_speed_max=75.4, accel_max=3.0,
                integral_limit=0.5, cal_duty=0.15, cal_sweep_rad=1.0, cal_sweeps=2)
    return ref.ControlParams(**{**base, **kw})


@pytest.mark.quick
@pytest.mark.parametrize("kw, needle", [
    ({"count": 1000}, "control.count"), ({"count": MAX_SENSORS + 1}, "control.count"), ({"count": 0}, "control.count"),
    ({"count": 8.0}, "control.count"), ({"cal_sweeps": 2**31}, "control.cal_sweeps"),
])
def test_counts_beyond_the_c_limits_are_refused(kw, needle):
    with pytest.raises(TwinError, match=needle) as e:
        params(**kw)
    assert "\n" not in str(e.value)


@pytest.mark.quick
def test_the_largest_sensor_count_is_accepted():
    assert params(count=MAX_SENSORS).count == 16


# --- step counts saturate identically in C and Python
def c_ticks(p) -> int:
    return core.lib.lf_calibration_ticks(ctypes.byref(core.params_to_c(p)))


@pytest.mark.quick
def test_calibration_ticks_by_hand():
    # ω = 0.01 · 1 rad/s · 16 mm / 42.5 mm; a quarter sweep of 3 rad takes 3 / (ω · 5 ms) = 159375 ticks
    slow = params(cal_duty=0.01, wheel_speed_max=1.0, cal_sweep_rad=3.0, cal_sweeps=10)
    assert ref.calibration_ticks(slow) == c_ticks(slow) == 4 * 159375 * 10


@pytest.mark.quick
@pytest.mark.parametrize("kw, expected", [
    # a quarter beyond 2**29 ticks saturates there: one sweep is then 2**31 ticks
    ({"wheel_radius_m": 1e-9, "cal_duty": 0.01, "wheel_speed_max": 1.0, "cal_sweeps": 1}, 2**31),
    # ideal: 4 · 1.33e12 · 10 ticks, far beyond uint32: saturates, never wraps to a short turn
    ({"wheel_radius_m": 1e-9, "cal_duty": 0.01, "wheel_speed_max": 1.0, "cal_sweeps": 10}, 2**32 - 1),
    ({"wheel_radius_m": 1e-300, "cal_sweeps": 2**31 - 1}, 2**32 - 1),
])
def test_calibration_ticks_saturate_alike(kw, expected):
    p = params(**kw)
    assert ref.calibration_ticks(p) == c_ticks(p) == expected


@pytest.mark.quick
def test_c_saturates_where_python_cannot_go():
    """Values ControlParams refuses still give C a defined answer (no division by zero, no wrap)."""
    p = core.params_to_c(params())
    p.cal_duty, p.cal_sweeps = 0.0, 1  # ω = 0: an endless quarter, saturated at 2**29 ticks
    assert core.lib.lf_calibration_ticks(ctypes.byref(p)) == 4 * 2**29
    p.cal_sweeps = 2  # 2**32 ticks do not fit a uint32
    assert core.lib.lf_calibration_ticks(ctypes.byref(p)) == 2**32 - 1
    p.cal_duty, p.cal_sweeps = float("nan"), -5
    assert core.lib.lf_calibration_ticks(ctypes.byref(p)) == 0


@pytest.mark.quick
def test_the_tick_counter_saturates_in_c_and_python():
    p = params(count=4)
    c = core.FwState()
    py = ref.FirmwareState.uncalibrated(4, 2500)
    c.tick = py.tick = 2**32 - 1
    c.mode = py.mode = ref.IDLE
    raw = (ctypes.c_uint16 * 16)(*[1000] * 4)
    core.lib.lf_step(ctypes.byref(c), ctypes.byref(core.params_to_c(p)), raw)
    ref.firmware_step(py, p, [1000] * 4)
    assert c.tick == py.tick == 2**32 - 1


@pytest.mark.quick
@pytest.mark.parametrize("remaining, per_tick, expected", [
    (7.18, 0.0, CHUNK_TICKS), (7.18, 1e-320, CHUNK_TICKS), (math.nan, 0.01, CHUNK_TICKS), (math.inf, 0.01, CHUNK_TICKS),
    (0.0, 0.01, MIN_CHUNK_TICKS),  # at most 1 tick could finish it: the shortest chunk
    (1.0, 0.01, 80),  # 101 ticks could not finish it: 10 · 2^floor(log2(10.1)) = 80
    (-3.0, 0.01, MIN_CHUNK_TICKS),
])
def test_chunk_scheduler_never_overflows(remaining, per_tick, expected):
    assert chunk_ticks(remaining, per_tick) == expected


# --- seeds
@pytest.mark.quick
@pytest.mark.parametrize("seed", [2**64, -1, 1.5, "7"])
def test_seeds_outside_the_generator_are_refused(twin, seed):
    with pytest.raises(TwinError, match=re.escape(f"seed: must be a whole number in [0, 2**64 - 1], got {seed!r}")):
        run_laps(twin, [{}], seed=seed)


@pytest.mark.quick
def test_the_largest_seed_is_its_own(twin):
    top = run_laps(twin, [{}], seed=2**64 - 1)[0]
    zero = run_laps(twin, [{}], seed=0)[0]
    assert top.completed and (top.trace.raw_us[:50] != zero.trace.raw_us[:50]).any()


# --- the calibration turn has a limit in simulated time, checked before simulating
@pytest.mark.quick
def test_a_turn_too_slow_fails_at_once(twin):
    slow = {"control.full_speed": 1.0, "control.cal_duty": 0.01, "control.cal_sweeps": 10, "control.cal_sweep": 3.0}
    t0 = time.perf_counter()
    r, default = run_laps(twin, [slow, {}], keep_traces=False, reuse_calibration=False)
    assert time.perf_counter() - t0 < 30  # the default lap alone; the slow turn would run for hours of wall time
    assert r.failure == "calibration" and r.simulated_s == 0.0
    # 4 · 159375 ticks per sweep (see test_calibration_ticks_by_hand) · 10 sweeps · 5 ms
    assert "31875 s" in r.detail and "control.cal_duty" in r.detail and "control.full_speed" in r.detail
    assert default.completed
    assert default.summary() == run_laps(twin, [{}], keep_traces=False)[0].summary()  # batch = alone


@pytest.mark.quick
def test_the_turn_limit_is_simulated_time(twin):
    p = twin.control_params()
    omega = p.cal_duty * twin.space.get("control.full_speed") * 0.016 / 0.0425  # Eq. 2: ω = R (ω_r − ω_l) / 2L
    turn_s = 4 * round(p.cal_sweep_rad / (omega * p.dt_s)) * p.cal_sweeps * p.dt_s  # 4 · 61 · 2 · 5 ms = 2.44 s
    assert turn_s == pytest.approx(2.44)  # 1.3 rad / (0.15 · 75.4 rad/s · 16 mm / 42.5 mm · 5 ms) = 61.06 ticks
    short = run_laps(twin, [{}], limits=LapLimits(calibration_timeout_s=turn_s - 0.005), keep_traces=False)[0]
    assert short.failure == "calibration" and "would take 2.44 s" in short.detail
    assert run_laps(twin, [{}], limits=LapLimits(calibration_timeout_s=turn_s + 0.005), keep_traces=False)[0].completed


# --- MuJoCo's warnings go to logging, not to MUJOCO_LOG.TXT
HEAVY = r"""
import json, logging
logging.basicConfig(level=logging.WARNING, format="LOG %(name)s %(message)s")
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
twin = DigitalTwin()
twin.model().body_mass[:] = 1e300
r = run_laps(twin, [{}, {"control.kp": 20.0}, {"motion.mu": 0.5}], nthread=2, keep_traces=False)
print(json.dumps([x.failure for x in r]))
"""


def test_an_unstable_lap_logs_mujoco_warnings_and_writes_no_file(tmp_path):
    env = {**os.environ, "PYTHONPATH": os.path.join(os.path.dirname(__file__), "..")}
    p = subprocess.run([sys.executable, "-c", HEAVY], cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env)
    assert p.returncode == 0, p.stderr[-2000:]
    assert json.loads(p.stdout.strip().splitlines()[-1]) == ["diverged"] * 3
    assert list(tmp_path.iterdir()) == []  # no MUJOCO_LOG.TXT, nothing else
    records = [line for line in p.stderr.splitlines() if line.startswith("LOG mujoco ")]
    assert any("Nan, Inf or huge value" in line for line in records)
    assert len(p.stderr.splitlines()) < 30  # thousands of warnings, a few lines
