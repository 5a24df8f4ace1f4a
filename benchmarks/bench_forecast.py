"""A prognostics benchmark: ageing robots (``emulate --drift``, plainly tuned gains, each its own noise seed) watched
by plain ``live`` for scenario × seed, each robot run to its real first failed lap; then, from what ``live``
recorded (its alignments, stamped with the laps they measured, and the robot's laps: lap time, the line's mean
offset and side), ``history``'s forecast (:func:`tuner.history.two_causes.forecasts_of`: each part that wears and, when
no one explains the laps, both at once; the soonest, as ``history`` says it) made at several points of life,
against the lap the robot first failed.

The metrics of the field (the definitions of Saxena et al. 2010, as ProgPy's ``progpy.metrics`` computes them;
written out on plain numbers in tests/prognostic_metrics.py, so the benchmark needs neither ProgPy's containers nor
its import time):
  * coverage: how often the true remaining life (laps from the forecast to the first failed lap) lies in the
    stated 90 % interval (an open end counts as covering), with the interval's median width;
  * α-λ accuracy (α = 0.2, λ = 0.5): at the forecast nearest half of the life, is the median within ±20 % of the
    true remaining life?
  * prognostic horizon: the life left when the forecasts start, and stay, within ±α of the true end of life
    (α = 0.2 of the whole life), as a fraction of the life;
  * relative accuracy at λ = 0.5: 1 − |true − median|/true;
  * the information limit (one part wearing straight or speeding up): at half of the life, the Cramér–Rao bound
    on the remaining life from the robot's laps read through the twin (:mod:`tuner.prognostics.information`), and
    how often an unbiased forecast that good would meet α-λ; and the same from the lap time alone, and with the
    line's offset (what each feature adds);
  * the exact posterior (one part wearing straight or speeding up): at half of the life, the posterior of the
    filter's own model on the evidence the forecast gave its filter, by adaptive importance sampling
    (tests/exact_posterior.py; without the rate's walk, which it does not model, and renewals, which it models
    one lap at a time: a sampler per lap, too slow beside every forecast; tests check it on them): its share of futures
    speeding up and its median against the filter's and the truth, so a miss shows as the evidence's or the filter's;
  * the twin's own Monte Carlo (``--race-seeds K``): the forecast at half of the life again from the twin raced on K
    other draws of its noise seeds (its failure and observation models are means over a few seeds a value, and every
    robot on the same gains reads through the same draw, so the robots above are not independent of it): the spread
    of the medians, and coverage and α-λ over (robot, race seed);
  * the Monte Carlo's own error: the forecast at half of the life again on ``FILTER_SEEDS`` filter seeds (the
    races kept): the spread of their medians as a fraction of the true remaining life, and α-λ on each seed;
  * the forecast's wall time (a forecast must be ready within one lap at real time on 2 cores): each robot's
    ``live --race-ahead`` races its gains on the twin in the background for each cause (each robot with a cache folder
    of its own, or with ``--share-cache`` one for all, as robots on one machine share the user's: robots on the same
    gains then race them once): how long that took, against the laps a forecast waits for (``MIN_TIMED_LAPS``) at real
    time; the first forecast, on those races (a robot kept by an older ``--keep`` has none: its first forecast races the
    twin); and once more after forgetting them, as a new ``history`` process does. At real time: is the first forecast,
    and the first of both parts at once (the first lap, read lap by lap, where no part alone explains the laps: it needs
    the race-ahead's rows of both), and the first on more seeds a value (raced last), ready within a lap of being
    asked, given when this run's races were done (each entry's time in the robot's cache folder) and its wall time?

  python benchmarks/bench_forecast.py [--seeds 2] [--speed 10] [--scenario NAME ...] [--keep DIR | --again DIR]
                                      [--share-cache] [--parallel 2] [--race-seeds K] [--quick] [--json]

``--quick``: one robot of the linear scenario compressed to 24 laps, at 20× real time, on the plain gains the tests
hold fixed (``QUICK_GAINS``), at half of its life on one more draw of the twin's races, its races in the cache folder of the run that started it (the tests' run races those
gains once for all its forecasts), for CI: the script cannot rot; the figures are not the table's.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time

from tuner.history import log_laps
from tuner.history.forecast import MIN_TIMED_LAPS, SEEDS_LATER_FROM, SERVICE, edge_seeds as seeds_for, race_ahead
from tuner.history.ingest import cross_track
from tuner.history.report import soonest
from tuner.history import twin_edge
from tuner.history.two_causes import ROWS, forecasts_of as history_forecasts, joint_address
from tuner.prognostics.information import remaining_life_bound, within_alpha
from twin.cli.guard import fail
from twin.core.digital_twin import DigitalTwin
from twin.link.emulator import Drift

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
from exact_posterior import exact_posterior  # noqa: E402  (an independent estimator of the filter's posterior)
from prognostic_metrics import ALPHA, LAMBDA, metrics, ready_within_a_lap  # noqa: E402  (the field's metrics)
from reference_gains import PLAIN_HELD, set_flags, tuned_gains  # noqa: E402  (the one home of tuned gains)

PLAIN: dict[str, float] = {}  # the gains ``tune`` answers today for the robot as built, tuned by main
GAINS: list[str] = []  # the same, as --set flags
RUN = [sys.executable, "-m", "twin.run"]
SCENARIOS = {  # name: (drifts, laps run at most)
    "linear": (["motion.mu=0.9:0.55@80"], 80),
    "accelerating": (["motion.mu=0.9:0.5@70:accelerating"], 70),
    "step": (["motion.mu=0.9:0.6@40:step@15"], 80),  # tyres swapped at lap 15 (μ 0.79), worn again from there
    "two causes": (["motion.mu=0.9:0.6@60", "motor.supply_voltage=6.0:4.0@60"], 80),
    # the battery alone, running down faster as it empties: its laps slow by half before the gains fail (issue 35:
    # read to its edge since the twin's regular laps are judged against their neighbours)
    "battery": (["motor.supply_voltage=6.2:4.0@80:accelerating"], 90),
}
QUICK = {"linear": (["motion.mu=0.9:0.6@24"], 24)}  # --quick: a linear wear those gains fail on near lap 17 …
# … on the gains the tests hold fixed (tests/reference_gains.py), in the caller's cache folder
QUICK_GAINS = PLAIN_HELD
POINTS = (0.3, 0.5, 0.7, 0.9)  # forecasts at these fractions of the life (first failed lap) …
EVERY = 5  # … and every this many laps (for the prognostic horizon)
CAUSES = sorted(SERVICE)  # what history forecasts for a robot: each part that wears; the soonest is the forecast
PITCH_M = 0.009525  # the default robot's sensor pitch (the robots here are the default robot)
FILTER_SEEDS = 4  # the forecast at half of the life on this many filter seeds: how far its Monte Carlo moves it
RACE_SEED_STEP = 100_000  # --race-seeds: race seed k draws the twin's laps from noise seed k·RACE_SEED_STEP on (the
# races of seed 0 take a few hundred)
SEED, SEED_STEP = 7, 1000  # the robots' emulate --seed: 7, 1007, … (each robot's laps use SEED + lap)


def run_robot(folder: str, drifts: list[str], laps: int, seed: int, speed: float,
              cache: str | None) -> tuple[dict, list]:
    """One robot watched by plain live: (live's JSON, the robot's own laps (completed, lap time)). ``cache``: the
    cache folder its races go to, whose entries' times are then measured (its own, or one the robots share), or
    None: the caller's (--quick)."""
    env = {**os.environ, **({"TWIN_CACHE_DIR": cache} if cache else {})}
    emu = subprocess.Popen([*RUN, "emulate", "--tcp", "0", "--speed", str(speed), "--laps", str(laps), "--seed",
                            str(seed), *[w for d in drifts for w in ("--drift", d)], "--echo", "echo.txt", "--json",
                            *GAINS], cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env)
    url = json.loads(emu.stdout.readline())["link"]
    started = time.time()  # (the races start a moment after live: its imports; so the times below are upper ones)
    live = subprocess.run([*RUN, "live", "--port", url, "--laps", str(laps), "--json", "--race-ahead", *GAINS],
                          cwd=folder, capture_output=True, text=True, env=env)
    emu.wait(timeout=120)
    if live.returncode != 0 and not live.stdout.strip():
        raise RuntimeError(f"live failed in {folder}: {live.stderr[-2000:]}")
    with open(os.path.join(folder, "live.json"), "w") as f:
        f.write(live.stdout)
    if cache:
        with open(os.path.join(folder, RACES_DONE), "w") as f:
            json.dump(races_done(os.path.join(cache, EDGES), started), f)
    return json.loads(live.stdout), robot_laps_of(folder)


