"""A prognostics benchmark: ageing robots (``emulate --drift``, plainly tuned gains, each its own noise seed) watched
by plain ``live`` for scenario × seed, each robot run to its real first failed lap; then, from what ``live``
recorded (its alignments, stamped with the laps they measured, and the robot's laps), ``history``'s forecast
(:func:`tuner.history.forecast_failure`) made at several points of life, against the lap the robot first failed.

The metrics of the field (the definitions of Saxena et al. 2010, as ProgPy's ``progpy.metrics`` computes them;
written out here on plain numbers so the benchmark needs neither ProgPy's containers nor its import time):
  * coverage: how often the true remaining life (laps from the forecast to the first failed lap) lies in the
    stated 90 % interval (an open end counts as covering), with the interval's median width;
  * α-λ accuracy (α = 0.2, λ = 0.5): at the forecast nearest half of the life, is the median within ±20 % of the
    true remaining life?
  * prognostic horizon: the life left when the forecasts start, and stay, within ±α of the true end of life
    (α = 0.2 of the whole life), as a fraction of the life;
  * relative accuracy at λ = 0.5: 1 − |true − median|/true;
  * the forecast's wall time (a forecast must be ready within one lap at real time on 2 cores).

  python benchmarks/bench_forecast.py [--seeds 2] [--speed 10] [--scenario NAME ...] [--keep DIR] [--quick] [--json]

``--quick``: one robot of the linear scenario compressed to 10 laps, at 20× real time (for CI: the script cannot rot;
the figures are not the table's).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time

from tuner.history import forecast_failure, log_laps
from twin.core.digital_twin import DigitalTwin

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
from reference_gains import set_flags, tuned_gains  # noqa: E402  (the one home of tuned gains)

PLAIN: dict[str, float] = {}  # the gains ``tune`` answers today for the robot as built, tuned by main
GAINS: list[str] = []  # the same, as --set flags
RUN = [sys.executable, "-m", "twin.run"]
SCENARIOS = {  # name: (drifts, laps run at most)
    "linear": (["motion.mu=0.9:0.55@80"], 70),
    "accelerating": (["motion.mu=0.9:0.5@70:accelerating"], 70),
    "step": (["motion.mu=0.9:0.6@40:step@15"], 80),  # tyres swapped at lap 15 (μ 0.79), worn again from there
    "two causes": (["motion.mu=0.9:0.6@60", "motor.supply_voltage=6.0:4.0@60"], 80),
}
QUICK = {"linear": (["motion.mu=0.9:0.55@10"], 10)}  # --quick: the linear wear in 10 laps
POINTS = (0.3, 0.5, 0.7, 0.9)  # forecasts at these fractions of the life (first failed lap)
ALPHA, LAMBDA = 0.2, 0.5


def run_robot(folder: str, drifts: list[str], laps: int, seed: int, speed: float) -> tuple[dict, list]:
    """One robot watched by plain live: (live's JSON, the robot's own laps (completed, lap time))."""
    emu = subprocess.Popen([*RUN, "emulate", "--tcp", "0", "--speed", str(speed), "--laps", str(laps), "--seed",
                            str(seed), *[w for d in drifts for w in ("--drift", d)], "--echo", "echo.txt", "--json",
                            *GAINS], cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    url = json.loads(emu.stdout.readline())["link"]
    live = subprocess.run([*RUN, "live", "--port", url, "--laps", str(laps), "--json", *GAINS], cwd=folder,
                          capture_output=True, text=True)
    emu.wait(timeout=120)
    if live.returncode != 0:
        raise RuntimeError(f"live failed in {folder}: {live.stderr[-2000:]}")
    return json.loads(live.stdout), [lap.lap_time_s for lap in log_laps(os.path.join(folder, "echo.txt"))]


def forecasts_of(twin: DigitalTwin, doc: dict, lap_times: list, seed: int) -> dict:
    """The forecasts at POINTS of the life, and at every alignment (for the prognostic horizon)."""
    failed = next((k for k, t in enumerate(lap_times) if t is None), None)
    out = {"first_failed_lap": failed, "forecasts": []}
    if failed is None:
        return out
    aligned = [a for a in doc["alignments"] if a.get("lap") is not None]
    laps = [{"n": k, "completed": t is not None, "gains": PLAIN} for k, t in enumerate(lap_times)]
    at = sorted({max(1, round(p * failed)) for p in POINTS} | {a["lap"] for a in aligned if a["lap"] < failed})
    for now in at:
        t0 = time.perf_counter()
        f = forecast_failure(twin, PLAIN, [a for a in aligned if a["lap"] <= now], laps[:now + 1], "motion.mu",
                             now_lap=now, seed=seed)
        wall = time.perf_counter() - t0
        q = f.quantiles
        out["forecasts"].append({"now": now, "true_rul": failed - now, "median": f.laps_to_failure,
                                 "lo": None if q is None else q["5"], "hi": None if q is None else q["95"],
                                 "numbered": q is not None, "statement": f.statement, "wall_s": round(wall, 2),
                                 "at_point": any(now == max(1, round(p * failed)) for p in POINTS)})
    return out


def _covered(f: dict) -> bool:
    lo = f["lo"] if f["lo"] is not None else -math.inf
    hi = f["hi"] if f["hi"] is not None else math.inf
    return lo <= f["true_rul"] <= hi


def metrics(runs: list[dict]) -> dict:
    points = [f for r in runs for f in r["forecasts"] if f["at_point"] and f["numbered"]]
    silent = sum(1 for r in runs for f in r["forecasts"] if f["at_point"] and not f["numbered"])
    widths = [f["hi"] - f["lo"] for f in points if f["hi"] is not None and f["lo"] is not None]
    alpha_lambda, ra, horizons = [], [], []
    for r in runs:
        life = r["first_failed_lap"]
        if not life or not r["forecasts"]:
            continue
        half = min(r["forecasts"], key=lambda f: abs(f["now"] - LAMBDA * life))
        if half["numbered"] and half["median"] is not None:
            alpha_lambda.append(abs(half["median"] - half["true_rul"]) <= ALPHA * half["true_rul"])
            ra.append(1 - abs(half["true_rul"] - half["median"]) / half["true_rul"])
        else:
            alpha_lambda.append(False)
        within = [f["numbered"] and f["median"] is not None and abs(f["median"] - f["true_rul"]) <= ALPHA * life
                  for f in r["forecasts"]]
        start = next((i for i in range(len(within)) if all(within[i:])), None)
        horizons.append(0.0 if start is None else (life - r["forecasts"][start]["now"]) / life)
    walls = [f["wall_s"] for r in runs for f in r["forecasts"]]
    return {"forecasts": len(points), "without_a_number": silent,
            "coverage_90": round(sum(map(_covered, points)) / len(points), 3) if points else None,
            "median_width_laps": statistics.median(widths) if widths else None,
            "open_ended": len(points) - len(widths),
            "alpha_lambda_met": round(sum(alpha_lambda) / len(alpha_lambda), 3) if alpha_lambda else None,
            "relative_accuracy_median": round(statistics.median(ra), 3) if ra else None,
            "prognostic_horizon_median": round(statistics.median(horizons), 3) if horizons else None,
            "forecast_wall_s_max": max(walls) if walls else None,
            "forecast_wall_s_median": statistics.median(walls) if walls else None}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2, help="robots per scenario (emulate --seed 7, 8, …)")
    ap.add_argument("--speed", type=float, default=10.0, help="the robots' pace against real time")
    ap.add_argument("--scenario", action="append", choices=sorted(SCENARIOS))
    ap.add_argument("--parallel", type=int, default=2, help="robots at once")
    ap.add_argument("--keep", metavar="DIR", help="run in this new folder and keep it")
    ap.add_argument("--quick", action="store_true", help="one robot, linear wear in 10 laps, 20× real time (for CI)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if args.quick:
        SCENARIOS.clear()
        SCENARIOS.update(QUICK)
        args.seeds, args.speed, args.scenario = 1, 20.0, None
    PLAIN.update(tuned_gains())
    GAINS[:] = set_flags(PLAIN)
    names = args.scenario or list(SCENARIOS)
    jobs = [(n, 7 + s) for n in names for s in range(args.seeds)]
    t0 = time.monotonic()
    if args.keep:
        os.makedirs(args.keep)
    twin = DigitalTwin()
    twin.model()
    runs = []
    with (contextlib.nullcontext(args.keep) if args.keep else tempfile.TemporaryDirectory(prefix="bench-fc-")) as tmp:
        from concurrent.futures import ThreadPoolExecutor

        def one(job):
            name, seed = job
            folder = os.path.join(tmp, f"{name.replace(' ', '_')}_{seed}")
            os.makedirs(folder)
            drifts, laps = SCENARIOS[name]
            return job, run_robot(folder, drifts, laps, seed, args.speed)

        with ThreadPoolExecutor(args.parallel) as pool:
            for (name, seed), (doc, lap_times) in pool.map(one, jobs):
                print(f"{name} seed {seed}: first failed lap "
                      f"{next((k for k, t in enumerate(lap_times) if t is None), None)}, "
                      f"{len(doc['alignments'])} alignments", file=sys.stderr)
                runs.append({"scenario": name, "seed": seed, **forecasts_of(twin, doc, lap_times, 0)})
    result = {"speed": args.speed, "seeds": args.seeds, "wall_s": round(time.monotonic() - t0, 1),
              "all": metrics(runs), "by_scenario": {n: metrics([r for r in runs if r["scenario"] == n]) for n in names},
              "runs": runs}
    if args.json:
        print(json.dumps(result, indent=1))
        return
    print(f"{len(runs)} robots ({', '.join(names)} × {args.seeds} seeds) at {args.speed:g}× real time, "
          f"{result['wall_s']:.0f} s wall")
    for name, m in [("all", result["all"]), *result["by_scenario"].items()]:
        print(f"{name}: {m}")
    for r in runs:
        for f in r["forecasts"]:
            if f["at_point"]:
                print(f"  {r['scenario']} seed {r['seed']}, lap {f['now']}: true {f['true_rul']} laps; {f['statement']}")


if __name__ == "__main__":
    main()
