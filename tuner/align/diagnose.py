"""Diagnosis of a robot slower (or faster) than its twin: which single change to the twin explains it best.

For each candidate cause (default: the physical parameters that the twin's learned influences say move the lap time
most, :func:`default_candidates`; without them tyre grip, battery, motor winding resistance, payload):

1. the aligner (:func:`tuner.align.lap_time.align_lap_time`, refined scan, every disjoint range) finds the value that
   explains the measured lap time within the candidate's search range, nearest the twin's own value; a
   candidate that rebuilds the robot (payload, ``cad.*``) runs one build per value;
2. the value is compared with the candidate's documented physical range (:data:`CANDIDATES`): how far it is
   from nominal, in units of that range (``deviation`` ≤ 1 inside it);
3. with telemetry, the twin's lap at that value is compared with the run's encoder traces (wheel speeds at
   equal odometric distance, rms): the cause that reproduces the traces, not only the lap time, ranks first.

Ranking: candidates that explain the measurement first; among them, with telemetry, the smaller trace
mismatch; without, the smaller deviation (the smallest plausible change). With telemetry the two best
batchable candidates are then fitted jointly (:func:`tuner.align.trace.align_telemetry`), which says whether the
run tells them apart.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np

from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.model.identifiability import unresolved
from twin.model.space import ChangeCost
from twin.telemetry.jsonl import Telemetry
from tuner.align.lap_time import LapTimeAlignment, align_lap_time
from tuner.align.trace import TraceAlignment, align_telemetry, wheel_residuals
from tuner.search.space import TunerError
from tuner.sensitivity import ASSUMED, PHYSICAL_RANGES, diagnosis_candidates
from tuner.sensitivity import load as load_learned


@dataclasses.dataclass(frozen=True)
class Cause:
    """A candidate's search range and documented physical range, as factors of the twin's own value."""

    what: str
    search: tuple[float, float]
    plausible: tuple[float, float]
    source: str


def _documented(what: str, search: tuple[float, float], address: str) -> Cause:
    r = PHYSICAL_RANGES[address]
    return Cause(what, search, (r.low, r.high), r.source)


CANDIDATES: dict[str, Cause] = {
    "motion.mu": _documented("tyre grip", (1 / 6, 2.2), "motion.mu"),
    "motor.supply_voltage": _documented("battery voltage", (0.5, 1.2), "motor.supply_voltage"),
    "motor.R_M": _documented("motor winding resistance", (0.5, 3.0), "motor.R_M"),
    "cad.m_c": _documented("payload (chassis mass)", (0.8, 3.0), "cad.m_c"),
}
DEFAULT_CANDIDATES = tuple(CANDIDATES)
GENERIC = Cause("parameter", (1 / 3, 3.0), (ASSUMED.low, ASSUMED.high), ASSUMED.source)


def cause_of(twin: DigitalTwin, address: str) -> Cause:
    """A candidate's ranges: its own (:data:`CANDIDATES`), else its documented physical range
    (:data:`tuner.sensitivity.PHYSICAL_RANGES`) searched a factor of 3 either way, else :data:`GENERIC`."""
    if address in CANDIDATES:
        return CANDIDATES[address]
    what = twin.space.parameter(address).description or GENERIC.what
    r = PHYSICAL_RANGES.get(address)
    if r is None:
        return dataclasses.replace(GENERIC, what=what)
    return Cause(what, (min(GENERIC.search[0], r.low), max(GENERIC.search[1], r.high)), (r.low, r.high), r.source)


def default_candidates(twin: DigitalTwin) -> tuple[tuple[str, ...], str]:
    """The candidate causes when none are given, and where they come from: the physical parameters the learned
    influences of this twin say move the lap time (``graph --learn``, :func:`tuner.sensitivity.diagnosis_candidates`),
    else :data:`DEFAULT_CANDIDATES`."""
    analysis, source = load_learned(twin)
    if analysis is None:
        return DEFAULT_CANDIDATES, f"the four default candidates: {source}"
    learned = tuple(diagnosis_candidates(analysis))
    if not learned:
        return DEFAULT_CANDIDATES, (f"the four default candidates: the {source} name no physical parameter that moves "
                                    "the lap time by 1 % over its range")
    return learned, f"the causes that move the lap time most, from the {source}"


@dataclasses.dataclass(frozen=True)
class Diagnosis:
    """One candidate: the value that explains the measurement (if any) and how plausible it is."""

    address: str
    cause: str
    nominal: float
    value: float | None
    explained: bool
    change: float | None  # value / nominal − 1
    deviation: float | None  # |ln(value/nominal)| / |ln(plausible bound on that side)|; ≤ 1 inside
    plausible: bool
    plausible_range: tuple[float, float]
    lap_time_s: float | None
    trace_rms_radps: float | None  # wheel-speed mismatch with the run's telemetry at that value
    solutions: int  # disjoint ranges of values that explain it
    laps: int
    message: str
    source: str
    ci95: tuple[float, float] | None = None  # if this is the cause, its value's 95 % interval (from the lap time)
    consistent: tuple[float, float] | None = None  # the values the laps cannot tell from the measurement
    ranges: tuple[tuple[tuple[float, float], str], ...] = ()  # every disjoint range that explains it: its 95 %
    # interval ("ci95"), or its consistent range where the lap time does not pin it ("consistent"); the value's first


@dataclasses.dataclass(frozen=True)
class DiagnosisReport:
    measured_lap_time_s: float
    nominal_lap_time_s: float | None
    candidates: tuple[Diagnosis, ...]  # best first
    joint: TraceAlignment | None  # the two best batchable candidates fitted together to the telemetry
    skipped: tuple[str, ...]  # candidates that do not apply to this robot, with the reason


def _deviation(value: float, nominal: float, cause: Cause) -> float:
    if value <= 0 or nominal <= 0:
        return math.inf
    bound = cause.plausible[0] if value < nominal else cause.plausible[1]
    return abs(math.log(value / nominal)) / max(abs(math.log(bound)), 1e-12)


def _trace_rms(twin: DigitalTwin, address: str, value: float, tel: Telemetry, seed: int) -> float:
    if twin.space.parameter(address).cost is ChangeCost.REBUILD:
        other = twin.clone({address: value})
        lap = run_laps(other, [{}], seed=seed)[0]
    else:
        lap = run_laps(twin, [{address: value}], seed=seed)[0]
    return float(np.sqrt(np.mean(wheel_residuals(lap, tel, twin.info.wheel_radius) ** 2)))


def explaining(r: LapTimeAlignment) -> tuple[tuple[tuple[float, float], str], ...]:
    """Every range of values that explains the lap time, with what it is: each solution's 95 % interval ("ci95"),
    else its consistent range ("consistent"); the chosen value's first."""
    ordered = sorted(r.solutions, key=lambda x: x.value != r.value)
    return tuple((tuple(x.ci95), "ci95") if x.ci95 else (tuple(x.consistent), "consistent") for x in ordered)