EDGES = twin_edge.RACES  # the races' folder in a cache folder (read once: forecasts_of points twin_edge at a robot's)
RACES_DONE = "races_done.json"  # a robot's folder: when each race live ran ahead was written, [s] after live started


def races_done(folder: str, started: float) -> list[float]:
    """When each race in ``folder`` was written (its entry's race.json), seconds after ``started``, in order:
    the race-ahead races the parts that wear one by one, then the rows of both at once
    (:mod:`tuner.history.race_ahead`), so the first ``len(SERVICE)`` are the one-cause races."""
    if not os.path.isdir(folder):
        return []
    return sorted(round(os.path.getmtime(os.path.join(folder, e, "race.json")) - started, 1)
                  for e in os.listdir(folder) if os.path.isfile(os.path.join(folder, e, "race.json")))


def robot_laps_of(folder: str) -> list:
    """The robot's own laps from its echo log: (lap time or None, the line's mean offset [m], its mean signed offset
    [m]), as the history reads them (:func:`tuner.history.ingest.cross_track`)."""
    return [(lap.lap_time_s, *cross_track(lap, PITCH_M)[1:]) for lap in log_laps(os.path.join(folder, "echo.txt"))]


def information_limit(twin: DigitalTwin, drifts: list[str], now: int, true_rul: int,
                      edge_seeds: int | None = None) -> dict | None:
    """How well any forecast could do at lap ``now`` of a robot whose one part wears along a straight line or a
    curve (``drifts``): the Cramér–Rao bound on the remaining life from its laps read through the twin's own
    observation model at the twin's own scatter (:mod:`tuner.prognostics.information`; value, rate and
    acceleration unknown), and the chance an unbiased forecast that good is within ±α (None: a step or two
    causes, which the bound's family does not describe); and the same from fewer of the features (the lap time
    alone, then with the line's offset: what each adds), with how far one lap pins the part at its value now."""
    if len(drifts) != 1:
        return None
    drift = Drift.parse(drifts[0], twin)
    if drift.shape == "step" or drift.address not in SERVICE:
        return None
    edge = race_ahead(twin, PLAIN, seeds=seeds_for(now + 1) if edge_seeds is None else edge_seeds)[drift.address]
    if edge.failure is None or edge.observation is None:
        return None
    values = [drift.at(k) for k in range(now + 1)]
    names = edge.observation.names
    by = {}
    for k in range(1, len(names) + 1):
        model = edge.observation.subset(names[:k])
        try:
            remaining, sd = remaining_life_bound(values, [model.pins(v) for v in values], edge.failure.threshold, now)
        except ValueError:  # too few laps that say anything
            return None
        by["+".join(names[:k])] = {"sd_laps": round(sd, 2), "alpha_lambda_attainable":
                                   round(within_alpha(true_rul, sd, ALPHA), 3), "pins_now": model.pins(values[-1])}
    every = by["+".join(names)]
    return {"now": now, "crossing_laps": round(remaining, 1), "sd_laps": every["sd_laps"],
            "alpha_lambda_attainable": every["alpha_lambda_attainable"], "by_features": by}


