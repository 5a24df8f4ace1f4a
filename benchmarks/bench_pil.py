"""Processor in the loop against real time: the robot's ATmega328P binary in simavr, in lockstep with MuJoCo.

Measured in one run on the default robot and track (shared machines are noisy; compare the ratios):
  * PIL lap:  ``twin.pil.lap.run_pil_lap`` (power-up, the firmware's calibration turn, the lap), one thread: simulated
              seconds (turn + lap) per CPU second of that thread
  * C lap:    ``twin.core.closed_loop.run_laps`` on one thread, the same phases, for scale
  * MCU only: the firmware run free for the same simulated time with the physics attached but not stepped, to
              split the PIL lap's cost between simavr and MuJoCo
  * 3pi program: any 3pi program on the board model (``twin.pil.board.run_board_lap``) on the 3pi: a program that
              busy-waits on every delay and polls its sensors for their whole timeout, as libpololu-avr's do, from
              power-up (prompt, the operator's press) to the end of its lap on the default track. By default the
              register-level follower of tests/firmware/board3pi; ``--program FILE`` (ELF or HEX) runs another, e.g.
              Pololu's 3pi-linefollower built from libpololu-avr (README).
Timed in CPU time of the thread (``time.thread_time``) with the garbage collector off, best of --repeat.
Targets: the PIL lap at least real time on one core (ratio ≥ 1), a 3pi program's at least twice real time.

  python benchmarks/bench_pil.py [--repeat 3] [--program FILE] [--quick] [--json]

``--quick``: one run of each (for CI: the script cannot rot).
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import shutil
import subprocess
import tempfile
import time

import mujoco

from twin.pil import firmware as fw
from twin.pil import lap as pil
from twin.core.closed_loop import run_laps
from twin.model.control import calibration_ticks
from twin.core.digital_twin import DigitalTwin
from twin.pil.mcu import Mcu
from twin.core.variant import Variant
from twin.model.robots import THREE_PI, use_robot
from twin.pil.board import run_board_lap
from twin.pil.program import load_program

BOARD3PI = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests", "firmware", "board3pi")


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
        mcu.board(lap.params.count <= pil.BOARD_SENSORS, 6.0, pil.TRIMMER_V, 0)
        sim = pil.place_robot(model, data, twin, lap, 0)
        mujoco.mj_forward(model, data)  # the sensors' rays need the start pose's kinematics
        mcu.attach(model, data, sim, 1e9)
        mcu.run_cycles(int(simulated_s * fw.F_CPU_HZ))


def follower(folder: str) -> str:
    """The register-level follower of tests/firmware/board3pi, built with avr-gcc."""
    elf = os.path.join(folder, "follower.elf")
    subprocess.run([shutil.which("avr-gcc") or "avr-gcc", "-mmcu=atmega328p", "-DF_CPU=20000000UL", "-Os", "-o", elf,
                    os.path.join(BOARD3PI, "follower.c"), os.path.join(BOARD3PI, "board3pi.c")], check=True, timeout=300)
    return elf


def board_lap(path: str, repeat: int) -> dict:
    twin = DigitalTwin(track="default")
    use_robot(twin, THREE_PI)
    twin.model()
    program = load_program(path)
    cpu, (lap, report) = best(lambda: run_board_lap(twin, program, keep_trace=False), repeat)
    simulated = report.cycles / report.f_cpu_hz
    return {"program": path, "completed": lap.completed, "lap_s": lap.lap_time_s, "lap_start_s": report.lap_start_s,
            "simulated_s": simulated, "cpu_s": cpu, "real_time_factor": simulated / cpu}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--program", metavar="FILE", help="a 3pi program (ELF or HEX) for the board lap")
    ap.add_argument("--quick", action="store_true", help="one run of each (for CI)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if args.quick:
        args.repeat = 1
    with tempfile.TemporaryDirectory() as folder:
        board = board_lap(args.program or follower(folder), args.repeat)
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
        "headroom": report.headroom, "board": board,
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
    print(f"3pi program on the board ({os.path.basename(board['program'])}): lap "
          + (f"{board['lap_s']:.3f} s" if board["completed"] else "not completed")
          + f", {board['simulated_s']:.2f} s simulated from power-up in {board['cpu_s']:.2f} CPU s: "
          f"{board['real_time_factor']:.1f}× real time (target ≥ 2×)")


if __name__ == "__main__":
    main()
