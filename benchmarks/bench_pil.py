"""Processor in the loop against real time: the robot's ATmega328P binary in simavr, in lockstep with MuJoCo.

Measured in one run on the default robot and track (shared machines are noisy; compare the ratios):
  * PIL lap:  ``twin.pil.lap.run_pil_lap`` (power-up, the firmware's calibration turn, the lap), one thread: simulated
              seconds (turn + lap) per CPU second of that thread
  * C lap:    ``twin.core.closed_loop.run_laps`` on one thread, the same phases, for scale
  * MCU only: the firmware run free for the same simulated time with the physics attached but not stepped, to
              split the PIL lap's cost between simavr and MuJoCo
Timed in CPU time of the thread (``time.thread_time``) with the garbage collector off, best of --repeat.
Target: the PIL lap at least real time on one core (ratio ≥ 1).

  python benchmarks/bench_pil.py [--repeat 3] [--json]
"""

from __future__ import annotations

import argparse
import gc
import json
import time

import mujoco

from twin.pil import firmware as fw
from twin.pil import lap as pil
from twin.core.closed_loop import run_laps
from twin.model.control import calibration_ticks
from twin.core.digital_twin import DigitalTwin
from twin.pil.mcu import Mcu
from twin.core.variant import Variant


def best(fn, repeat: int):
    times, out = [], None
    for _ in range(repeat):
        gc.collect()
        gc.disable()
        t0 = time.thread_time()
        try:
            out = fn()
        finally:
            gc.enable()
        times.append(time.thread_time() - t0)
    return min(times), out


def mcu_only(twin: DigitalTwin, simulated_s: float) -> None:
    lap = Variant.of(twin, {})
    model = twin.model()
    data = mujoco.MjData(model)
    with Mcu(fw.check_elf(fw.build("robot"), fw.TRACE_SYMBOLS)) as mcu:
        mcu.eeprom(fw.config_image(lap.params, lap.sensor.timeout_us, pil.TELEMETRY_EVERY))
        sim = pil.place_robot(model, data, twin, lap, 0)
        mujoco.mj_forward(model, data)  # the sensors' rays need the start pose's kinematics
        mcu.attach(model, data, sim, 1e9)
        mcu.run_cycles(int(simulated_s * fw.F_CPU_HZ))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    twin = DigitalTwin(track="default")
    twin.model()
    fw.build("robot")
    pil_s, (lap, report) = best(lambda: pil.run_pil_lap(twin, keep_trace=False), args.repeat)
    params = twin.control_params()
    simulated = lap.simulated_s + calibration_ticks(params) * params.dt_s  # the calibration turn came first
    c_s, c_lap = best(lambda: run_laps(twin, [{}], nthread=1, keep_traces=False, reuse_calibration=False)[0],
                      args.repeat)
    mcu_s, _ = best(lambda: mcu_only(twin, simulated), args.repeat)
    out = {
        "pil_lap_s": lap.lap_time_s, "c_lap_s": c_lap.lap_time_s,
        "lap_time_difference": (lap.lap_time_s - c_lap.lap_time_s) / c_lap.lap_time_s,
        "simulated_s": simulated, "pil_cpu_s": pil_s, "c_cpu_s": c_s, "mcu_only_cpu_s": mcu_s,
        "pil_real_time_factor": simulated / pil_s, "c_real_time_factor": simulated / c_s,
        "pil_vs_c": pil_s / c_s, "simavr_share": mcu_s / pil_s,
        "busy_cycles_mean": report.busy_cycles_mean, "busy_cycles_max": report.busy_cycles_max,
        "headroom": report.headroom,
    }
    if args.json:
        print(json.dumps(out))
        return
    print(f"lap: firmware on the MCU {lap.lap_time_s:.3f} s, C callback {c_lap.lap_time_s:.3f} s "
          f"({out['lap_time_difference'] * 100:+.2f} %)")
    print(f"{simulated:.2f} s simulated (turn + lap), CPU seconds on one thread, best of {args.repeat}:")
    print(f"  PIL lap   {pil_s:6.2f} s   {out['pil_real_time_factor']:6.1f}× real time   (target ≥ 1×)")
    print(f"  C lap     {c_s:6.2f} s   {out['c_real_time_factor']:6.1f}× real time   (PIL costs {out['pil_vs_c']:.1f}× the C lap)")
    print(f"  MCU only  {mcu_s:6.2f} s   ({out['simavr_share'] * 100:.0f} % of the PIL lap is simavr)")
    print(f"MCU: busy {report.busy_cycles_mean:.0f} cycles per 5 ms tick on average, {report.busy_cycles_max} at most, "
          f"of {report.period_cycles}: headroom {report.headroom * 100:.1f} %")


if __name__ == "__main__":
    main()