def exact_check(drifts: list[str], twin: DigitalTwin, forecast, record: dict, now: int, true_rul: int,
                seed: int) -> dict | None:
    """The exact posterior of the filter's model at lap ``now`` on the evidence ``forecast``'s filter was given
    (``record``, :class:`tuner.history.forecast.FilterInputs`) against what the filter said (None: a step, two
    causes, or no filter ran for the soonest cause)."""
    if len(drifts) != 1 or Drift.parse(drifts[0], twin).shape == "step" or forecast.address not in record:
        return None
    given = record[forecast.address]
    if forecast.quantiles is None or not given.settings.one_way:
        return None
    settings = dataclasses.replace(given.settings, rate_walk=0.0, renewal=0.0)
    exact = exact_posterior(given.measurements, given.outcomes, now, settings, given.failure, seed=seed,
                            observations=given.observations, model=given.model)
    shapes = forecast.shapes or {}
    return {"now": now, "true_rul": true_rul, "exact_speeding_up": round(exact.speeding_up, 3),
            "exact_median": exact.life.quantiles()["50"],  # None: beyond the horizon
            "filter_speeding_up": round(shapes.get("speeding_up", {}).get("share", 0.0), 3),
            "filter_median": forecast.laps_to_failure, "effective_draws": [round(e) for e in exact.effective]}


