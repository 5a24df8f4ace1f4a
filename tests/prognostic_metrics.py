"""The metrics of the field over a prognostics benchmark's robots (``benchmarks/bench_forecast.py``): the definitions
of Saxena et al. (2010), "Metrics for offline evaluation of prognostic performance", as ProgPy's ``progpy.metrics``
computes them, written out on plain numbers so the benchmark needs neither ProgPy's containers nor its import time
(the definitions are checked by hand in tests/test_prognostic_metrics.py), beside the benchmark's own figures (the
races run ahead, readiness, the filter's and the twin's Monte Carlo). Not a test module.

A robot's run (``forecasts_of``) holds its ``forecasts`` lap by lap, each ``{"now", "true_rul", "median", "lo", "hi",
"numbered", "at_point", "wall_s"}`` (laps; ``lo``/``hi`` the stated 90 % interval, None an open end), and its
``first_failed_lap`` (the life)."""

from __future__ import annotations

import math
import statistics

ALPHA, LAMBDA = 0.2, 0.5  # α-λ accuracy: within ±α of the true remaining life at the forecast nearest λ of the life


def covered(f: dict) -> bool:
    """Does the forecast's stated 90 % interval hold its true remaining life (an open end holds everything past it)?"""
    lo = f["lo"] if f["lo"] is not None else -math.inf
    hi = f["hi"] if f["hi"] is not None else math.inf
    return lo <= f["true_rul"] <= hi


def metrics(runs: list[dict]) -> dict:
    """Over ``runs``: coverage of the stated 90 % intervals at the points of life (``at_point``) and their median
    width; α-λ at the forecast nearest λ of each life; relative accuracy there (1 − |true − median|/true); the
    prognostic horizon (the life left, as a fraction of it, when the forecasts start and stay within ±α of the whole
    life of the truth); and the benchmark's own figures the runs carry (None where no run has them)."""
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
    walls = [max(f["wall_s"] for f in r["forecasts"]) for r in runs if r["forecasts"]]  # the slowest: the first
    # to ask for the races (on those live ran ahead)
    ahead = [r["race_ahead_wall_s"] for r in runs if r.get("race_ahead_state") == "done"]
    beaten = [r["race_ahead_wall_s"] <= r["min_timed_laps_s"] for r in runs
              if r.get("race_ahead_state") == "done" and r.get("min_timed_laps_s")]
    cached = [r["cached_wall_s"] for r in runs if "cached_wall_s" in r]
    # the same evidence on other filter seeds: the spread of the medians (a fraction of the true remaining life),
    # and α-λ met on each seed
    seeded = [r["filter_seeds_at_half"] for r in runs if r.get("filter_seeds_at_half")]
    spreads = [(max(m) - min(m)) / h["true_rul"] for h in seeded if None not in (m := h["medians"])]
    per_seed = [m is not None and abs(m - h["true_rul"]) <= ALPHA * h["true_rul"] for h in seeded
                for m in h["medians"]]
    bounds = [r["information_limit"]["alpha_lambda_attainable"] for r in runs if r.get("information_limit")]
    # the same evidence on other draws of the twin's races: the medians' spread, coverage and α-λ over them all
    drawn = [r["race_seeds_at_half"] for r in runs if r.get("race_seeds_at_half")]
    race_spreads = [(max(m) - min(m)) / h["true_rul"] for h in drawn
                    if None not in (m := [f["median"] for f in h["forecasts"]])]
    per_race = [(f["median"] is not None and abs(f["median"] - h["true_rul"]) <= ALPHA * h["true_rul"],
                 f["median"] is not None and covered({**f, "true_rul": h["true_rul"]}))
                for h in drawn for f in h["forecasts"]]
    ready = [r["ready"] for r in runs if r.get("ready")]
    firsts = [x["first"] for x in ready if "first" in x]
    joints = [x["first_joint"] for x in ready if "first_joint" in x]
    laters = [x["first_later"] for x in ready if "first_later" in x]
    return {"forecasts": len(points), "without_a_number": silent,
            "coverage_90": round(sum(map(covered, points)) / len(points), 3) if points else None,
            "median_width_laps": statistics.median(widths) if widths else None,
            "open_ended": len(points) - len(widths),
            "alpha_lambda_met": round(sum(alpha_lambda) / len(alpha_lambda), 3) if alpha_lambda else None,
            "relative_accuracy_median": round(statistics.median(ra), 3) if ra else None,
            "prognostic_horizon_median": round(statistics.median(horizons), 3) if horizons else None,
            "race_ahead_done": f"{len(ahead)}/{len(runs)}",
            "race_ahead_wall_s_max": max(ahead) if ahead else None,
            "race_ahead_within_min_timed_laps": f"{sum(beaten)}/{len(beaten)}",
            "forecast_wall_s_max": max(walls) if walls else None,
            "forecast_wall_s_median": statistics.median(walls) if walls else None,
            "cached_forecast_wall_s_max": max(cached) if cached else None,
            "cached_forecast_wall_s_median": statistics.median(cached) if cached else None,
            # at real time (ready_within_a_lap): the first forecast, the first of both parts at once …
            "first_forecast_within_a_lap": f"{sum(x['within_a_lap'] for x in firsts)}/{len(firsts)}",
            "first_forecast_late_s_max": max((x["late_s"] for x in firsts), default=None),
            "first_joint_within_a_lap": f"{sum(x['within_a_lap'] for x in joints)}/{len(joints)}",
            "first_joint_late_s_max": max((x["late_s"] for x in joints), default=None),
            # … and the first on the races of more seeds a value (forecast.SEEDS_LATER_FROM laps in)
            "first_later_within_a_lap": f"{sum(x['within_a_lap'] for x in laters)}/{len(laters)}",
            "first_later_late_s_max": max((x["late_s"] for x in laters), default=None),
            "filter_seed_spread_median": round(statistics.median(spreads), 3) if spreads else None,
            "filter_seed_spread_max": round(max(spreads), 3) if spreads else None,
            "alpha_lambda_met_per_filter_seed": round(sum(per_seed) / len(per_seed), 3) if per_seed else None,
            "race_seed_spread_median": round(statistics.median(race_spreads), 3) if race_spreads else None,
            "race_seed_spread_max": round(max(race_spreads), 3) if race_spreads else None,
            "alpha_lambda_met_per_race_seed": round(sum(a for a, _ in per_race) / len(per_race), 3) if per_race
            else None,
            "coverage_90_at_half_per_race_seed": round(sum(c for _, c in per_race) / len(per_race), 3) if per_race
            else None,
            # how often an unbiased forecast at the information limit would meet α-λ (one part, straight or curved)
            "alpha_lambda_attainable_mean": round(statistics.mean(bounds), 3) if bounds else None}


