"""Closed-loop throughput: the C firmware in MuJoCo's control callback against its ceiling and against Python.

Measured in one run on the default robot and track (shared machines are noisy; compare the ratios):
  * closed loop: ``twin.core.closed_loop.run_laps`` (calibration + one lap, C callback), as laps for answers run:
                 no trace kept, the lap judged in C and run in one batch call; and with its trace kept, drained and
                 judged in Python every chunk (``lap``, ``record``, the viewers)
  * ceiling:     the same voltages replayed open-loop by ``mujoco.batch`` rollouts, no callback: the same
                 physics step by step (the replayed path is checked against the closed loop's), nothing else
  * Python loop: the same model stepped with ``mujoco.mj_step`` from Python, with the sensors (``mj_ray``,
                 footprint, response: line_sensor.reflectance) and the firmware (Eqs. 8–11: twin.model.control)
                 in Python every Δt — the references the C is tested against
All on one thread, timed in CPU time of that thread (``time.thread_time``) with the garbage collector off, as
``timeit`` does: on a shared machine wall time swings ±15 % between identical runs, CPU time a few %.
Targets: closed loop ≥ 90 % of the ceiling and ≥ 20× the Python loop. The closed loop's time is also split into
MuJoCo's batch calls (physics and C callback) and Python between them, each measured on the same runs.

  python benchmarks/bench_closed_loop.py [--python-seconds 2] [--repeat 11] [--quick] [--json]

``--quick``: one run of each, 0.1 s of the Python loop (for CI: the script cannot rot).
"""

from __future__ import annotations

import argparse
import gc
import json
import time

import mujoco
import mujoco.batch
import numpy as np

from line_sensor.reflectance import NoiseSource, footprint_reflectance
from mjcf.world import LINE_SENSOR, MOTORS, START_KEY
from twin.core.lap import COL
from twin.model import control as ref
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.model.timing import applied_voltages


class BatchCallTimer:
    """CPU time of this thread spent inside ``mujoco.batch.Batch.step`` and ``rollout`` (the physics and the C
    callback), while installed: the rest of a closed-loop run is Python between the calls."""

    def __init__(self):
        self.seconds = 0.0
        self._saved = {}

    def __enter__(self):
        for name in ("step", "rollout"):
            method = self._saved[name] = getattr(mujoco.batch.Batch, name)

            def timed(batch, *a, _method=method, **k):
                t0 = time.thread_time()
                try:
                    return _method(batch, *a, **k)
                finally:
                    self.seconds += time.thread_time() - t0

            setattr(mujoco.batch.Batch, name, timed)
        return self

    def __exit__(self, *exc):
        for name, method in self._saved.items():
            setattr(mujoco.batch.Batch, name, method)


def closed_loop(twin: DigitalTwin, keep_traces: bool) -> tuple[float, object, float]:
    """(wall s, lap result, s inside MuJoCo's batch calls) of calibration + one lap on one thread. Without its trace
    the lap is judged in C alone and runs in one batch call, as laps for answers run (tuning, sweeps, alignment);
    with it, Python drains and judges the trace every chunk (``lap``, ``record``, viewers)."""
    with BatchCallTimer() as inside:
        t0 = time.thread_time()
        r = run_laps(twin, [{}], nthread=1, keep_traces=keep_traces, reuse_calibration=False)[0]
        wall = time.thread_time() - t0
    return wall, r, inside.seconds


def voltages(twin: DigitalTwin, lap) -> tuple[np.ndarray, np.ndarray]:
    """The motor voltages the closed loop applied at every physics step: calibration turn (its commands at each tick,
    for the cost: the ceiling replays each phase from the start line, and only the lap's path is compared), then the
    lap."""
    p, model = twin.control_params(), twin.model()
    k = round(p.dt_s / model.opt.timestep)
    supply = twin.space.get("motor.supply_voltage")
    n_cal = ref.calibration_ticks(p) + 2
    turn = np.array([ref.calibration_direction(p, t) * p.cal_duty * supply for t in range(n_cal)])
    cal = np.repeat(np.stack([-turn, turn], axis=1), k, axis=0)
    records = lap.trace.records  # the lap's: the duties each tick commanded, applied as the robot's timing says
    run = applied_voltages(records[:, COL["time_s"]], records[:, [COL["u_left_v"], COL["u_right_v"]]] / supply,
                           lap.trace.raw_us.max(axis=1), twin.timing(), supply, model.opt.timestep,
                           len(records) * k)
    return cal, run