def forecasts_of(twin: DigitalTwin, folder: str, doc: dict, robot_laps: list, seed: int,
                 drifts: list[str] = (), cache: str | None = None, edge_seeds: int | None = None) -> dict:
    """The forecasts at POINTS of the life, and every EVERY laps (for the prognostic horizon), from what the
    history would hold: live's alignments and the robot's laps (lap time, the line's mean offset and side), the
    twin raced on ``edge_seeds`` noise seeds a value (None: as history does, by the laps, and live's race-ahead
    races ahead; with any other, no readiness figure)."""
    lap_times = [t for t, *_ in robot_laps]
    twin_edge.forget_races()  # each robot's first forecast reads the races its live ran ahead, in its cache folder
    if cache:  # (as run_robot ran it)
        twin_edge.RACES = os.path.join(cache, EDGES)
    ahead = doc.get("race_ahead") or {}
    failed = next((k for k, t in enumerate(lap_times) if t is None), None)
    done = [t for t in lap_times if t is not None]
    out = {"first_failed_lap": failed, "forecasts": [], "race_ahead_state": ahead.get("state"),
           "race_ahead_wall_s": ahead.get("wall_s"),
           # what the races must beat: the laps a forecast waits for, at real time
           "min_timed_laps_s": round(MIN_TIMED_LAPS * statistics.median(done), 1) if done else None}
    if failed is None:
        return out
    aligned = [a for a in doc["alignments"] if a.get("lap") is not None]
    laps = [{"n": k, "completed": t is not None, "gains": PLAIN, "lap_time_s": t, "xte_mean_m": x, "line_side_m": side}
            for k, (t, x, side) in enumerate(robot_laps)]
    at = sorted({max(1, round(p * failed)) for p in POINTS} | set(range(EVERY, failed, EVERY)))

    joint = joint_address(tuple(sorted(SERVICE)))
    made_joint = set()  # the laps whose forecasts include one of both parts at once

    def forecast(now, filter_seed=None, record=None):
        t0 = time.perf_counter()
        fs = history_forecasts(twin, PLAIN, [a for a in aligned if a["lap"] <= now], laps[:now + 1], CAUSES, now,
                               seed=seed, filter_seed=filter_seed, record=record, seeds=edge_seeds)
        if joint in fs:
            made_joint.add(now)
        return soonest(fs.values()), time.perf_counter() - t0

    half_now = min(at, key=lambda now: abs(now - LAMBDA * failed))  # the forecast nearest half of the life
    given: dict = {}
    for now in at:
        f, wall = forecast(now, record=given if now == half_now else None)
        if now == half_now:
            out["exact_at_half"] = exact_check(list(drifts), twin, f, given, now, failed - now, seed)
        q = f.quantiles
        out["forecasts"].append({"now": now, "true_rul": failed - now, "median": f.laps_to_failure, "cause": f.address,
                                 "lo": None if q is None else q["5"], "hi": None if q is None else q["95"],
                                 "numbered": q is not None, "statement": f.statement, "wall_s": round(wall, 2),
                                 "joint": now in made_joint,
                                 "at_point": any(now == max(1, round(p * failed)) for p in POINTS)})
    # the first forecast with a number, and the first of both parts at once (the laps between the forecasts above
    # read one by one), each as a new history process makes it: the races read back from the cache folder
    first = next((f for f in out["forecasts"] if f["numbered"]), None)
    if first is not None:
        twin_edge.forget_races()
        first = {"now": first["now"], "wall_s": round(forecast(first["now"])[1], 2)}
    later = next((k for k, f in enumerate(out["forecasts"]) if f["joint"]), None)
    joint_first = None
    if later is not None:
        for now in range(out["forecasts"][later - 1]["now"] + 1 if later else 1, out["forecasts"][later]["now"]):
            twin_edge.forget_races()
            wall = forecast(now)[1]
            if now in made_joint:
                joint_first = {"now": now, "wall_s": round(wall, 2)}
                break
        else:
            joint_first = {k: out["forecasts"][later][k] for k in ("now", "wall_s")}
    done_path = os.path.join(folder, RACES_DONE)
    if os.path.isfile(done_path) and edge_seeds is None:
        with open(done_path) as done_file:
            written = json.load(done_file)
        # the first forecast on more seeds a value, as a new history makes it (if live raced them: a race a part last)
        later_races, first_later = len(SERVICE) if len(written) >= 2 * len(SERVICE) + ROWS - 1 else 0, None
        if later_races and failed > SEEDS_LATER_FROM:
            twin_edge.forget_races()
            first_later = {"now": SEEDS_LATER_FROM - 1, "wall_s": round(forecast(SEEDS_LATER_FROM - 1)[1], 2)}
        out["ready"] = ready_within_a_lap(written, done, first, joint_first, MIN_TIMED_LAPS, len(SERVICE),
                                          first_later, later_races)
    # the Monte Carlo's own error: the forecast at half of the life again, on other filter seeds (the races kept)
    half = next(f for f in out["forecasts"] if f["now"] == half_now)  # its own seed's is made already
    others = [forecast(half["now"], filter_seed=k)[0].laps_to_failure for k in range(seed + 1, seed + FILTER_SEEDS)]
    out["filter_seeds_at_half"] = {"now": half["now"], "true_rul": half["true_rul"],
                                   "medians": [half["median"], *others]}
    out["evidence_at_half"] = {"alignments": [a for a in aligned if a["lap"] <= half["now"]],
                               "laps": laps[:half["now"] + 1]}
    out["information_limit"] = information_limit(twin, list(drifts), half["now"], half["true_rul"], edge_seeds)
    twin_edge.forget_races()  # a new history process: the races read back from the cache folder
    again, wall = forecast(at[-1])
    assert again.quantiles == f.quantiles and again.statement == f.statement, "a race read back is not the race"
    out["cached_wall_s"] = round(wall, 2)
    return out


