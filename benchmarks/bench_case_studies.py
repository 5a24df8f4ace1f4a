"""Wall time of the case studies on this machine, measured in one run:

  * one alignment to a measured lap time (default robot with tuned gains, hidden μ = 0.9, default track)
  * one alignment to a recorded run (oval, hidden R_M and K, two parameters)
  * the default design study (cad.L × cad.S, 3 × 3 designs, 20 laps each) — the long one; --no-design skips it

  python benchmarks/bench_case_studies.py [--no-design] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time

from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.telemetry.jsonl import lap_lines, read_telemetry, write_telemetry
from tuner.align.lap_time import align_lap_time
from tuner.align.trace import align_telemetry
from tuner.studies.design import DEFAULT_GRID, grid, study

FAST = {"control.v_max": 1.5, "control.kb": 0.1247, "control.kp": 33.52, "control.ki": 0.0, "control.kd": 1.118}
MODERATE = {"control.v_max": 1.0, "control.kb": 0.3, "control.kp": 25.0, "control.kd": 0.5}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--no-design", action="store_true", help="skip the design study")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    out = {"cores": os.cpu_count()}

    t = DigitalTwin()
    t.update(FAST)
    measured = run_laps(t, [{"motion.mu": 0.9}], seed=0)[0].lap_time_s
    t0 = time.perf_counter()
    r = align_lap_time(t, measured)
    out["align_lap_time"] = {"wall_s": time.perf_counter() - t0, "laps": r.laps, "value": r.value, "hidden": 0.9}

    o = DigitalTwin(track="oval")
    o.update(MODERATE)
    hidden = {"motor.R_M": 10.0, "motor.K": o.space.get("motor.K") * 1.08}
    lap = run_laps(o, [hidden], seed=7)[0]
    path = os.path.join(tempfile.mkdtemp(), "lap.jsonl")
    write_telemetry(path, lap_lines(lap, {"track": "oval", "sensors": 8, "dt_s": 0.005, "gains": MODERATE}, 2))
    t0 = time.perf_counter()
    a = align_telemetry(o, read_telemetry(path), list(hidden))
    out["align_telemetry"] = {"wall_s": time.perf_counter() - t0, "laps": a.laps,
                              "recovered": {p.address: p.value for p in a.parameters}, "hidden": hidden}
    if not args.no_design:
        t0 = time.perf_counter()
        rs = study(grid(DEFAULT_GRID), {"track": "default", "metres_per_pixel": None, "values": {}}, laps=20)
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
