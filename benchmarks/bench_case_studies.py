"""Wall time of the case studies on this machine, measured in one run:

  * one alignment to a measured lap time (default robot with the gains ``tune`` answers today, hidden μ = 0.9,
    default track)
  * one alignment to a recorded run (oval, hidden R_M and K, two parameters)
  * the default design study (cad.L × cad.S, 3 × 3 designs, 20 laps each) — the long one; --no-design skips it

  python benchmarks/bench_case_studies.py [--no-design] [--quick] [--json]

``--quick``: gains tuned for one iteration, each alignment stopped after 2 iterations (the lap time's on one noise
seed, the recorded run's of R_M alone), a study of 2 designs × 2 laps tuned for one iteration (for CI: the script
cannot rot; the figures are not the table's).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.telemetry.jsonl import lap_lines, read_telemetry, write_telemetry
from tuner.align.lap_time import align_lap_time
from tuner.align.trace import align_telemetry
from tuner.studies.design import DEFAULT_GRID, grid, study

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
from reference_gains import tuned_gains  # noqa: E402  (the one home of tuned gains)

# deliberately arbitrary, not tuned: moderate gains that lap the oval well inside its limits, so the recorded run
# depends on the motor (R_M, K) and not on the edge of grip
MODERATE = {"control.v_max": 1.0, "control.kb": 0.3, "control.kp": 25.0, "control.kd": 0.5}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--no-design", action="store_true", help="skip the design study")
    ap.add_argument("--quick", action="store_true",
                    help="one tuning iteration, 2 alignment iterations, 2 designs (for CI)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    out = {"cores": os.cpu_count()}
    iterations = {"max_iter": 2} if args.quick else {}

    t = DigitalTwin()
    t.update(tuned_gains(*(["--max-iter", "1"] if args.quick else [])))
    measured = run_laps(t, [{"motion.mu": 0.9}], seed=0)[0].lap_time_s
    t0 = time.perf_counter()
    r = align_lap_time(t, measured, **iterations, **({"noise_seeds": 1} if args.quick else {}))
    out["align_lap_time"] = {"wall_s": time.perf_counter() - t0, "laps": r.laps, "value": r.value, "hidden": 0.9}

    o = DigitalTwin(track="oval")
    o.update(MODERATE)
    hidden = {"motor.R_M": 10.0, "motor.K": o.space.get("motor.K") * 1.08}
    if args.quick:  # one parameter: the same fit, a fraction of its profile scans
        del hidden["motor.K"]
    lap = run_laps(o, [hidden], seed=7)[0]
    path = os.path.join(tempfile.mkdtemp(), "lap.jsonl")
    write_telemetry(path, lap_lines(lap, {"track": "oval", "sensors": 8, "dt_s": 0.005, "gains": MODERATE}, 2))
    t0 = time.perf_counter()
    a = align_telemetry(o, read_telemetry(path), list(hidden), **iterations)
    out["align_telemetry"] = {"wall_s": time.perf_counter() - t0, "laps": a.laps,
                              "recovered": {p.address: p.value for p in a.parameters}, "hidden": hidden}
    if not args.no_design:
        t0 = time.perf_counter()
        designs = grid({"cad.S": (0.04, 0.06)} if args.quick else DEFAULT_GRID)
        rs = study(designs, {"track": "default", "metres_per_pixel": None, "values": {}},
                   **({"laps": 2, "max_iter": 1} if args.quick else {"laps": 20}))
        out["design_study"] = {"wall_s": time.perf_counter() - t0, "designs": len(rs),
                               "ok": sum(r.ok for r in rs)}
    if args.json:
        print(json.dumps(out))
        return
    print(f"{out['cores']} cores")
    x = out["align_lap_time"]
    print(f"  align to a lap time      : {x['wall_s']:6.1f} s, {x['laps']} laps (μ {x['value']:.4f}, hidden 0.9)")
    x = out["align_telemetry"]
    rec = ", ".join(f"{k} {v:.4g} (hidden {hidden[k]:.4g})" for k, v in x["recovered"].items())
    print(f"  align to a recorded run  : {x['wall_s']:6.1f} s, {x['laps']} laps ({rec})")
    if "design_study" in out:
        x = out["design_study"]
        print(f"  default design study     : {x['wall_s']:6.1f} s for {x['designs']} designs ({x['ok']} built)")


if __name__ == "__main__":
    main()
