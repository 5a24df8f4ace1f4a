"""When will the gains in force stop finishing laps? Prognostics as the field does it (:mod:`tuner.prognostics`),
for each part that wears (:data:`SERVICE`: grip, the battery) and each aligned parameter, one at a time:

1. the twin races the gains in force at a ladder of values of the parameter, from a little above the twin's value
   (or a less worn value measured: :func:`race_range`) towards the worn end (a few noise seeds each, each value
   its own), then finely where the laps still finish
   and across the first failures (:mod:`tuner.history.twin_edge`): how likely a lap is to fail at each value (the
   failure model), and what a finished lap shows at each value, its lap time and the line's mean offset from the
   sensor array's centre and the side it runs on, with their scatter lap to lap (the observation model);
2. the degradation state (the value, its rate, whether the wear speeds up) is estimated lap by lap by a particle
   filter from every finished lap on the gains in force, read through the observation model (the lap time and,
   where the link carries the telemetry, the line's offset and side: ``xte_mean_m`` and ``line_side_m`` in the
   history, :data:`COLUMNS`), every lap outcome,
   finished or failed, and the alignments of laps before those (an alignment of laps the filter reads already is
   the same evidence again, so it is not counted twice; estimates from failed laps are never evidence);
3. before that, a check that wear of this parameter alone explains the last laps: with two features or more a
   lap lies on the twin's curve or off it (:func:`one_cause_misfit`); off it, another cause is at work (or more than
   one), and the forecast for this parameter says so and gives no number;
4. a Monte Carlo carries each particle forward, lap by lap, racing each lap against the failure model: the
   distribution of the laps to the first failure (remaining useful life), its median and 90 % interval.

Advice comes from the same distribution: re-tune now when one future in ten fails within ``RETUNE_WITHIN`` laps,
and for a parameter with a service limit (:data:`SERVICE`: the ends of the robust envelope,
:data:`tuner.search.envelope.ROBUST_AXES`) when the futures reach it: replace the tyres, charge the battery.
With fewer than ``MIN_TIMED_LAPS`` timed laps of a part that wears, and fewer than two alignments at different
laps, there is too little evidence: a sentence, no number.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from lf_common.cache import StillBuilding
from tuner.history.trend import measured
from tuner.prognostics import (FailureModel, FilterSettings, LapObservation, Measurement, ObservationModel, Outcome,
                               estimate, life_sentence, measurement_sigma, remaining_life, retune_advice,
                               service_advice, shape_sentence)
from tuner.prognostics.particle_filter import SCALE_PRIOR
from tuner.history.twin_edge import SEEDS as EDGE_SEEDS
from tuner.history.twin_edge import twin_edge
from tuner.search.envelope import ROBUST_AXES
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapLimits

LADDER = 12  # values raced along the trend, one batch
REFINE = 6  # then between the last that finished and the first that failed, one more batch
STILL_RACING = "still racing"  # a forecast's note when the races it reads are still running in another process
LAP_TIMEOUT_S = 30.0  # the longest lap the twin races for a forecast [s]
MIN_MEASURED_LAPS = 2  # alignments at different laps, at least, for a forecast …
MIN_TIMED_LAPS = 8  # … or this many finished laps on the gains in force, read through the twin
SEEDS_LATER = 20  # the twin's noise seeds a value a one-cause forecast's race runs on once the robot has …
SEEDS_LATER_FROM = 30  # … this many timed laps on the gains in force (before: EDGE_SEEDS, 5). From the first
# forecast on, the robot's laps pin its value better than 5 seeds a value pin the twin's curve there: over eight
# draws of the twin's races the forecasts at half of life met α-λ 77 % on 5 seeds a value, 86 % on 20 throughout
# and 83 % on 20 from here (docs/models.md). But 20 take four times as long, and the first forecast, 8 laps in, is to be ready within a lap;
# so live's race-ahead races 5 first, then the rows of both at once, then 20: done 188 s after live started at real
# time on 2 cores beside live's own work (docs/performance.md), where a robot of 7.2 s laps is 26 laps in. The laps
# decide which races a forecast reads, not the clock: the same history gives the same forecast however its races
# came
EDGE_PRIOR = 0.05  # the robot's failure edge lies within this share of the way to it of the twin's (one sd)
MISFIT_WINDOW = 8  # the last laps whose features are checked against wear of one parameter alone, …
MISFIT_DROPPED = 2  # … the worst of them left out: a lap now and then lies far off every value's features (the
# robot's way round the track that the twin's few seeds a value did not show: 19 of 1412 laps the benchmark's
# one-cause robots ran, 1.3 %, beyond the limit below). With one left out, a battery-only robot with two such laps
# and a third at 7 σ within eight was read as both causes at once, 32 laps (31–33) against 58 (issue 35); three in
# eight come about once in 8000 windows
MISFIT_QUANTILE = 0.999  # … against this quantile of their mean's distribution (each lap χ², d − 1 degrees of
# freedom for d features) …
MISFIT_DRAWS = 1 << 19  # windows of laps drawn for that quantile (a fixed seed: the same limit every run)


@functools.cache
def misfit_limit(features: int) -> float:
    """… so the most their mean misfit may be, per lap, for a robot scattering up to the filter's largest noise
    scale more than the twin: the 99.9 % point of the mean of the best MISFIT_WINDOW − MISFIT_DROPPED of
    MISFIT_WINDOW laps' χ² with features − 1 degrees of freedom, times that scale squared (17.0 for two features,
    30.2 for three). No table gives a trimmed mean's quantile, so it is drawn: 2¹⁹ windows on a fixed seed, within
    0.5 % of the exact point (tests/test_lap_features.py checks it against the closed form for two degrees of
    freedom). The bound χ²(kept·(d − 1))/kept used before (the best laps scatter less than as many drawn at random)
    is loose by half with two left out (49.4 for three features): on five of the benchmark's six robots wearing
    both at once the joint forecast came a forecast later, at lap 18, not 15 (issue 35)."""
    if features < 2:
        raise ValueError(f"a misfit needs two features or more, not {features}")
    rng = np.random.default_rng(20261206)
    means = np.concatenate([
        np.sort((rng.standard_normal((MISFIT_DRAWS >> 3, MISFIT_WINDOW, features - 1)) ** 2).sum(axis=2),
                axis=1)[:, :MISFIT_WINDOW - MISFIT_DROPPED].mean(axis=1) for _ in range(8)])  # (in 8 parts: memory)
    return SCALE_PRIOR[1] ** 2 * float(np.quantile(means, MISFIT_QUANTILE))


# each feature of the observation model (tuner.history.twin_edge.FEATURES) and the history's column that holds it
COLUMNS = {"lap_time_s": "lap_time_s", "line_offset_m": "xte_mean_m", "line_side_m": "line_side_m"}
# where a parameter needs service, and what to do: the worn end of the robust envelope
SERVICE = {"motion.mu": (min(ROBUST_AXES["motion.mu"]), "replace the tyres"),
           "motor.supply_voltage": (min(ROBUST_AXES["motor.supply_voltage"]), "charge or replace the battery")}


@dataclasses.dataclass(frozen=True)
class FilterInputs:
    """What one cause's forecast gave its particle filter (:func:`tuner.prognostics.estimate`), as it gave it: for a
    check of the filter against another estimator on the same evidence (benchmarks/bench_forecast.py)."""
    measurements: tuple[Measurement, ...]
    outcomes: tuple[Outcome, ...]
    observations: tuple[LapObservation, ...]
    model: ObservationModel | None
    failure: FailureModel
    settings: FilterSettings
    now_lap: int


@dataclasses.dataclass(frozen=True)
class Forecast:
    """The forecast for one parameter. Laps are counted after ``now_lap`` (the robot's last lap seen)."""
    address: str
    now_lap: int
    statement: str  # what a person reads
    value_now: float | None  # the filter's median at now_lap
    value_band: tuple[float, float] | None  # its 90 % interval
    rate: tuple[float, float, float] | None  # per lap: 5 %, 50 %, 95 %
    failing_value: float | None  # where the twin first fails the gains in force (None: not within the range raced)
    laps_to_failure: float | None  # the median laps to the first failure (0: they fail already; None: no number)
    interval: tuple[float | None, float | None] | None  # 90 %; None at an end: open (beyond the horizon)
    quantiles: dict | None  # {"5": …, "95": …} laps; None: beyond the horizon
    raced: tuple[float, float] | None  # the range of values raced
    laps: int  # twin laps run
    evidence: dict  # {"alignments": n, "laps": n, "failed": n}: what the estimate rests on
    band: tuple  # (lap, 5 %, median, 95 %) of the value, lap by lap
    advice: tuple[str, ...]
    note: str
    misfit: float | None = None  # the last laps' mean distance from what wear of this parameter alone gives
    shapes: dict | None = None  # a part that only wears: {"straight"|"speeding_up": {"share", "median"}} of the futures
    causes: dict | None = None  # two causes at once (:mod:`tuner.history.two_causes`): per address its value_now,
    # value_band, rate and band, as the fields above give them for one

    def summary(self) -> dict:
        return dataclasses.asdict(self)


def _fails(twin: DigitalTwin, gains: dict, address: str, values, seeds: int, seed: int, limits: LapLimits):
    """For each value: does any seed's lap fail? (one batch)"""
    laps = run_laps(twin, [{**gains, address: float(v)} for v in values for _ in range(seeds)],
                    seed=[seed + k for _ in values for k in range(seeds)], limits=limits, keep_traces=False)
    return [any(not r.completed for r in laps[i * seeds:(i + 1) * seeds]) for i in range(len(values))], len(laps)


def failure_bracket(twin: DigitalTwin, gains: dict, address: str, start: float, end: float, seeds: int, seed: int,
                    limits: LapLimits) -> tuple[float | None, float | None, int]:
    """Racing ``gains`` from ``address`` = ``start`` towards ``end``: (the last value where every lap finished
    before the first where one fails (None: they fail at ``start``), that first failing value (None: none does),
    laps run), refined between the ladder's steps."""
    values = np.linspace(start, end, LADDER)
    fails, laps = _fails(twin, gains, address, values, seeds, seed, limits)
    if fails[0] or not any(fails):
        return (None, float(start), laps) if fails[0] else (float(end), None, laps)
    i = fails.index(True)
    fine = np.linspace(values[i - 1], values[i], REFINE + 2)[1:-1]
    more, n = _fails(twin, gains, address, fine, seeds, seed, limits)
    if not any(more):
        return float(fine[-1]), float(values[i]), laps + n
    j = more.index(True)
    return float(values[i - 1] if j == 0 else fine[j - 1]), float(fine[j]), laps + n


def first_failure(twin: DigitalTwin, gains: dict, address: str, start: float, end: float, seeds: int, seed: int,
                  limits: LapLimits) -> tuple[float | None, bool, int]:
    """Racing ``gains`` from ``address`` = ``start`` towards ``end``: (the first value where a lap fails, refined
    between the ladder's steps; None if none does), whether they fail at ``start`` already, laps run."""
    finished, failing, laps = failure_bracket(twin, gains, address, start, end, seeds, seed, limits)
    return failing, finished is None, laps


def service_direction(twin: DigitalTwin, address: str, known: list[float]) -> float:
    """The way a part that wears one way goes (−1: down): towards its service limit from the twin's value and the
    values measured."""
    return -1.0 if SERVICE[address][0] < max([*known, float(twin.space.get(address))]) else 1.0


def _range_from(twin: DigitalTwin, address: str, unworn: float, direction: float) -> tuple[float, float]:
    p = twin.space.parameter(address)
    end = p.lower if direction < 0 else p.upper
    service = SERVICE.get(address)
    if service is not None and (service[0] - unworn) * direction > 0:
        end = unworn + 2 * (service[0] - unworn)  # twice as far as the service limit: far enough, and finely spaced
    end = float(np.clip(end, p.lower, p.upper))
    # a tenth of the way further back than the least worn value: a robot a little better than it fits in
    return float(np.clip(unworn - 0.1 * (end - unworn), p.lower, p.upper)), end


def race_range(twin: DigitalTwin, address: str, known: list[float], direction: float) -> tuple[float, float]:
    """(start, end) of the values the twin races the gains at, from the twin's value of ``address`` towards where
    the wear goes (``direction``); only a value measured less worn than that start moves it. So the range, and
    the race, are the robot's history's only in that rare case: a race run ahead (:func:`race_ahead`) is the one a
    forecast asks for."""
    start, end = _range_from(twin, address, float(twin.space.get(address)), direction)
    unworn = max(known, default=start) if direction < 0 else min(known, default=start)
    if (unworn - start) * direction < 0:
        start, end = _range_from(twin, address, unworn, direction)
    return start, end


def edge_seeds(timed_laps: int) -> int:
    """The twin's noise seeds a value a one-cause forecast's race runs on, given the robot's timed laps on the gains
    in force (:data:`SEEDS_LATER_FROM`)."""
    return SEEDS_LATER if timed_laps >= SEEDS_LATER_FROM else EDGE_SEEDS


def race_ahead(twin: DigitalTwin, gains: dict, seed: int = 0, lap_timeout_s: float = LAP_TIMEOUT_S,
               seeds: int = EDGE_SEEDS) -> dict:
    """Race ``gains`` on the twin for each part that wears (:data:`SERVICE`) as a forecast on them will ask on
    ``seeds`` noise seeds a value (the cache keeps each race): {address: the race}. ``live`` runs it in the
    background when a robot's gains come into force (:mod:`tuner.history.race_ahead`)."""
    out = {}
    for address in sorted(SERVICE):
        direction = service_direction(twin, address, [])
        start, end = race_range(twin, address, [], direction)
        out[address] = twin_edge(twin, gains, address, start, end, direction, seed,
                                 LapLimits(timeout_s=lap_timeout_s), seeds=seeds)
    return out


def measurements_of(alignments: list[dict], address: str, lap_sd: float | None = None) -> list[Measurement]:
    """The measured alignments of ``address`` (estimates from failed laps are not measurements); each one's standard
    error from its consistent interval and, given ``lap_sd`` (how far one lap time pins the parameter, in its
    unit), from the lap-time scatter of the laps it measured: lap_sd/√n for n laps."""
    out = []
    for a in alignments:
        if a.get("address", address) == address and measured(a):
            last = int(a["lap"])
            first = min(int(a["first_lap"]) if a.get("first_lap") is not None else last, last)
            v = float(a["value"])
            sigma = measurement_sigma(v, a.get("interval"))
            if lap_sd:
                sigma = math.hypot(sigma, lap_sd / math.sqrt(last - first + 1))
            out.append(Measurement(first, last, v, sigma))
    return out


def same_gains(a: dict | None, b: dict) -> bool:
    return bool(a) and all(math.isclose(float(a.get(k, math.nan)), float(v), rel_tol=1e-6, abs_tol=1e-9)
                           for k, v in b.items())


def outcomes_of(laps: list[dict], gains: dict) -> list[Outcome]:
    """Every lap the robot ran on ``gains`` (each ``laps`` row: ``n``, ``completed``, ``gains``)."""
    return [Outcome(int(r["n"]), not r["completed"]) for r in laps if same_gains(r.get("gains"), gains)]


def carried_on(last_read: int, outcomes: list[Outcome], now_lap: int) -> str:
    """What a value now rests on when the robot's last laps were not read ("" when the last lap was): a failed lap
    says only that the value is past where the gains fail, not how far, so the filter carries the wear on at its
    rate from the last lap read, and the band is that rate's, not a reading (issue 35: a battery held at 3.95 V
    read as 3.35 V after its laps began to fail)."""
    since = [o for o in outcomes if last_read < o.lap <= now_lap]
    if now_lap <= last_read or not since:
        return ""
    failed = sum(o.failed for o in since)
    return (f"carried on at its rate from lap {last_read}, the last lap read: the {len(since)} lap(s) since "
            f"({failed} failed) say only which side of the twin's edge it lies")


def no_number(address: str, now_lap: int, statement: str, evidence: dict, note: str, band=()) -> Forecast:
    return Forecast(address, now_lap, statement, None, None, None, None, None, None, None, None, 0, evidence,
                    tuple(band), (), note)


def alone_explains(f: Forecast) -> bool | None:
    """Does wear of ``f``'s parameter alone explain the last laps it read (their misfit within :func:`misfit_limit`
    for the features read)? None: it did not check (one feature, or too few laps read)."""
    return None if f.misfit is None else f.misfit <= misfit_limit(len(f.evidence["features"]))


def one_cause_misfit(model: ObservationModel, obs: list[LapObservation], span: tuple[float, float]) -> float | None:
    """The mean over the last ``MISFIT_WINDOW`` observed laps but the ``MISFIT_DROPPED`` worst of each one's misfit
    (its features' squared Mahalanobis distance from the nearest the twin gives at any value: about χ²(d − 1) when
    the parameter alone explains them); None with one feature (any value fits a lap time)."""
    if len(model.names) < 2:
        return None
    wide = (span[0] - 0.5 * (span[1] - span[0]), span[1] + 0.5 * (span[1] - span[0]))
    each = sorted(model.misfit(o.features, wide) for o in obs[-MISFIT_WINDOW:])
    return float(np.mean(each[:max(len(each) - MISFIT_DROPPED, 1)]))


def carried(laps: list[dict], names: tuple[str, ...] = tuple(COLUMNS)) -> tuple[str, ...]:
    """The features of ``names`` (the lap time first) that the history holds for every finished lap (the line's
    offset and side come from the robot's telemetry: a robot without it, or laps stored before the side was, have
    the lap time alone, or the lap time and the offset)."""
    done = [r for r in laps if r.get("completed")]
    return tuple(n for k, n in enumerate(names) if k == 0 or (done and all(r.get(COLUMNS[n]) is not None
                                                                          for r in done)))


def observations_of(laps: list[dict], gains: dict, now_lap: int,
                    names: tuple[str, ...] = ("lap_time_s",)) -> list[LapObservation]:
    """What each finished, plausible lap on ``gains`` up to ``now_lap`` shows: its features ``names`` (the history's
    columns :data:`COLUMNS`), a lap without one of them left out."""
    out = []
    for r in laps:
        if (r.get("completed") and r.get("lap_time_s") is not None and not r.get("implausible")
                and int(r["n"]) <= now_lap and same_gains(r.get("gains"), gains)):
            x = [r.get(COLUMNS[n]) for n in names]
            if all(v is not None for v in x):
                out.append(LapObservation(int(r["n"]), tuple(float(v) for v in x)))
    return sorted(out, key=lambda o: (o.lap, o.features))  # in lap order, whatever order the rows came in


def forecast_failure(twin: DigitalTwin, gains: dict, alignments: list[dict], laps: list[dict], address: str,
                     now_lap: int, seeds: int | None = None, seed: int = 0, lap_timeout_s: float = LAP_TIMEOUT_S,
                     settings: FilterSettings | None = None, filter_seed: int | None = None,
                     record: dict | None = None, race_wait_s: float | None = None,
                     race_here: bool = True) -> Forecast:
    """When the ``gains`` in force first fail, from the robot's ``alignments`` of ``address`` (each with
    ``first_lap``, ``lap``, ``value``, ``interval``) and its ``laps`` (``n``, ``completed``, ``gains``,
    ``lap_time_s``, ``xte_mean_m``) up to ``now_lap``. Deterministic in its inputs and ``seed``, whatever their
    order. ``filter_seed`` (default ``seed``) seeds the particle filter and the Monte Carlo alone, the races kept:
    another filter seed on the same evidence measures the estimate's own Monte Carlo error. ``record``: a dict
    that gets the filter's inputs under ``address`` (:class:`FilterInputs`) when the filter runs. ``race_wait_s``:
    how long to wait for the twin's race if another process is running it (``live``'s race-ahead; None: until it
    is done); past that, no number, and a statement that says the race is still running (the one answer that
    depends on timing, not on the inputs alone); ``race_here`` False: nor is a race raced here that no process is
    running yet (another process's races are under way, this one is to come from them). ``seeds``: the twin's noise
    seeds a raced value (None: as the robot's timed laps ask, :func:`edge_seeds`)."""
    filter_seed = seed if filter_seed is None else filter_seed
    p = twin.space.parameter(address)
    ms = [m for m in measurements_of(alignments, address) if m.lap <= now_lap]
    outs = sorted((o for o in outcomes_of(laps, gains) if o.lap <= now_lap), key=lambda o: (o.lap, o.failed))
    timed = observations_of(laps, gains, now_lap)
    seeds = edge_seeds(len(timed)) if seeds is None else seeds
    evidence = {"alignments": len(ms), "laps": len(outs), "failed": sum(o.failed for o in outs),
                "timed_laps": len(timed), "edge_seeds": seeds}
    service = SERVICE.get(address)
    enough_laps = service is not None and len(timed) >= MIN_TIMED_LAPS
    if len({m.lap for m in ms}) < MIN_MEASURED_LAPS and not enough_laps:
        return no_number(address, now_lap, f"too little evidence to forecast {address}: {len(ms)} alignment(s) of it "
                          f"at different laps and {len(timed)} timed lap(s) on the gains in force (at least "
                          f"{MIN_MEASURED_LAPS} alignments at different laps, or {MIN_TIMED_LAPS} timed laps of a part "
                          f"that wears one way, are needed)", evidence, "too little evidence")
    known = [m.value for m in ms]
    if service is not None:  # a part that wears one way only (grip, charge): towards its service limit
        direction = service_direction(twin, address, known)
    else:  # else the way the alignments say it goes
        first = estimate(ms, (), now_lap, settings or FilterSettings(span=float(p.upper - p.lower)), None, filter_seed)
        direction = -1.0 if first.rate_quantiles((0.5,))[0] <= 0 else 1.0
    start, end = race_range(twin, address, known, direction)
    try:
        edge = twin_edge(twin, gains, address, start, end, direction, seed, LapLimits(timeout_s=lap_timeout_s),
                         seeds=seeds, wait_s=race_wait_s, race_here=race_here)
    except StillBuilding:
        return dataclasses.replace(no_number(
            address, now_lap, f"the twin's race of {address} on the gains in force is still to come from another "
            "process's races (live's race-ahead, or another history): no number yet, ask again",
            evidence, STILL_RACING), raced=(start, end))
    failure, failing, raced = edge.failure, edge.failing, edge.laps
    if failure is None:
        return dataclasses.replace(
            no_number(address, now_lap, f"the gains in force finish every lap the twin raced for {address} from "
                       f"{start:.4g} to {end:.4g}: no failure to forecast", evidence,
                       "no failure within the range raced"),
            raced=(start, end), laps=raced)
    model = edge.observation
    if model is not None:
        model = model.subset(carried(laps, model.names))
        obs = [o for o in observations_of(laps, gains, now_lap, model.names) if model.reads(o.features)]
    else:
        obs = []
    if len(obs) < MIN_TIMED_LAPS:
        obs = []
    misfit = one_cause_misfit(model, obs, (min(start, end), max(start, end))) if obs else None
    evidence["features"] = list(model.names) if obs else []
    if misfit is not None and misfit > misfit_limit(len(model.names)):
        return dataclasses.replace(
            no_number(address, now_lap, f"the robot's last {MISFIT_WINDOW} laps changed in a way wear of {address} "
                       f"alone does not explain (their {', '.join(model.names)} disagree: {misfit:.3g} against at "
                       f"most {misfit_limit(len(model.names)):.3g}): another cause is at work, or more than one; no "
                       f"number for {address}", evidence, "not explained by one cause"),
            raced=(start, end), laps=raced, failing_value=failure.threshold, misfit=misfit)
    # no lap counted twice: an alignment measured lap times the observations hold already, so only alignments of
    # laps before the first observed lap are evidence beside them
    before = min((o.lap for o in obs), default=math.inf)
    kept = [m for m in measurements_of(alignments, address, edge.value_sd_per_lap()) if m.lap <= now_lap
            and m.lap < before]
    if not kept and not obs:
        return no_number(address, now_lap, f"too little evidence to forecast {address}: no alignment and no lap "
                          "the twin can read", evidence, "too little evidence")
    span = max(abs(start - failure.threshold), 1e-3 * max(abs(start), 1.0))
    lo_range = min(start, failure.threshold) - 0.5 * span
    hi_range = max(start, failure.threshold) + 0.5 * span
    settings = settings or FilterSettings(span=span, value_range=(lo_range, hi_range),
                                          one_way=direction if service is not None else 0.0,
                                          edge_prior=EDGE_PRIOR * span)
    if record is not None:
        record[address] = FilterInputs(tuple(kept), tuple(outs), tuple(obs), model if obs else None, failure,
                                       settings, now_lap)
    state = estimate(kept, outs, now_lap, settings, failure, filter_seed, obs, model)
    life = remaining_life(state, failure, settings.q, filter_seed + 1,
                          service_limit=service[0] if service is not None else None)
    already = bool(outs) and outs[-1].failed and outs[-1].lap == now_lap
    lo, med, hi = state.quantiles()
    last_read = max([o.lap for o in obs] + [m.lap for m in kept])
    evidence["observed_laps"] = len(obs)
    evidence["alignments_used"] = len(kept)  # those of laps before the first lap read
    evidence["last_read_lap"] = last_read  # the value now is carried on from here (carried_on)
    advice: list[str] = []
    if already:
        statement = f"the gains in force already fail (the robot's last lap, {now_lap}, did)"
        laps_to, interval = 0.0, (0.0, 0.0)
        advice.append(f"re-tune now: the gains in force already fail (live --act does it, or tune with --set "
                      f"{address}={failure.threshold:.4g})")
    else:
        statement = life_sentence(life)
        humps = shape_sentence(life)
        if humps:
            statement = f"{statement}; {humps}"
        q = life.quantiles()
        laps_to, interval = q["50"], (q["5"], q["95"])
        retune = retune_advice(life, address, failure.threshold)
        if retune:
            advice.append(retune)
    if service is not None:
        said = service_advice(life, service[1], address, service[0])
        if said:
            advice.append(said)
    read = f"{len(obs)} laps read through the twin ({', '.join(model.names)})" if obs else "no lap read"
    since = carried_on(last_read, outs, now_lap)
    evidence["carried_on"] = bool(since)  # the value now is not read but carried on from last_read_lap
    note = (f"{address} is {med:.4g} now (90 % {lo:.4g}–{hi:.4g}{'; ' + since if since else ''}), from "
            f"{len(kept)} alignments, {read} and "
            f"{evidence['laps']} lap outcomes on these gains ({evidence['failed']} failed); on the twin half their "
            f"laps fail at {failure.threshold:.4g} (the first failure raced at {failing:.4g}; {seeds} noise seeds a "
            "value)")
    return Forecast(address, now_lap, statement, med, (lo, hi), state.rate_quantiles(), failure.threshold, laps_to,
                    interval, life.quantiles(), (start, end), raced, evidence, tuple(state.band), tuple(advice), note,
                    misfit, life.by_shape())