def under_load(twin: DigitalTwin, phases: list[np.ndarray]) -> list[np.ndarray]:
    """The voltages the motors got: each phase's commanded ones (duty × the nominal supply) times the supply under the
    step's load (twin.model.power, which the C loop's lf_bus_voltage follows to 1e-12 V), found by stepping each phase
    once from the start line in Python (untimed; the ceiling then replays them in one batch call)."""
    mujoco.set_mjcb_control(None)
    model, power, motor = twin.model(), twin.power(), twin.motor()
    data = mujoco.MjData(model)
    act = [model.actuator(n).id for n in MOTORS]
    out = []
    for u in phases:
        mujoco.mj_resetDataKeyframe(model, data, model.key(START_KEY).id)
        applied = np.empty_like(u)
        for k, duty in enumerate(u / power.nominal_v):
            mujoco.mj_step1(model, data)  # the state's velocities: the back-EMF the step's control sees
            emf = [motor.K * data.actuator_velocity[a] for a in act]  # the actuator's velocity is the motor shaft's
            bus, _ = power.bus_voltage(duty, emf, (motor.R_M, motor.R_M))
            applied[k] = data.ctrl[act] = duty * bus
            mujoco.mj_step2(model, data)
        out.append(applied)
    return out


def ceiling(model: mujoco.MjModel, phases: list[np.ndarray]) -> tuple[float, np.ndarray]:
    """Replay the same voltages open-loop (no callback): the same physics, nothing else. (wall s, last qpos)."""
    mujoco.set_mjcb_control(None)
    batch = mujoco.batch.Batch(model, nsim=1, nthread=1)
    key = np.array([model.key(START_KEY).id])
    wall = 0.0
    for u in phases:
        batch.reset(keyframe=key)
        t0 = time.thread_time()
        out = batch.rollout(len(u), control=u[None], record=("qpos",))
        wall += time.thread_time() - t0
    return wall, out["qpos"][0]


