"""Wall time and coverage of the case studies on this machine, measured in one run:

  * one alignment to a measured lap time (default robot with the gains ``tune`` answers today, default track; the
    robot hides μ = 0.7, dusty tyres inside the documented range where those gains still finish, and runs on its
    own noise seed, 1000; with the caster's drag the value before, 0.62, no longer finishes a lap to align to)
  * one alignment to a recorded run (oval, hidden R_M and K, two parameters)
  * the coverage study (tuner.studies.coverage): robots on the oval with the tuned gains, each hiding μ, the battery
    voltage or the winding resistance drawn across its documented range, on its own noise seed; how often the
    interval that align --measured-lap-time, diagnose and align --telemetry state holds the hidden value (with
    Wilson's 95 % interval of that proportion), and the laps and CPU it took
  * the default design study (cad.L × cad.S, 3 × 3 designs, 20 laps each) — the long one; --no-design skips it

  python benchmarks/bench_case_studies.py [--no-design] [--trials N] [--quick] [--json]

``--trials N``: robots per procedure in the coverage study (default 30; 0 skips it). ``--quick``: the same gains
(tuned once per code by tests/reference_gains.py, whose answer the tests' run shares), each alignment stopped after
2 iterations (the lap time's on one noise seed, the recorded run's of R_M alone), 1 robot per procedure, a study of
2 designs × 2 laps tuned for one iteration (for CI: the script cannot rot; the figures are not the table's).
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
from tuner.studies.coverage import PROCEDURES, ROBOT_SEED0, coverage, run_study, wilson
from tuner.studies.design import DEFAULT_GRID, grid, study

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
from reference_gains import tuned_gains  # noqa: E402  (the one home of tuned gains)

# deliberately arbitrary, not tuned: moderate gains that lap the oval well inside its limits, so the recorded run
# depends on the motor (R_M, K) and not on the edge of grip
MODERATE = {"control.v_max": 1.0, "control.kb": 0.3, "control.kp": 25.0, "control.kd": 0.5}


HIDDEN_MU = 0.7  # the lap-time case's robot: dusty tyres (documented range 0.3–1.2), on its own seed
COVERAGE_ADDRESSES = ("motion.mu", "motor.supply_voltage", "motor.R_M")


def coverage_study(gains: dict, per_procedure: int) -> dict:
    """The coverage study: ``per_procedure`` robots that finish for each procedure, in two worker processes."""
    t0 = time.perf_counter()
    done = run_study("oval", gains, PROCEDURES, per_procedure, COVERAGE_ADDRESSES, 2026)
    out = {"wall_s": time.perf_counter() - t0, "robots_drawn": done.robots_drawn,
           "robots_finished": done.robots_finished, "procedures": {}}
    for p in PROCEDURES:
        mine = [t for t in done.trials if t.procedure == p]
        covered, n = coverage(mine)
        out["procedures"][p] = {
            "covered": covered, "trials": n, "wilson95": wilson(covered, n),
            "intervals": sum(t.kind == "ci95" for t in mine), "sets": sum(t.kind == "consistent" for t in mine),
            "unexplained": sum(t.kind == "none" for t in mine), "laps": sum(t.laps for t in mine),
            "cpu_s": sum(t.cpu_s for t in mine), "misses": [t.row() for t in mine if not t.covered]}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--no-design", action="store_true", help="skip the design study")
    ap.add_argument("--quick", action="store_true",
                    help="2 alignment iterations, 1 robot per procedure, 2 designs (for CI)")
    ap.add_argument("--trials", type=int, default=30, help="robots per procedure in the coverage study (default 30)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    out = {"cores": os.cpu_count()}
    iterations = {"max_iter": 2} if args.quick else {}

    gains = tuned_gains()
    t = DigitalTwin()
    t.update(gains)
    measured = run_laps(t, [{"motion.mu": HIDDEN_MU}], seed=ROBOT_SEED0)[0].lap_time_s
    if measured is None:
        raise SystemExit(f"bench_case_studies: the robot hiding μ {HIDDEN_MU} does not finish its lap with the tuned "
                         "gains: nothing to align to")
    t0 = time.perf_counter()
    r = align_lap_time(t, measured, **iterations, **({"noise_seeds": 1} if args.quick else {}))
    out["align_lap_time"] = {"wall_s": time.perf_counter() - t0, "laps": r.laps, "value": r.value,
                             "ci95": r.ci95, "consistent": r.consistent, "hidden": HIDDEN_MU}

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
    trials = 1 if args.quick else args.trials
    if trials > 0:
        out["coverage"] = coverage_study(gains, trials)
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
    stated = x["ci95"] or x["consistent"]
    shown = f"[{stated[0]:.4f}, {stated[1]:.4f}]" if stated else "none"
    value = f"{x['value']:.4f}" if x["value"] is not None else "none"
    print(f"  align to a lap time      : {x['wall_s']:6.1f} s, {x['laps']} laps (μ {value}, "
          f"{'95 % interval' if x['ci95'] else 'consistent set'} {shown}; hidden {HIDDEN_MU})")
    x = out["align_telemetry"]
    rec = ", ".join(f"{k} {v:.4g} (hidden {hidden[k]:.4g})" for k, v in x["recovered"].items())
    print(f"  align to a recorded run  : {x['wall_s']:6.1f} s, {x['laps']} laps ({rec})")
    if "coverage" in out:
        x = out["coverage"]
        print(f"  coverage study           : {x['wall_s']:6.1f} s wall; {x['robots_finished']} of "
              f"{x['robots_drawn']} robots drawn finished their lap")
        for p, c in x["procedures"].items():
            lo, hi = c["wilson95"]
            print(f"    {p:10s}: {c['covered']:3d} of {c['trials']:3d} covered ({100 * c['covered'] / max(c['trials'], 1):.0f} %,"
                  f" Wilson 95 % [{100 * lo:.0f}, {100 * hi:.0f}] %); {c['intervals']} intervals, {c['sets']} "
                  f"consistent sets, {c['unexplained']} unexplained; {c['laps']} laps, {c['cpu_s']:.0f} s CPU")
    if "design_study" in out:
        x = out["design_study"]
        print(f"  default design study     : {x['wall_s']:6.1f} s for {x['designs']} designs ({x['ok']} built)")


if __name__ == "__main__":
    main()
