"""Design-study throughput, measured in one run, and the cost model it checks:

  * designs per hour with 1 and 2 local worker processes, and with a local Ray head of 1 and 2 CPUs;
  * Ray's overhead per design: on 1 CPU, the study's wall time minus the designs' own work, per design
    (scheduling, a worker's start and imports, moving the result);
  * the cost model  T(N, M, C) = ⌈N / (M·C)⌉ · (t_design + t_task) + t_start,  with t_design the mean wall time
    of one design on one core (from the 1-worker run), t_task Ray's overhead per design, paid inside each wave
    because workers start and import in parallel, and t_start the cluster's start-up; its prediction for the
    2-CPU run against the measurement, and what ``--predict N`` designs cost on 10 machines of 16 cores, with
    the bound if the overhead were all the driver's, one design after another (+ N · t_task).

  python benchmarks/bench_cluster.py [--designs 4] [--laps 2] [--max-iter 3] [--no-ray] [--quick] [--json]

``--quick``: 2 designs, 1 lap, 1 iteration each (for CI: the script cannot rot; Ray's heads still start).

Designs are independent, so the model is linear in ⌈N/(M·C)⌉ waves. It assumes equal designs: tuning
converges in different numbers of iterations, so a wave lasts as long as its slowest design and the model is
optimistic by the spread of t_design (reported as its coefficient of variation).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import tempfile
import time

import numpy as np

from tuner.studies.design import grid, study

BASE = {"track": "oval", "metres_per_pixel": None, "values": {}}


def designs(n: int) -> list[dict]:
    return grid({"cad.S": tuple(np.round(np.linspace(0.04, 0.08, n), 4))})


def local(n: int, workers: int, laps: int, max_iter: int) -> tuple[float, list]:
    t0 = time.perf_counter()
    results = study(designs(n), BASE, laps=laps, max_iter=max_iter, workers=workers)
    return time.perf_counter() - t0, results


def on_ray(n: int, cpus: int, laps: int, max_iter: int) -> tuple[float, float, list]:
    """(study wall time, head start-up time, results) on a fresh local Ray head with ``cpus`` CPUs."""
    import ray

    from tuner.studies.cluster import local_head, study_on_ray, wait_for_cluster

    with tempfile.TemporaryDirectory(prefix="ray") as temp:
        t0 = time.perf_counter()
        with local_head(cpus, temp):
            ray.init(address="auto", log_to_driver=False)
            try:
                wait_for_cluster(ray, cpus)
                start = time.perf_counter() - t0
                t1 = time.perf_counter()
                results = study_on_ray(designs(n), BASE, laps, max_iter, "auto")
                wall = time.perf_counter() - t1
            finally:
                ray.shutdown()
    return wall, start, results


def model(n: int, machines: int, cores: int, t_design: float, t_task: float, t_start: float) -> float:
    return math.ceil(n / (machines * cores)) * (t_design + t_task) + t_start


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--designs", type=int, default=4)
    ap.add_argument("--laps", type=int, default=2)
    ap.add_argument("--max-iter", type=int, default=3)
    ap.add_argument("--predict", type=int, default=1000, help="designs in the study the model prices")
    ap.add_argument("--no-ray", action="store_true")
    ap.add_argument("--quick", action="store_true", help="2 designs, 1 lap, 1 iteration each (for CI)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if args.quick:
        args.designs, args.laps, args.max_iter = 2, 1, 1
    n, out = args.designs, {"cores": os.cpu_count(), "designs": args.designs}

    w1, r1 = local(n, 1, args.laps, args.max_iter)
    per = np.array([r.wall_s for r in r1])
    t_design = float(per.mean())
    out["local_1"] = {"wall_s": w1, "designs_per_hour": 3600 * n / w1, "t_design_s": t_design,
                      "t_design_cv": float(per.std() / per.mean())}
    w2, _ = local(n, 2, args.laps, args.max_iter)
    out["local_2"] = {"wall_s": w2, "designs_per_hour": 3600 * n / w2, "speedup": w1 / w2}
    if not args.no_ray:
        rw1, start1, g1 = on_ray(n, 1, args.laps, args.max_iter)
        rw2, start2, g2 = on_ray(n, 2, args.laps, args.max_iter)
        same = all((a.gains, a.lap_times_s) == (b.gains, b.lap_times_s) for a, b in zip(r1, g2))
        t_task = max(0.0, (rw1 - float(sum(r.wall_s for r in g1))) / n)  # 1 CPU: the chain is every design
        predicted = model(n, 1, 2, t_design, t_task, 0.0)
        out["ray_1"] = {"wall_s": rw1, "start_s": start1, "designs_per_hour": 3600 * n / rw1}
        out["ray_2"] = {"wall_s": rw2, "start_s": start2, "designs_per_hour": 3600 * n / rw2, "speedup": rw1 / rw2,
                        "equal_to_local": same}
        big = model(args.predict, 10, 16, t_design, t_task, start2)
        out["model"] = {"t_design_s": t_design, "t_task_s": t_task, "t_start_s": start2,
                        "predicted_ray_2_s": predicted, "measured_ray_2_s": rw2, "error": rw2 / predicted - 1,
                        f"predicted_{args.predict}_designs_10x16_s": big,
                        f"bound_{args.predict}_designs_10x16_s": big + args.predict * t_task}
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"{n} designs (oval, {args.laps} laps, ≤ {args.max_iter} iterations each), {out['cores']} cores")
    print(f"  local, 1 worker : {w1:6.1f} s  {out['local_1']['designs_per_hour']:7.0f} designs/h  "
          f"(t_design {t_design:.2f} s, CV {out['local_1']['t_design_cv']:.0%})")
    print(f"  local, 2 workers: {w2:6.1f} s  {out['local_2']['designs_per_hour']:7.0f} designs/h  ×{w1 / w2:.2f}")
    if not args.no_ray:
        m = out["model"]
        print(f"  Ray, 1 CPU      : {rw1:6.1f} s  {out['ray_1']['designs_per_hour']:7.0f} designs/h  (head start {start1:.1f} s)")
        print(f"  Ray, 2 CPUs     : {rw2:6.1f} s  {out['ray_2']['designs_per_hour']:7.0f} designs/h  ×{rw1 / rw2:.2f}, "
              f"equal to local: {same}")
        print(f"  Ray overhead    : {m['t_task_s'] * 1000:.0f} ms per design")
        print(f"  model, 2 CPUs   : predicted {m['predicted_ray_2_s']:.1f} s, measured {rw2:.1f} s ({m['error']:+.0%})")
        key, bound = f"predicted_{args.predict}_designs_10x16_s", f"bound_{args.predict}_designs_10x16_s"
        print(f"  model: {args.predict} designs on 10 machines × 16 cores ≈ {m[key]:.0f} s "
              f"(⌈{args.predict}/160⌉ = {math.ceil(args.predict / 160)} waves of {t_design + m['t_task_s']:.1f} s); "
              f"at most {m[bound]:.0f} s if the overhead were serial")


if __name__ == "__main__":
    main()