def python_loop(twin: DigitalTwin, seconds: float) -> tuple[float, int]:
    """The same loop with sensors and firmware in Python (no calibration turn: calibrated to white/black)."""
    mujoco.set_mjcb_control(None)
    model, p, sensor, tex = twin.model(), twin.control_params(), twin.sensor_model(), twin.texture
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(START_KEY).id)
    sites = [model.site(LINE_SENSOR.format(i)).id for i in range(p.count)]
    mount = model.body(twin.info.sensor_body).id
    groups = np.array([1, 1, 0, 0, 0, 0], dtype=np.uint8)  # as the C glue: the world, not the robot
    geom = np.zeros(1, dtype=np.int32)
    act = [model.actuator(n).id for n in MOTORS]
    fw = ref.FirmwareState.uncalibrated(p.count, int(sensor.timeout_us))
    fw.cal_min, fw.cal_max = [200] * p.count, [2400] * p.count
    fw.reset(ref.RUN)
    noise = NoiseSource(1)
    every = round(p.dt_s / model.opt.timestep)
    nstep = int(round(seconds / model.opt.timestep))
    supply = twin.space.get("motor.supply_voltage")
    t0 = time.thread_time()
    for k in range(nstep):
        if k % every == 0:
            mujoco.mj_kinematics(model, data)  # site poses at the current state, as the C callback sees them
            raw = []
            for site in sites:
                origin, ray = data.site_xpos[site], data.site_xmat[site].reshape(3, 3)[:, 2].copy()
                h = mujoco.mj_ray(model, data, origin, ray, groups, 1, mount, geom)
                x, y = origin[0] + h * ray[0], origin[1] + h * ray[1]
                rho = footprint_reflectance(tex.grey, tex.origin_xy, tex.metres_per_pixel, x, y, sensor.footprint_radius(h))
                raw.append(sensor.raw_reading(rho, h, noise.noise()))
            ref.firmware_step(fw, p, raw)
            data.ctrl[act[0]], data.ctrl[act[1]] = fw.duty_left * supply, fw.duty_right * supply
        mujoco.mj_step(model, data)
    return time.thread_time() - t0, nstep


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--python-seconds", type=float, default=2.0, help="simulated seconds of the Python loop")
    ap.add_argument("--repeat", type=int, default=11, help="runs of each, in pairs (closed loop, ceiling)")
    ap.add_argument("--quick", action="store_true", help="one run of each, 0.1 s of the Python loop (for CI)")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args()
    if args.quick:
        args.python_seconds, args.repeat = 0.1, 1
    twin = DigitalTwin()
    model = twin.model()
    _, lap, _ = closed_loop(twin, keep_traces=True)  # warm-up; the ceiling replays this lap's voltages
    gc.disable()
    cal, run = under_load(twin, list(voltages(twin, lap)))
    nstep, sim_s = len(cal) + len(run), (len(cal) + len(run)) * model.opt.timestep
    walls, ceils, insides, traced = [], [], [], []
    for _ in range(args.repeat):  # side by side, so all of a round see the same machine
        w, untraced, inside = closed_loop(twin, keep_traces=False)
        walls.append(w)
        insides.append(inside)
        traced.append(closed_loop(twin, keep_traces=True)[0])
        ceils.append(ceiling(model, [cal, run]))
    if untraced.summary() != {**lap.summary(), "parameters": untraced.parameters}:
        raise SystemExit("the lap without its trace is not the lap with it")
    wall = min(walls)
    ceil, qpos = min(ceils, key=lambda x: x[0])
    paired = float(np.median([c[0] / w for w, c in zip(walls, ceils)]))
    k = round(twin.space.get("control.dt") / model.opt.timestep)
    # the replay is the same trajectory: its path at each tick against the closed loop's
    deviation = float(np.max(np.hypot(*(qpos[k - 1 :: k, :2][: len(lap.trace.records) - 1]
                                         - lap.trace.records[1:, 1:3]).T)))
    py_wall, py_steps = min(python_loop(twin, args.python_seconds) for _ in range(max(1, args.repeat - 1)))
    out = {
        "timestep_s": model.opt.timestep,
        "control_period_s": twin.space.get("control.dt"),
        "steps": nstep,
        "simulated_s": sim_s,
        "closed_loop_steps_per_s": nstep / wall,
        "closed_loop_realtime_factor": sim_s / wall,
        "ceiling_steps_per_s": nstep / ceil,
        "python_loop_steps_per_s": py_steps / py_wall,
        "ratio_closed_loop_over_ceiling": paired,
        "ratio_best_over_best": ceil / wall,
        "ratio_traced_over_ceiling": float(np.median([c[0] / w for w, c in zip(traced, ceils)])),
        # the closed loop's time inside MuJoCo's batch calls (physics + C callback) against the ceiling, and the
        # share of its time spent in Python between those calls (setting laps up, draining and judging each chunk)
        "ratio_batch_calls_over_ceiling": float(np.median([c[0] / i for i, c in zip(insides, ceils)])),
        "python_share_of_closed_loop": float(np.median([1 - i / w for w, i in zip(walls, insides)])),
        "ratio_closed_loop_over_python": (nstep / wall) / (py_steps / py_wall),
        "replay_max_deviation_m": deviation,
    }
    if args.json:
        print(json.dumps(out))
        return
    print(f"default robot, default track: {nstep} steps of {model.opt.timestep * 1e3:g} ms "
          f"(calibration + lap, {sim_s:.2f} s simulated), control every {out['control_period_s'] * 1e3:g} ms, 1 thread")
    print(f"  closed loop (C)    : {out['closed_loop_steps_per_s']:10.0f} steps/s  ({out['closed_loop_realtime_factor']:.0f}× real time)")
    print(f"  ceiling (mj_step)  : {out['ceiling_steps_per_s']:10.0f} steps/s  (same voltages replayed open-loop; "
          f"path within {deviation * 1e6:.1g} µm of the closed loop's)")
    print(f"  Python loop        : {out['python_loop_steps_per_s']:10.0f} steps/s")
    print(f"  closed / ceiling   : {out['ratio_closed_loop_over_ceiling'] * 100:.1f} %   (median of {args.repeat} paired runs; "
          f"best/best {out['ratio_best_over_best'] * 100:.1f} %; target ≥ 90 %; no trace kept, as laps for answers run)")
    print(f"    of which inside MuJoCo's batch calls (physics + C callback): {out['ratio_batch_calls_over_ceiling'] * 100:.1f} % "
          f"of the ceiling; Python around them (setting the lap up, between calls): "
          f"{out['python_share_of_closed_loop'] * 100:.1f} % of the closed loop's time")
    print(f"  with the trace kept: {out['ratio_traced_over_ceiling'] * 100:.1f} % of the ceiling (Python drains and judges "
          f"it every 1.6 s chunk: lap, record, the viewers)")
    print(f"  closed / Python    : {out['ratio_closed_loop_over_python']:.1f}×   (target ≥ 20×)")


if __name__ == "__main__":
    main()
