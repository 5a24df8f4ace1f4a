"""A lap with a controller FMU in the twin's loop.

The phases are the lap's (:mod:`twin.core.closed_loop`): the robot's own firmware calibrates by turning in place over
the start line (the sensor library's procedure, the same turn bit for bit), the robot is put back on the start line
with that calibration, and then the controller FMU drives. Each physics step runs as ``mj_step`` runs the control
callback (``mj_step1``, the loop's work, ``mj_step2``); at each of the controller's sample times the C core reads the
sensors and runs the firmware's sensor side (``lf_external_step``: Eqs. 8–9), the FMU steps from t to t + T on those
values, and its outputs reach the motors as the firmware's would on the same robot: with the robot's timing
(``timing.*``: the read's duration, ``timing.compute``, the PWM's whole counts; set ``timing.compute`` to the
controller's own compute time on the robot's MCU). The head of this loop carries no mark, so the control callback
leaves it alone. The lap is judged as every lap is (:class:`twin.core.lap.LapJudge`) but for line loss: whether the
controller still sees the line is its own belief, which the twin cannot read (the firmware's threshold is not its; an
INTO-CPS robot's two sensors straddle the line by design and see it only to turn), so off-track, cut-across and the
timeout judge it, as they judge a 3pi program.
"""

from __future__ import annotations

import ctypes

import mujoco
import numpy as np

from mjcf.world import START_KEY
from twin.core import native as core
from twin.core.calibration import range_too_small, turn_too_long
from twin.core.closed_loop import check_seed, setup, start_phase
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapJudge, LapLimits, LapResult
from twin.core.outcomes import Outcome
from twin.errors import TwinError
from twin.fmi.controller import ControllerFmu
from twin.model.control import IDLE, RUN, calibration_ticks

CHUNK_TICKS = 100  # controller ticks between drains of the trace ring (it holds RECORD_CAPACITY records)
_P = ctypes.c_void_p


def _library() -> ctypes.CDLL:
    """The C core with the external-control entry points typed (an older build lacks them: say so)."""
    lib = core.lib
    try:
        lib.lf_external_step.argtypes = [_P, _P, _P, ctypes.POINTER(ctypes.c_double)]
    except AttributeError:
        raise TwinError("twin.core._lfcore is out of date (no lf_external_step); rebuild it with pip install -e .") \
            from None
    lib.lf_external_step.restype = ctypes.c_int32
    lib.lf_external_command.argtypes = [_P, _P, _P, ctypes.c_double, ctypes.c_double, ctypes.c_double]
    lib.lf_external_command.restype = None
    lib.lf_external_drive.argtypes = [_P, _P, _P]
    lib.lf_external_drive.restype = None
    return lib
BAD = (mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL, mujoco.mjtWarning.mjWARN_BADQACC)


def _diverged(data: mujoco.MjData) -> bool:
    """MuJoCo found a bad state (and reset the data, head included), or the state is not finite."""
    return any(data.warning[w].number for w in BAD) or not np.isfinite(data.qpos).all()


def white_8bit(calibrated: int) -> int:
    """A calibrated reading (0 white … 1000 black) on the white-high 8-bit scale (0 black … 255 white) of the
    INTO-CPS sensor blocks: 255 (1000 − calibrated) / 1000, rounded half up, as integers."""
    return (255 * (1000 - int(calibrated)) + 500) // 1000


def _readers(sim: core.Sim, data: mujoco.MjData) -> dict:
    """The sensor-side ports as functions of the head and data at a tick."""
    fw = sim.fw
    out = {"line_position": lambda: fw.position, "line_angle": lambda: fw.e, "line_seen": lambda: fw.line_seen,
           "wheel_speed_left": lambda: data.qvel[sim.dof_left], "wheel_speed_right": lambda: data.qvel[sim.dof_right],
           "energy_used": lambda: sim.energy_j}
    for i in range(sim.nsensor):
        out[f"sensor.calibrated[{i + 1}]"] = lambda i=i: fw.value[i]
        out[f"sensor.raw[{i + 1}]"] = lambda i=i: sim.raw[i]
        out[f"sensor.white_8bit[{i + 1}]"] = lambda i=i: white_8bit(fw.value[i])
    return out


def _calibrate(twin, model, data, params, sensor, physics, seed, judge) -> tuple | None:
    """The firmware's calibration turn from the start line: (min, max), or None if it failed."""
    mujoco.mj_resetDataKeyframe(model, data, model.key(START_KEY).id)
    sim = setup(data.userdata, model, twin, params, sensor, seed, physics)
    steps = round(params.dt_s / physics.timestep)
    mujoco.mj_step(model, data, (calibration_ticks(params) + 2) * steps)
    core.flush_mujoco_log()
    if _diverged(data):
        judge.fail(Outcome.DIVERGED, "the physics produced a non-finite state during the calibration turn", data.time, 0.0)
        return None
    if why := core.refusal(sim):
        judge.fail(Outcome.REFUSED, why, data.time, 0.0)
        return None
    if sim.fw.mode != IDLE:
        raise TwinError(f"calibration did not finish in {(calibration_ticks(params) + 2) * steps} steps")
    return tuple(sim.fw.cal_min[: sim.nsensor]), tuple(sim.fw.cal_max[: sim.nsensor])