def race_seeds_at_half(twin: DigitalTwin, run: dict, race_seeds: int,
                       edge_seeds: int | None = None) -> dict | None:
    """The forecast at half of the life again, on the same evidence and filter seed, from the twin raced on
    ``race_seeds`` other draws of its noise seeds (into whatever cache folder ``twin_edge.RACES`` names: robots on the
    same gains share them): {"now", "true_rul", "forecasts": [{"median", "lo", "hi"}, …]}, race seed 0's first."""
    half = next((f for f in run["forecasts"] if f["now"] == run["filter_seeds_at_half"]["now"]), None) \
        if run.get("filter_seeds_at_half") else None
    if half is None:
        return None
    given = run["evidence_at_half"]
    out = [{"median": half["median"], "lo": half["lo"], "hi": half["hi"]}]
    for k in range(1, race_seeds + 1):
        f = soonest(history_forecasts(twin, PLAIN, given["alignments"], given["laps"], CAUSES, half["now"],
                                      seed=k * RACE_SEED_STEP, filter_seed=0, seeds=edge_seeds).values())
        q = f.quantiles
        out.append({"median": f.laps_to_failure, "lo": None if q is None else q["5"],
                    "hi": None if q is None else q["95"]})
    return {"now": half["now"], "true_rul": half["true_rul"], "forecasts": out}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2, help="robots per scenario (emulate --seed 7, 1007, …)")
    ap.add_argument("--speed", type=float, default=10.0, help="the robots' pace against real time")
    ap.add_argument("--scenario", action="append", choices=sorted(SCENARIOS))
    ap.add_argument("--parallel", type=int, default=2, help="robots at once")
    ap.add_argument("--keep", metavar="DIR", help="run in this new folder and keep it")
    ap.add_argument("--again", metavar="DIR", help="forecast again from the robots a --keep run left in DIR (their "
                    "live.json and echo.txt), without running them")
    ap.add_argument("--share-cache", action="store_true", help="the robots' races in one cache folder, as robots on "
                    "one machine share the user's (the same twin and gains: raced once for all); default: a folder "
                    "per robot, so each robot's races are timed as if its gains were its own")
    ap.add_argument("--race-seeds", type=int, default=0, metavar="K", help="forecast each robot at half of its life "
                    "again from the twin raced on K other draws of its noise seeds (default 0: none; the robots "
                    "share those races, in one cache folder of the run)")
    ap.add_argument("--edge-seeds", type=int, default=None, metavar="N", help="with --again: the twin's noise seeds a "
                    "raced value, every forecast (default: as history asks, by the robot's laps: forecast.edge_seeds; "
                    "with N, the races are raced here and no readiness figure is given)")
    ap.add_argument("--quick", action="store_true", help="one robot, linear wear in 24 laps, 20× real time (for CI)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if args.quick:
        SCENARIOS.clear()
        SCENARIOS.update(QUICK)
        args.seeds, args.speed, args.scenario = 1, 20.0, None
        args.race_seeds = max(args.race_seeds, 1)  # (its code path too: two more races)
    if args.edge_seeds is not None and args.edge_seeds < 2:
        sys.exit(fail(f"--edge-seeds {args.edge_seeds}: at least 2 (a value's scatter needs two laps)"))
    if args.edge_seeds is not None and not args.again:
        sys.exit(fail(f"--edge-seeds {args.edge_seeds}: only with --again (live races the gains ahead on "
                      "the seeds history asks for)"))
    if args.again and not os.path.isdir(args.again):
        sys.exit(fail(f"--again {args.again}: no such folder"))
    names = args.scenario or list(SCENARIOS)
    if args.again:  # the scenarios a --keep run left robots of (an older run has fewer), unless named
        def kept_robot(name: str, s: int) -> str:
            return os.path.join(args.again, f"{name.replace(' ', '_')}_{SEED + SEED_STEP * s}", "live.json")

        names = names if args.scenario else [n for n in names if os.path.isfile(kept_robot(n, 0))]
        missing = [kept_robot(n, s) for n in names for s in range(args.seeds) if not os.path.isfile(kept_robot(n, s))]
        if missing or not names:
            where = f"no robot kept at {missing[0]}" if missing else "no robot kept of any scenario"
            sys.exit(fail(f"--again {args.again}: {where} (run them with --keep DIR)"))
    PLAIN.update(QUICK_GAINS if args.quick else tuned_gains())
    GAINS[:] = set_flags(PLAIN)
    # seeds far apart: emulate --seed S runs lap k on noise seed S + k, so robots 7 and 8 would share their laps'
    # noise one lap apart (until 2026-11-28 they did, and agreed with each other more than robots do)
    jobs = [(n, SEED + SEED_STEP * s) for n in names for s in range(args.seeds)]
    t0 = time.monotonic()
    if args.keep:
        os.makedirs(args.keep)
    twin = DigitalTwin()
    twin.model()
    runs = []
    kept = args.again or args.keep
    with (contextlib.nullcontext(kept) if kept else tempfile.TemporaryDirectory(prefix="bench-fc-")) as tmp:
        from concurrent.futures import ThreadPoolExecutor

        def cache_of(folder: str) -> str | None:  # (--quick: the caller's)
            return None if args.quick else os.path.join(tmp if args.share_cache else folder, "cache")

        def one(job):
            name, seed = job
            folder = os.path.join(tmp, f"{name.replace(' ', '_')}_{seed}")
            if args.again:
                with open(os.path.join(folder, "live.json")) as f:
                    return job, folder, (json.load(f), robot_laps_of(folder))
            os.makedirs(folder)
            drifts, laps = SCENARIOS[name]
            return job, folder, run_robot(folder, drifts, laps, seed, args.speed, cache_of(folder))

        with ThreadPoolExecutor(args.parallel) as pool:
            for (name, seed), folder, (doc, robot_laps) in pool.map(one, jobs):
                print(f"{name} seed {seed}: first failed lap "
                      f"{next((k for k, (t, *_) in enumerate(robot_laps) if t is None), None)}, "
                      f"{len(doc['alignments'])} alignments", file=sys.stderr)
                runs.append({"scenario": name, "seed": seed,
                             **forecasts_of(twin, folder, doc, robot_laps, 0, SCENARIOS[name][0], cache_of(folder),
                                            args.edge_seeds)})
        if args.race_seeds > 0:  # after the robots: one cache folder for these races, which every robot asks for
            twin_edge.RACES = os.path.join(tmp, "race-seeds", EDGES)
            for r in runs:
                print(f"{r['scenario']} seed {r['seed']}: its forecast at half of its life on {args.race_seeds} more "
                      "races of the twin", file=sys.stderr)
                r["race_seeds_at_half"] = race_seeds_at_half(twin, r, args.race_seeds, args.edge_seeds)
    for r in runs:
        r.pop("evidence_at_half", None)  # (the inputs, not a result)
    result = {"speed": None if args.again else args.speed, "seeds": args.seeds, "share_cache": args.share_cache,
              "edge_seeds": args.edge_seeds,
              "wall_s": round(time.monotonic() - t0, 1),
              "all": metrics(runs), "by_scenario": {n: metrics([r for r in runs if r["scenario"] == n]) for n in names},
              "runs": runs}
    if args.json:
        print(json.dumps(result, indent=1))
        return
    pace = f"kept in {args.again} (their pace as run)" if args.again else f"at {args.speed:g}× real time"
    caches = "one cache folder for all" if args.share_cache else "a cache folder each"
    if args.edge_seeds is not None:
        caches += f", the twin raced on {args.edge_seeds} noise seeds a value"
    print(f"{len(runs)} robots ({', '.join(names)} × {args.seeds} seeds) {pace}, {caches}, "
          f"{result['wall_s']:.0f} s wall")
    for name, m in [("all", result["all"]), *result["by_scenario"].items()]:
        print(f"{name}: {m}")
    for r in runs:
        for f in r["forecasts"]:
            if f["at_point"]:
                print(f"  {r['scenario']} seed {r['seed']}, lap {f['now']}: true {f['true_rul']} laps; "
                      f"{f['statement']}")
        exact = r.get("exact_at_half")
        if exact:
            print(f"  {r['scenario']} seed {r['seed']}, exact posterior at lap {exact['now']}: speeding up "
                  f"{exact['exact_speeding_up']:.0%} (filter {exact['filter_speeding_up']:.0%}), median "
                  f"{exact['exact_median']} laps (filter {exact['filter_median']}), true {exact['true_rul']}")
        ready = r.get("ready") or {}
        later = f"first forecast on {seeds_for(SEEDS_LATER_FROM)} seeds a value"
        for what, x in [("first forecast", ready.get("first")), ("first forecast of both at once",
                        ready.get("first_joint")), (later, ready.get("first_later"))]:
            if x:
                at = f" (lap {x['now']})" if "now" in x else ""
                print(f"  {r['scenario']} seed {r['seed']}, {what}{at} at real time: asked {x['asked_s']} s after "
                      f"live started, its races done at {x['races_done_s']} s, {x['wall_s']} s to compute: ready "
                      f"{x['late_s']} s after asking, {'within' if x['within_a_lap'] else 'not within'} a lap "
                      f"({ready['lap_s']} s)")
        drawn = r.get("race_seeds_at_half")
        if drawn:
            said = ", ".join(f"{f['median']} ({f['lo']}–{f['hi']})" for f in drawn["forecasts"])
            print(f"  {r['scenario']} seed {r['seed']}, at lap {drawn['now']} on {len(drawn['forecasts'])} races of "
                  f"the twin (seed 0 first): {said}; true {drawn['true_rul']}")
        bound = r.get("information_limit")
        if bound:
            print(f"  {r['scenario']} seed {r['seed']}, information limit at lap {bound['now']}: remaining life "
                  f"known to ± {bound['sd_laps']} laps at best (Cramér–Rao, the twin's scatter): within ±{ALPHA:g} "
                  f"at most {bound['alpha_lambda_attainable']:.0%} of the time; by the features read: " + "; ".join(
                      f"{names} ± {b['sd_laps']} laps ({b['alpha_lambda_attainable']:.0%}, a lap pins it to "
                      f"{b['pins_now']:.3g})" for names, b in bound["by_features"].items()))


if __name__ == "__main__":
    main()