def ready_within_a_lap(done: list[float], lap_times: list[float], first: dict | None, joint_first: dict | None,
                       timed_laps: int, one_cause_races: int, later: dict | None = None,
                       later_races: int = 0) -> dict | None:
    """Whether a robot at real time would have had its first forecast (``first``: {"now", "wall_s"}), and its first
    of both parts at once (``joint_first``), within one lap of asking: asked when the lap is in (``timed_laps``, the
    laps a forecast waits for; the first lap of both at once), at the robot's median lap time (of its finished
    ``lap_times``); ready when the races it needs are done (``done``: when each race was written [s after live
    started], in order: the first ``one_cause_races`` the parts one at a time, the rest the rows of both at once;
    at a pace above real time live works harder beside them, so they are slower there than at real time; the last
    ``later_races`` the parts again on more seeds, which the first forecast ``later`` reads) and it is computed (its
    wall time, the races read). None without the races' times."""
    if not done or not lap_times:
        return None
    lap_s = statistics.median(lap_times)
    out = {"lap_s": round(lap_s, 2)}

    def ready(asked_s, races_s, wall_s):
        late = max(0.0, races_s - asked_s) + wall_s
        return {"asked_s": round(asked_s, 1), "races_done_s": races_s, "wall_s": wall_s,
                "late_s": round(late, 1), "within_a_lap": late <= lap_s}

    if first is not None and len(done) >= one_cause_races:  # asked at the earliest: when its laps are in
        out["first"] = ready(timed_laps * lap_s, done[one_cause_races - 1], first["wall_s"])
    if joint_first is not None and len(done) > later_races:
        out["first_joint"] = {"now": joint_first["now"],
                              **ready((joint_first["now"] + 1) * lap_s, done[-1 - later_races], joint_first["wall_s"])}
    if later is not None and later_races and len(done) >= one_cause_races + later_races:
        out["first_later"] = {"now": later["now"], **ready((later["now"] + 1) * lap_s, done[-1], later["wall_s"])}
    return out