def run_controller_lap(twin: DigitalTwin, controller: ControllerFmu, seed: int = 0, limits: LapLimits = LapLimits(),
                       keep_trace: bool = True) -> LapResult:
    """Calibrate, then one lap driven by ``controller``; the same seed gives the same lap, bit for bit.

    Args:
      twin: the robot on its track, with its values.
      controller: the checked and mapped controller FMU.
      seed: sensor-noise seed in [0, 2**64 − 1].
      limits: failure thresholds.
      keep_trace: keep the per-tick trace in the result.
    """
    check_seed(seed)
    _library()  # before any work: a stale build is one line
    with controller.start() as session:  # its process loads the FMU while the twin builds and calibrates
        return _calibrate_and_drive(twin, controller, session, seed, limits, keep_trace)


def _calibrate_and_drive(twin, controller, session, seed: int, limits: LapLimits, keep_trace: bool) -> LapResult:
    model = twin.model()
    params, sensor, physics = twin.control_params(), twin.sensor_model(), twin.physics()
    values = dict(twin.space.values)
    judge = LapJudge(twin.track, limits, keep_trace, line_loss=False)  # its belief about the line is its own
    if controller.sample_time < physics.timestep:
        raise TwinError(f"--controller-fmu {controller.path}: its sample time {controller.sample_time:g} s is "
                        f"shorter than the physics step ({physics.timestep:g} s)")
    if why := turn_too_long(params, limits):
        judge.fail(Outcome.CALIBRATION, why, 0.0, 0.0)
        return judge.result(params.count, [], [], values)
    core.install_callback()
    data = mujoco.MjData(model)
    cal = _calibrate(twin, model, data, params, sensor, physics, seed, judge)
    if cal is None:
        return judge.result(params.count, [], [], values)
    lo, hi = cal
    mujoco.mj_resetDataKeyframe(model, data, model.key(START_KEY).id)
    sim = setup(data.userdata, model, twin, params, sensor, seed, physics)
    for j, (a, b) in enumerate(zip(lo, hi)):
        sim.fw.cal_min[j], sim.fw.cal_max[j] = a, b
    if why := range_too_small(twin, params, sensor, lo, hi, limits):
        judge.fail(Outcome.CALIBRATION, why, 0.0, 0.0)
        return judge.result(params.count, lo, hi, values)
    start_phase(sim, RUN)
    sim.magic = 0.0  # this loop owns the head: the control callback leaves it alone
    sim.firmware.dt_s = controller.sample_time  # ticks at the controller's sample times
    session.wait_ready()
    _drive(model, data, sim, session, controller, judge, params.wheel_speed_max, physics.supply_voltage)
    return judge.result(params.count, lo, hi, values)


def _drive(model, data, sim, session, controller, judge, full_speed: float, supply: float) -> None:
    lib = _library()
    mp, dp = _P(model._address), _P(data._address)
    sp = _P(ctypes.addressof(sim))
    h0 = ctypes.c_double()
    period = controller.sample_time
    readers = _readers(sim, data)
    used = [(readers[link.port], link.to_fmu) for link in controller.inputs]
    first = [link.at_start for link in controller.inputs]  # a replaced instance's outputs at t = 0, or None
    to_left, to_right = (link.from_fmu for link in controller.outputs)
    per_volt = {"voltage": None, "setpoint": full_speed, "duty": 1.0}[controller.actuation]
    chunk = CHUNK_TICKS * max(1, int(np.ceil(period / model.opt.timestep - 1e-9)))
    tick = consumed = 0
    while not judge.done:
        refused = False
        for _ in range(chunk):
            mujoco.mj_step1(model, data)
            due = lib.lf_external_step(mp, dp, sp, ctypes.byref(h0))
            if due < 0:
                refused = True
                break
            if due:
                values = [to_fmu(read()) if tick or start is None else start
                          for (read, to_fmu), start in zip(used, first)]
                left, right = session.step(tick * period, period, values)
                left, right = to_left(left), to_right(right)
                if per_volt is not None:  # a PWM duty (a set-point: of the no-load speed, as the firmware maps it)
                    left, right = (float(np.clip(w / per_volt, -1.0, 1.0)) * supply for w in (left, right))
                lib.lf_external_command(mp, dp, sp, left, right, h0.value)  # they reach the motors with the robot's timing
                tick += 1
            lib.lf_external_drive(mp, dp, sp)
            mujoco.mj_step2(model, data)
        core.flush_mujoco_log()
        if _diverged(data):
            judge.fail(Outcome.DIVERGED, "the physics produced a non-finite state", data.time, 0.0)
            return
        if refused:
            judge.fail(Outcome.REFUSED, core.refusal(sim) or "the C loop refused the simulation", data.time, 0.0)
            return
        judge.feed(core.records_since(data.userdata, sim, consumed))
        consumed = sim.records_written
