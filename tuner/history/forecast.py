"""When will the gains in force stop finishing laps? Prognostics as the field does it (:mod:`tuner.prognostics`):

1. the degradation state of each aligned parameter (its value and rate) is estimated lap by lap by a particle filter
   from the robot's alignments (each stamped with the laps it measured; estimates from failed laps are no evidence);
2. the twin races the gains in force at a ladder of values of the parameter (each with a few noise seeds, one
   batch) and fits how likely a lap is to fail at each value (:mod:`tuner.history.twin_edge`), and how far a lap
   time pins the value (the lap time's slope and scatter over seeds): the failure model. Lap times say little about
   this until the failures begin: a line follower keeps its lap time almost to its grip limit, then leaves the track;
3. the filter runs again with every lap the robot ran on the gains in force, finished or failed, as evidence;
4. a Monte Carlo carries each particle forward, lap by lap, racing each lap against the failure model: the
   distribution of the laps to the first failure (remaining useful life), its median and 90 % interval.

Advice comes from the same distribution: re-tune now when one future in ten fails within ``RETUNE_WITHIN`` laps,
and for a parameter with a service limit (:data:`SERVICE`: the ends of the robust envelope,
:data:`tuner.search.envelope.ROBUST_AXES`) when the futures reach it: replace the tyres, charge the battery.
With fewer than two alignments at different laps there is too little evidence: a sentence, no number.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from tuner.history.trend import measured
from tuner.prognostics import (FailureModel, FilterSettings, Measurement, Outcome, estimate, life_sentence,
                               measurement_sigma, remaining_life, retune_advice, service_advice)
from tuner.history.twin_edge import SEEDS as EDGE_SEEDS
from tuner.history.twin_edge import twin_edge
from tuner.search.envelope import ROBUST_AXES
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapLimits

LADDER = 12  # values raced along the trend, one batch
REFINE = 6  # then between the last that finished and the first that failed, one more batch
MIN_MEASURED_LAPS = 2  # alignments at different laps, at least, for a forecast
# where a parameter needs service, and what to do: the worn end of the robust envelope
SERVICE = {"motion.mu": (min(ROBUST_AXES["motion.mu"]), "replace the tyres"),
           "motor.supply_voltage": (min(ROBUST_AXES["motor.supply_voltage"]), "charge or replace the battery")}


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


def _no_number(address: str, now_lap: int, statement: str, evidence: dict, note: str, band=()) -> Forecast:
    return Forecast(address, now_lap, statement, None, None, None, None, None, None, None, None, 0, evidence,
                    tuple(band), (), note)


def forecast_failure(twin: DigitalTwin, gains: dict, alignments: list[dict], laps: list[dict], address: str,
                     now_lap: int, seeds: int = EDGE_SEEDS, seed: int = 0, lap_timeout_s: float = 30.0,
                     settings: FilterSettings | None = None) -> Forecast:
    """When the ``gains`` in force first fail, from the robot's ``alignments`` of ``address`` (in lap order, each
    with ``first_lap``, ``lap``, ``value``, ``interval``) and its ``laps`` (``n``, ``completed``, ``gains``) up
    to ``now_lap``. Deterministic in its inputs and ``seed``."""
    p = twin.space.parameter(address)
    ms = [m for m in measurements_of(alignments, address) if m.lap <= now_lap]
    outs = [o for o in outcomes_of(laps, gains) if o.lap <= now_lap]
    evidence = {"alignments": len(ms), "laps": len(outs), "failed": sum(o.failed for o in outs)}
    if len({m.lap for m in ms}) < MIN_MEASURED_LAPS:
        return _no_number(address, now_lap, f"too little evidence to forecast {address}: {len(ms)} alignment(s) of it "
                          f"(at least {MIN_MEASURED_LAPS} at different laps are needed)", evidence, "too little evidence")
    settings = settings or FilterSettings(span=float(p.upper - p.lower))
    first = estimate(ms, (), now_lap, settings, None, seed)
    now = first.quantiles((0.5,))[0]
    service = SERVICE.get(address)
    if service is not None:  # a part that wears one way only (grip, charge): towards its service limit
        direction = -1.0 if service[0] < max(m.value for m in ms) else 1.0
    else:  # else the way the evidence says it goes
        direction = -1.0 if first.rate_quantiles((0.5,))[0] <= 0 else 1.0
    worn = max(m.value for m in ms) if direction < 0 else min(m.value for m in ms)
    start = float(np.clip(worn, p.lower, p.upper))  # the least worn value measured: the gains finished there
    end = p.lower if direction < 0 else p.upper
    if service is not None and (service[0] - now) * direction > 0:
        end = now + 2 * (service[0] - now)  # twice as far as the service limit: far enough, and finely spaced
    end = float(np.clip(end, p.lower, p.upper))
    edge = twin_edge(twin, gains, address, start, end, direction, seed, LapLimits(timeout_s=lap_timeout_s),
                     seeds=seeds)
    ms = [m for m in measurements_of(alignments, address, edge.value_sd_per_lap()) if m.lap <= now_lap]
    failure, finished, failing, raced = edge.failure, edge.finished, edge.failing, edge.laps
    if failure is None:
        return dataclasses.replace(
            _no_number(address, now_lap, f"the gains in force finish every lap the twin raced for {address} from "
                       f"{start:.4g} to {end:.4g}: no failure to forecast", evidence,
                       "no failure within the range raced", first.band),
            value_now=now, raced=(start, end), laps=raced)
    state = estimate(ms, outs, now_lap, settings, failure, seed)
    life = remaining_life(state, failure, settings.q, seed + 1,
                          service_limit=service[0] if service is not None else None)
    already = bool(outs) and outs[-1].failed and outs[-1].lap == now_lap
    lo, med, hi = state.quantiles()
    advice: list[str] = []
    if already:
        statement = f"the gains in force already fail (the robot's last lap, {now_lap}, did)"
        laps_to, interval = 0.0, (0.0, 0.0)
        advice.append(f"re-tune now: the gains in force already fail (live --act does it, or tune with --set "
                      f"{address}={failure.threshold:.4g})")
    else:
        statement = life_sentence(life)
        q = life.quantiles()
        laps_to, interval = q["50"], (q["5"], q["95"])
        retune = retune_advice(life, address, failure.threshold)
        if retune:
            advice.append(retune)
    if service is not None:
        said = service_advice(life, service[1], address, service[0])
        if said:
            advice.append(said)
    note = (f"{address} is {med:.4g} now (90 % {lo:.4g}–{hi:.4g}), from {evidence['alignments']} alignments and "
            f"{evidence['laps']} laps on these gains ({evidence['failed']} failed); on the twin half their laps fail "
            f"at {failure.threshold:.4g} (the first failure raced at {failing:.4g})")
    return Forecast(address, now_lap, statement, med, (lo, hi), state.rate_quantiles(), failure.threshold, laps_to,
                    interval, life.quantiles(), (start, end), raced, evidence, tuple(state.band), tuple(advice), note)
