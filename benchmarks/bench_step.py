"""Raw physics throughput of the default robot on the default track: the ceiling for the closed loop.

Measured in one run (shared machines are noisy; compare the ratios):
  * serial:  a Python loop calling mujoco.mj_step on one MjData
  * batch-1: mujoco.batch.Batch with 1 thread (stepping in C, no Python per step)
  * batch-N: mujoco.batch.Batch on all cores
  * laps:    ``--laps`` closed-loop laps (calibration + lap, no trace kept) in one ``run_laps`` batch on 2 threads
             against 1: wall time of each
The robot drives on both motors (3 V) so wheel contacts are active throughout.

  python benchmarks/bench_step.py [--seconds 2] [--nsim 16] [--laps 16] [--quick] [--json]

``--quick``: 0.05 simulated seconds, 2 simulations, 2 laps (for CI: the script cannot rot).
"""

from __future__ import annotations

import argparse
import json
import os
import time

import mujoco
import mujoco.batch
import numpy as np

from mjcf.world import MOTORS
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin


def serial_rate(model: mujoco.MjModel, nstep: int) -> float:
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("start").id)
    data.ctrl[[model.actuator(n).id for n in MOTORS]] = 3.0
    t0 = time.perf_counter()
    for _ in range(nstep):
        mujoco.mj_step(model, data)
    return nstep / (time.perf_counter() - t0)


def batch_rate(model: mujoco.MjModel, nsim: int, nthread: int, nstep: int) -> float:
    batch = mujoco.batch.Batch(model, nsim=nsim, nthread=nthread)
    batch.reset(keyframe=np.full(nsim, model.key("start").id))
    batch.ctrl[:] = 3.0
    batch.step(nstep=10)  # warm up the pool
    t0 = time.perf_counter()
    batch.step(nstep=nstep)
    return nsim * nstep / (time.perf_counter() - t0)


def laps_wall(twin: DigitalTwin, laps: int, nthread: int) -> float:
    """Wall seconds of ``laps`` laps in one batch on ``nthread`` threads (calibration simulated, not reused)."""
    t0 = time.perf_counter()
    run_laps(twin, [{}] * laps, seed=list(range(laps)), nthread=nthread, keep_traces=False, reuse_calibration=False)
    return time.perf_counter() - t0


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, default=2.0, help="simulated seconds per simulation")
    p.add_argument("--nsim", type=int, default=16, help="simulations in each batch")
    p.add_argument("--laps", type=int, default=16, help="laps in the run_laps batch (2 threads against 1)")
    p.add_argument("--quick", action="store_true", help="0.05 s, 2 simulations, 2 laps (for CI)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    args = p.parse_args()
    if args.quick:
        args.seconds, args.nsim, args.laps = 0.05, 2, 2
    twin = DigitalTwin()
    model = twin.model()
    nstep = int(args.seconds / model.opt.timestep)
    cores = os.cpu_count() or 1
    serial = serial_rate(model, nstep)
    one = batch_rate(model, args.nsim, 1, nstep)
    many = batch_rate(model, args.nsim, 0, nstep)
    laps_1 = laps_wall(twin, args.laps, 1)
    laps_2 = laps_wall(twin, args.laps, 2)
    out = {
        "timestep_s": model.opt.timestep,
        "cores": cores,
        "serial_steps_per_s": serial,
        "batch_1thread_steps_per_s": one,
        "batch_all_cores_steps_per_s": many,
        "us_per_step_1thread": 1e6 / one,
        "realtime_factor_1thread": one * model.opt.timestep,
        "ratio_batch1_over_serial": one / serial,
        "ratio_allcores_over_1thread": many / one,
        "laps": args.laps, "laps_1thread_wall_s": laps_1, "laps_2threads_wall_s": laps_2,
        "ratio_laps_1thread_over_2threads": laps_1 / laps_2,
    }
    if args.json:
        print(json.dumps(out))
        return
    print(f"default robot on default track, timestep {model.opt.timestep * 1e3:g} ms, {cores} cores")
    print(f"  serial Python loop : {serial:10.0f} steps/s")
    print(f"  batch, 1 thread    : {one:10.0f} steps/s  ({1e6 / one:.1f} µs/step, {one * model.opt.timestep:.0f}× real time)")
    print(f"  batch, all cores   : {many:10.0f} steps/s  ({many / one:.2f}× one thread)")
    print(f"  batch-1 / serial   : {one / serial:.2f}")
    print(f"  {args.laps} laps batched (run_laps): 2 threads {laps_2:.1f} s, 1 thread {laps_1:.1f} s wall "
          f"({laps_1 / laps_2:.2f}×)")


if __name__ == "__main__":
    main()
