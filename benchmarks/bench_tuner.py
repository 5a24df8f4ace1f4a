"""The learning model's figures, measured in one run on the default robot and track from the default gains:

  * a full default tuning run (``python -m tuner`` defaults, batched): wall time (target < 60 s on 2 cores)
  * batched versus the paper's sequential procedure, same step and stopping rules: final lap time, laps,
    wall time (target: same or better lap time in at least 5× less wall time)
  * the tuned lap time against an independent global search: CMA-ES (``cma``), its populations evaluated as
    batches of laps over the same five gains, bounds and objective (target: within 3 %)

  pip install -e '.[bench]'   # cma
  python benchmarks/bench_tuner.py [--cma-evals 600] [--json]
"""

from __future__ import annotations

import argparse
import json
import logging
import time
import warnings

import numpy as np

from tuner.gradient import DescentOptions, descend, sequential
from tuner.objective import LapObjective
from tuner.space import SearchSpace
from twin.digital_twin import DigitalTwin


def tune(method, twin: DigitalTwin) -> dict:
    space = SearchSpace(twin.space)
    objective = LapObjective(twin, space, seed=0)
    t0 = time.perf_counter()
    r = method(objective, space.to_unit(space.start(twin.space)), DescentOptions())
    wall = time.perf_counter() - t0
    return {"lap_time_s": objective.best.lap.lap_time_s, "cost_s": objective.best.cost, "laps": objective.laps,
            "iterations": len(r.iterations), "wall_s": wall, "converged": r.converged,
            "gains": space.assignments(objective.best.x)}


def cma_search(twin: DigitalTwin, max_evals: int, seed: int = 1) -> dict:
    import cma

    space = SearchSpace(twin.space)
    objective = LapObjective(twin, space, seed=0)
    t0 = time.perf_counter()
    es = cma.CMAEvolutionStrategy(space.to_unit(space.start(twin.space)), 0.3,
                                  {"bounds": [0, 1], "popsize": 12, "seed": seed, "verbose": -9,
                                   "maxfevals": max_evals})
    while not es.stop():
        z = np.array(es.ask())
        es.tell(list(z), list(objective(z)))  # one population = one batch of laps
    return {"lap_time_s": objective.best.lap.lap_time_s, "cost_s": objective.best.cost, "laps": objective.laps,
            "wall_s": time.perf_counter() - t0, "gains": space.assignments(objective.best.x)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cma-evals", type=int, default=600, help="laps the CMA-ES search may use")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args()
    logging.disable(logging.WARNING)
    warnings.filterwarnings("ignore")
    twin = DigitalTwin()
    twin.model()
    batch = tune(descend, twin)
    seq = tune(sequential, twin)
    glob = cma_search(twin, args.cma_evals)
    out = {
        "batch": batch, "sequential": seq, "cma_es": glob,
        "ratio_wall_sequential_over_batch": seq["wall_s"] / batch["wall_s"],
        "batch_over_global_lap_time": batch["cost_s"] / glob["cost_s"],
    }
    if args.json:
        print(json.dumps(out))
        return
    print("default robot, default track, from the default gains (13.17 s), seed 0")
    for name, r in (("batched", batch), ("sequential", seq)):
        print(f"  {name:11s}: {r['lap_time_s']:.3f} s after {r['iterations']} iterations, {r['laps']} laps, "
              f"{r['wall_s']:.1f} s wall{'' if r['converged'] else ' (not converged)'}")
    print(f"  CMA-ES     : {glob['lap_time_s']:.3f} s after {glob['laps']} laps, {glob['wall_s']:.1f} s wall")
    print(f"  full default tuning run: {batch['wall_s']:.1f} s (target < 60 s)")
    print(f"  sequential / batched wall time: {out['ratio_wall_sequential_over_batch']:.2f}× (target ≥ 5×); "
          f"lap time {batch['lap_time_s']:.3f} vs {seq['lap_time_s']:.3f} s")
    print(f"  batched / CMA-ES lap time: {out['batch_over_global_lap_time']:.3f} (target ≤ 1.03)")


if __name__ == "__main__":
    main()