def diagnose_one(twin: DigitalTwin, measured: float, address: str, tel: Telemetry | None = None, seed: int = 0,
                 nthread: int = 0) -> Diagnosis:
    cause = cause_of(twin, address)
    p = twin.space.parameter(address)
    nominal = twin.space.get(address)
    if nominal <= 0:
        raise TunerError(f"diagnosis {address}: its value {nominal:g} is not positive, so it has no ratio to search")
    bounds = (max(p.lower, nominal * cause.search[0]), min(p.upper, nominal * cause.search[1]))
    r: LapTimeAlignment = align_lap_time(twin, measured, address, bounds=bounds, seed=seed, nthread=nthread,
                                         bounds_flag=f"align --param {address} --bounds")  # (diagnose has no --bounds)
    rng = (nominal * cause.plausible[0], nominal * cause.plausible[1])
    if not r.explained or r.value is None:
        return Diagnosis(address, cause.what, nominal, None, False, None, None, False, rng, r.simulated_lap_time_s,
                         None, 0, r.laps, r.message, cause.source)
    deviation = _deviation(r.value, nominal, cause)
    rms = _trace_rms(twin, address, r.value, tel, seed) if tel is not None else None
    return Diagnosis(address, cause.what, nominal, r.value, True, r.value / nominal - 1, deviation,
                     rng[0] <= r.value <= rng[1], rng, r.simulated_lap_time_s, rms, len(r.solutions), r.laps,
                     r.message, cause.source, r.ci95, r.consistent, explaining(r))


def _rank_key(d: Diagnosis):
    if not d.explained:
        return (1, math.inf, math.inf)
    return (0, d.trace_rms_radps if d.trace_rms_radps is not None else 0.0, d.deviation)


def diagnose(twin: DigitalTwin, measured: float | None, candidates: Sequence[str] = DEFAULT_CANDIDATES,
             tel: Telemetry | None = None, seed: int = 0, nthread: int = 0,
             on_candidate=None, joint: bool = True) -> DiagnosisReport:
    """Rank the candidates (see the module docstring). ``measured`` defaults to the telemetry's lap time;
    ``joint``: with telemetry, also fit the best two together (the most expensive step)."""
    if measured is None:
        measured = tel.lap_time_s if tel is not None else None
    if measured is None or not (math.isfinite(measured) and measured > 0):
        raise TunerError("diagnosis: needs a measured lap time (or telemetry with a completed lap)")
    if not candidates or len(set(candidates)) != len(candidates):
        raise TunerError("diagnosis: give each candidate once")
    for a in candidates:
        if twin.space.parameter(a).integer:
            raise TunerError(f"diagnosis {a}: a whole-number parameter cannot explain a lap time by degrees")
    skipped, usable = [], []
    for a in candidates:
        if a.startswith("cad.") and twin.robot_urdf is not None:
            skipped.append(f"{a}: the robot comes from a URDF; its geometry and masses are not parameters")
        elif why := unresolved(twin.space.values, a):
            skipped.append(why)
        else:
            usable.append(a)
    nominal_lap = run_laps(twin, [{}], seed=seed, nthread=nthread, keep_traces=False)[0]
    results = []
    for a in usable:
        results.append(diagnose_one(twin, measured, a, tel, seed, nthread))
        if on_candidate is not None:
            on_candidate(results[-1])
    ranked = tuple(sorted(results, key=_rank_key))
    pair_fit = None
    if tel is not None and joint:
        pair = [d.address for d in ranked if d.explained and twin.space.parameter(d.address).cost is not ChangeCost.REBUILD][:2]
        if len(pair) == 2:
            pair_fit = align_telemetry(twin, tel, pair, seed=seed, nthread=nthread,
                                       start={d.address: d.value for d in ranked if d.address in pair})
    return DiagnosisReport(measured, nominal_lap.lap_time_s if nominal_lap.completed else None, ranked, pair_fit,
                           tuple(skipped))
