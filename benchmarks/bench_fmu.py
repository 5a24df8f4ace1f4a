"""The twin's FMUs in fmpy, on one core: the closed-loop FMU against real time and against ``lap``, the plant FMU,
and a controller FMU in the twin's own loop (``lap --controller-fmu``).

Measured in one run on the default robot and track, pinned to one core, in CPU seconds of the process
(``time.process_time``; wall time on a shared machine swings widely), best of ``--repeat``:
  * closed-loop FMU: ``fmpy.simulate_fmu`` from instantiation (the model loaded from the FMU, the calibration turn
    during initialisation) to a stop time just past the lap, outputs recorded every control period (5 ms), and
    every 50 ms; the FMU's lap time against ``lap``'s (same seed)
  * ``lap``: ``run_laps`` on one thread, calibration simulated (not reused), the same turn and lap
  * plant FMU: equal voltages from fmpy's input table, 5 s at a 5 ms step
  * controller FMU in the twin's loop: the firmware's control law compiled as an FMI 2 controller (the tests' FMU),
    driving the same lap through fmpy from the twin's Python loop; also in wall time, as a user meets it, the
    controller behind its wall (its own process): ``python -m twin.run lap --controller-fmu C.fmu --seed 3`` in a
    fresh process (median of ``--repeat``), and ``run_controller_lap`` 6 times in one process (the first lap,
    then the median of the later ones: each a fresh instance in the same controller process)
Target: the closed-loop FMU in fmpy ≥ 50× real time.

  python benchmarks/bench_fmu.py [--repeat 3] [--quick] [--json]

``--quick``: one run of each, 2 laps in one process (for CI: the script cannot rot).
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
from fmpy import extract, read_model_description, simulate_fmu

from twin.core import DigitalTwin, run_laps
from twin.fmi import CLOSED_LOOP, PLANT, ControllerFmu, export_fmu, run_controller_lap
from twin.model.control import calibration_ticks

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
from fmu_helpers import build_controller  # noqa: E402  (the tests' controller FMU, built from C)


def _cpu() -> float:
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


WALL: dict[str, float] = {}  # least wall seconds of each timed call, by name (reported beside the CPU figures)


def best(fn, repeat: int, name: str = ""):
    """(least CPU seconds, last result) of ``repeat`` calls, garbage collector off; the least wall time goes to
    ``WALL[name]``. CPU seconds count this process and its ended children (a controller FMU's own process)."""
    times, walls, out = [], [], None
    for _ in range(repeat):
        gc.collect()
        gc.disable()
        t0, w0 = _cpu(), time.perf_counter()
        try:
            out = fn()
        finally:
            gc.enable()
        times.append(_cpu() - t0)
        walls.append(time.perf_counter() - w0)
    WALL[name] = min(walls)
    return min(times), out


def controller_walls(twin: DigitalTwin, controller: ControllerFmu, path: str, repeat: int, in_process: int) -> dict:
    """Wall seconds of a controller FMU's laps, as a user meets them: ``lap --controller-fmu`` in a fresh process
    (median of ``repeat``), and ``in_process`` laps of ``run_controller_lap`` in this one (the first, and the median
    of the rest)."""
    cli = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "twin.run", "lap", "--controller-fmu", path, "--seed", "3"],
                       check=True, capture_output=True, timeout=600)
        cli.append(time.perf_counter() - t0)
    laps = []
    for _ in range(in_process):
        t0 = time.perf_counter()
        run_controller_lap(twin, controller, seed=3, keep_trace=False)
        laps.append(time.perf_counter() - t0)
    return {"cli_wall_s": statistics.median(cli), "first_lap_wall_s": laps[0],
            "later_laps_wall_s": statistics.median(laps[1:]) if len(laps) > 1 else None}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="one run of each (for CI)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    in_process = 6
    if args.quick:
        args.repeat, in_process = 1, 2
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core
    twin = DigitalTwin(track="default")
    params = twin.control_params()
    turn_s = (calibration_ticks(params) + 2) * params.dt_s
    with tempfile.TemporaryDirectory() as work:
        t0 = time.perf_counter()
        closed = export_fmu(twin, os.path.join(work, "closed.fmu"), CLOSED_LOOP, 2)
        export_wall = time.perf_counter() - t0
        plant = export_fmu(twin, os.path.join(work, "plant.fmu"), PLANT, 2)
        controller_path = build_controller(twin, os.path.join(work, "controller.fmu"))
        walls = controller_walls(twin, ControllerFmu(controller_path, None, params.count, params.dt_s),
                                 controller_path, args.repeat, in_process)
        controller = ControllerFmu(controller_path, None, params.count, params.dt_s)
        closed_dir, plant_dir = extract(closed.path), extract(plant.path)
        closed_md, plant_md = read_model_description(closed_dir), read_model_description(plant_dir)
        c_s, c_lap = best(lambda: run_laps(twin, [{}], nthread=1, keep_traces=False, reuse_calibration=False)[0],
                          args.repeat)
        stop = float(np.ceil(c_lap.lap_time_s)) + 0.5

        def closed_run(interval):
            return simulate_fmu(closed_dir, stop_time=stop, output_interval=interval, model_description=closed_md,
                                output=["lap_time", "lap_completed"])

        fmu_s, r = best(lambda: closed_run(params.dt_s), args.repeat, "fmu")
        coarse_s, _ = best(lambda: closed_run(0.05), args.repeat)
        volts = np.array([(0.0, 3.0, 3.0), (5.0, 3.0, 3.0)],
                         dtype=[("time", float), ("voltage_left", float), ("voltage_right", float)])
        plant_s, _ = best(lambda: simulate_fmu(plant_dir, stop_time=5.0, output_interval=params.dt_s, input=volts,
                                               model_description=plant_md, output=["pose.x"]), args.repeat)
        ctl_s, ctl_lap = best(lambda: run_controller_lap(twin, controller, keep_trace=False), args.repeat)
    fmu_lap = float(r["lap_time"][-1])
    simulated = stop + turn_s  # the FMU also simulates the calibration turn, during initialisation
    lap_simulated = c_lap.lap_time_s + turn_s
    out = {
        "lap_time_s": c_lap.lap_time_s, "fmu_lap_time_s": fmu_lap,
        "fmu_lap_time_difference": (fmu_lap - c_lap.lap_time_s) / c_lap.lap_time_s,
        "controller_fmu_lap_time_s": ctl_lap.lap_time_s, "export_wall_s": export_wall,
        "fmu_cpu_s": fmu_s, "fmu_real_time_factor": simulated / fmu_s,
        "fmu_50ms_cpu_s": coarse_s, "fmu_50ms_real_time_factor": simulated / coarse_s,
        "lap_cpu_s": c_s, "lap_real_time_factor": lap_simulated / c_s,
        "fmu_vs_lap": (fmu_s / simulated) / (c_s / lap_simulated),
        "plant_cpu_s": plant_s, "plant_real_time_factor": (5.0 + turn_s) / plant_s,
        "controller_fmu_cpu_s": ctl_s, "controller_fmu_real_time_factor": lap_simulated / ctl_s,
        "controller_fmu_vs_lap": ctl_s / c_s,  # the same turn and lap
        "controller_fmu_walls": walls,
        "fmu_wall_s": WALL["fmu"], "fmu_wall_real_time_factor": simulated / WALL["fmu"], "load_average": os.getloadavg()[0], "fmu_size_bytes": closed.size_bytes,
    }
    if args.json:
        print(json.dumps(out))
        return
    print(f"lap: {c_lap.lap_time_s:.6f} s; closed-loop FMU in fmpy {fmu_lap:.6f} s "
          f"({out['fmu_lap_time_difference'] * 100:+.2g} %); controller FMU in the twin {ctl_lap.lap_time_s:.6f} s")
    print(f"export: {export_wall:.1f} s wall (build, compile, zip); FMU {closed.size_bytes / 1e6:.1f} MB")
    print(f"CPU seconds on one core, best of {args.repeat} (the calibration turn, {turn_s:.2f} s, counts as simulated):")
    print(f"  closed-loop FMU, outputs every {params.dt_s * 1000:g} ms  {fmu_s:6.3f} s for {simulated:.2f} s "
          f"{out['fmu_real_time_factor']:7.1f}× real time   (target ≥ 50×); wall {WALL['fmu']:.3f} s, "
          f"{out['fmu_wall_real_time_factor']:.1f}× at load average {out['load_average']:.1f}")
    print(f"  closed-loop FMU, outputs every 50 ms   {coarse_s:6.3f} s for {simulated:.2f} s "
          f"{out['fmu_50ms_real_time_factor']:7.1f}× real time")
    print(f"  lap (run_laps, 1 thread)               {c_s:6.3f} s for {lap_simulated:.2f} s "
          f"{out['lap_real_time_factor']:7.1f}× real time   (a simulated second in the FMU costs {out['fmu_vs_lap']:.2f}× one in the lap)")
    print(f"  plant FMU, 3 V each side, 5 ms steps   {plant_s:6.3f} s for {5.0 + turn_s:.2f} s "
          f"{out['plant_real_time_factor']:7.1f}× real time")
    print(f"  controller FMU in the twin's loop      {ctl_s:6.3f} s for {lap_simulated:.2f} s "
          f"{out['controller_fmu_real_time_factor']:7.1f}× real time   ({out['controller_fmu_vs_lap']:.2f}× the lap)")
    later = walls["later_laps_wall_s"]
    print(f"controller FMU behind its wall, wall time (seed 3): lap --controller-fmu {walls['cli_wall_s']:.2f} s "
          f"(median of {args.repeat}); in one process: first lap {walls['first_lap_wall_s']:.2f} s, later laps "
          + (f"{later:.2f} s (median of {in_process - 1})" if later is not None else "—"))


if __name__ == "__main__":
    main()
