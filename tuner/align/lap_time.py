"""Alignment to a measured lap time (paper §4.1, Fig. 6): find every value of one parameter (tyre friction μ by
default) for which the simulated lap time equals the robot's measured one.

Gradient descent on (t_sim(p) − t_measured)², as in the paper, safeguarded for where it fails:

1. **Scan** (one batch): the lap at ``SCAN_POINTS`` values across the allowed range. This gives the range of
   lap times the parameter can explain; a measurement outside it is reported as unexplained, with that
   range, instead of returning the nearest bound as if it were an answer.
2. **Refine** (one batch per round, at most ``REFINE_ROUNDS`` rounds and ``REFINE_LAPS`` laps): t(p) can be steep
   and narrow, just above the grip limit, where eight scan points miss it. A midpoint is added between
   neighbours where one lap fails and the other completes, when the laps between them may take the measurement
   (t(p) runs on steeply towards a limit the way it runs into it, so the measurement lies that way, or within one
   step of the last completed lap), and between neighbours whose lap times differ by more than the measurement's
   tolerance and by more than half the spread of their own laps (nearer than that the noise, not the parameter,
   orders them) while the measurement lies within their reach (between them, or within one such difference of
   them). Only while no lap explains the measurement does it also refine between neighbours whose lap times differ
   by more than ``JUMP`` (a step in t(p) or a steep stretch: refined until it is known which), for the lap times
   it reports it can give instead. Those are reported as intervals (:func:`reachable_intervals`): a failing lap
   between two values, or a step that refinement narrowed to ``FLOOR`` of the value without closing, separates
   two intervals.
3. **Brackets**: every pair of neighbouring scan values whose lap times straddle the measurement.
4. **Descend** inside each bracket. Each iteration is one batch of three laps (p and p(1 ± h)) for the residual
   r = t − t_m and its slope; the step is the Gauss–Newton step on r² (gradient descent with γ = 1/(2 r'²)).
   Where t(p) is flat (tyres that never slip give no gradient) or the step leaves the bracket, bisect
   instead; every lap narrows the bracket by the sign of its residual. Stops at |r| ≤ ``TOLERANCE``·t_m.

The default search range (:func:`default_range`) is the parameter's documented physical range where the model
space declares one (tyre friction: 0.05, rubber on dusty paper or vinyl, to 2.0, soft rubber on a grippy mat),
else a factor of ``RELATIVE_RANGE`` either side of the current value; ``bounds`` (``--bounds``) overrides it.

A measured lap time is one lap: one draw of the sensors' noise. Far from a limit that hardly matters, but near the
grip limit, where the robot slides and recovers, laps of the same robot differ by a few per cent from one noise draw
to the next (2 % at μ 0.6 with robust gains and the robot's timing). So each value is raced on ``NOISE_SEEDS`` seeds
(``seed``, ``seed`` + 1, …): its lap time is the median of the laps that complete (a value whose laps mostly fail
fails), and the fastest and slowest of them are kept as its spread. The scan, the brackets and the descent follow
the medians; the reachable lap times are the medians' intervals, and the single laps seen are reported beside them.

Every lap run on the way is kept. Around each solution, the values the laps cannot tell from the measurement give a
range it is consistent with: those whose median lies within ``ACCEPT_Z`` σ of one lap of it (σ, the lap-to-lap
scatter there, from the ranges of the nearest values' laps) or whose spread of laps holds it, widened to the nearest
value on either side that excludes itself. Disjoint ranges are all reported (ranges less than ``JUMP`` of the value
apart are one: near a limit the noise makes t(p) jagged), and the value returned is the one nearest the twin's
current value (the robot changed least). When a range is wide (lap time hardly depends on the parameter there), the
result says the parameter is not identifiable from a lap time alone.

5. **Interval** (:mod:`tuner.align.lap_interval`): each solution's 95 % interval. The range of 39 laps at it
   holds one more lap, the robot's, at 95 % whatever the noise's shape; 8 laps either side of it on the same seeds
   give the slope that turns that range into values (:mod:`tuner.align.calibration`), widened until it lies inside
   the values the slope was taken over; none where the lap time is not a straight, clearly sloped function there (a
   limit, or too flat for one lap to pin it). Its coverage, and the consistent range's where there is none, is
   measured by :mod:`tuner.studies.coverage` (``tests/test_case2.py``, ``benchmarks/bench_case_studies.py``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapLimits
from twin.model.identifiability import unresolved
from tuner.align.calibration import local_scatter, median_variance
from tuner.align.lap_interval import laps_on_seeds, with_intervals
from tuner.search.space import TunerError

SCAN_POINTS = 8
NOISE_SEEDS = 3  # laps per value, on consecutive seeds: its median and spread
REFINE_ROUNDS = 12  # midpoint rounds after the scan, one batch each: a band of 1 % of the range takes ~10
REFINE_LAPS = 40  # at most this many refinement laps in all
# parameters whose model-space range is their documented physical range: searched over all of it by default
# (friction coefficients: a line follower with soft enough gains holds the track down to where its laps fail)
PHYSICAL_RANGE = ("motion.mu", "motion.floor_mu")
RELATIVE_RANGE = 3.0  # other parameters: from a third to three times their current value
JUMP = 0.01  # neighbouring lap times further apart than this fraction are refined, to tell a step from a slope
FLOOR = 1e-4  # values closer than this fraction are as fine as a scan goes
REL_STEP = 0.01  # finite-difference step, relative to the value
TOLERANCE = 0.001  # aim for 0.1 %; success is within 0.5 % (ACCEPT)
ACCEPT = 0.005
IDENTIFIABLE_SPAN = 0.10  # a consistent range wider than this fraction of the value: not identifiable
SLOWEST = 3.0  # a lap not done after this many times the measurement cannot explain it: it ends as a timeout


@dataclasses.dataclass(frozen=True)
class AlignPoint:
    """One lap of the alignment: the parameter value and its lap time (None if the lap failed)."""

    iteration: int  # 0: the scan
    value: float
    lap_time_s: float | None  # the median of its laps that completed (None if most of them failed)
    spread_s: tuple[float, float] | None = None  # its fastest and slowest completed lap


@dataclasses.dataclass(frozen=True)
class Solution:
    """One value that explains the measurement, and the range of values around it that do too."""

    value: float
    lap_time_s: float
    consistent: tuple[float, float]  # values the laps run cannot tell from the measurement, around it
    identifiable: bool  # that range is narrow (< IDENTIFIABLE_SPAN of the value)
    ci95: tuple[float, float] | None = None  # values whose single lap holds the measurement at 95 % (lap_interval)


@dataclasses.dataclass(frozen=True)
class LapTimeAlignment:
    parameter: str
    value: float | None  # None when no value explains the measurement
    simulated_lap_time_s: float | None
    measured_lap_time_s: float
    explained: bool  # within ACCEPT of the measurement
    iterations: int
    laps: int  # laps run: values × noise seeds
    reachable_s: tuple[float, float] | None  # fastest and slowest median the scan found (the hull of the intervals)
    consistent: tuple[float, float] | None  # the chosen solution's consistent range
    identifiable: bool  # the chosen solution's range is narrow and it is the only one
    message: str
    trace: tuple[AlignPoint, ...]
    solutions: tuple[Solution, ...] = ()  # every disjoint range that explains the measurement
    reachable_intervals_s: tuple[tuple[float, float], ...] = ()  # the lap times it can give, as disjoint intervals
    bounds: tuple[float, float] | None = None  # the range searched
    single_laps_s: tuple[float, float] | None = None  # fastest and slowest single lap run on the way
    noise_seeds: int = NOISE_SEEDS  # laps per value
    ci95: tuple[float, float] | None = None  # the chosen solution's 95 % interval (None: not pinned, or no solution)

    def summary(self) -> dict:
        d = dataclasses.asdict(self)
        d["trace"] = [dataclasses.asdict(p) for p in self.trace]
        d["solutions"] = [dataclasses.asdict(x) for x in self.solutions]
        return d


def _lap_times(twin: DigitalTwin, address: str, values, seed: int, nthread: int, limits: LapLimits = LapLimits(),
               noise_seeds: int = NOISE_SEEDS) -> list[tuple[float | None, tuple[float, float] | None]]:
    """Each value's (median lap time or None, spread) over ``noise_seeds`` seeds from ``seed``: one batch, or, for a
    parameter that rebuilds the robot, one build per value."""
    results = laps_on_seeds(twin, address, values, seed, nthread, limits, noise_seeds)
    out = []
    for i in range(len(values)):
        laps = [r.lap_time_s for r in results[i * noise_seeds:(i + 1) * noise_seeds] if r.completed]
        median = float(np.median(laps)) if 2 * len(laps) > noise_seeds else None
        out.append((median, (min(laps), max(laps)) if laps else None))
    return out


def _midpoint(a: float, b: float) -> float:
    return math.sqrt(a * b) if a > 0 else 0.5 * (a + b)


def default_range(twin: DigitalTwin, address: str) -> tuple[float, float]:
    """The range searched when none is given: the model space's range of a parameter in ``PHYSICAL_RANGE``, else a
    factor of ``RELATIVE_RANGE`` either side of the current value, inside the model space's range."""
    p = twin.space.parameter(address)
    v = twin.space.get(address)
    if address in PHYSICAL_RANGE or v <= 0:
        return (p.lower, p.upper)
    return (max(p.lower, v / RELATIVE_RANGE), min(p.upper, v * RELATIVE_RANGE))


def _resolved(a: float, b: float) -> bool:
    return b - a <= FLOOR * max(abs(a), abs(b), 1e-9)


def refine_midpoints(points: list[tuple[float, float | None]], m: float, tol: float,
            spreads: dict[float, tuple[float, float] | None] | None = None) -> tuple[list[float], list[float]]:
    """Where the scan may have stepped over a crossing or a step: (midpoints where a crossing may hide, midpoints
    where t(p) only jumps by more than ``JUMP`` far from the measurement). Neighbours whose medians differ by no
    more than half the spread of their own laps (``spreads``: each value's fastest and slowest lap) are not told
    apart by a value between them: the noise, not the parameter, orders them there (near a limit t(p) is jagged)."""
    half = {v: 0.5 * (s[1] - s[0]) for v, s in (spreads or {}).items() if s}
    near, jumps = [], []
    for i, ((a, ta), (b, tb)) in enumerate(zip(points, points[1:])):
        if _resolved(a, b):
            continue  # as fine as it is worth going
        if (ta is None) != (tb is None):
            if _band_may_reach(points, i + 1 if ta is None else i, -1 if ta is None else 1, m):
                near.append(_midpoint(a, b))
        elif ta is not None and abs(ta - tb) > max(tol * m, half.get(a, 0.0), half.get(b, 0.0)):
            reach = abs(ta - tb)
            if min(ta, tb) - reach <= m <= max(ta, tb) + reach:
                near.append(_midpoint(a, b))
            elif reach > JUMP * min(ta, tb):
                jumps.append(_midpoint(a, b))
    return near, jumps


def _band_may_reach(points: list[tuple[float, float | None]], k: int, away: int, m: float) -> bool:
    """Whether the laps between the completed value ``points[k]`` and the failed one beside it (``away``: -1 below,
    +1 above) may take the measured ``m``: near a limit t(p) runs on steeply the way it runs into ``points[k]`` from
    its completed neighbour on the other side, so ``m`` must lie that way, or within one such step of it. Without
    that neighbour (or a failed one there) anything may lie in the band."""
    j = k - away
    if not 0 <= j < len(points) or points[j][1] is None:
        return True
    tb, tc = points[k][1], points[j][1]
    return (m - tb) * math.copysign(1.0, tb - tc) >= -abs(tb - tc)


def _explained(points: list[tuple[float, float | None]], m: float, tol: float) -> bool:
    """Some completed neighbours straddle the measurement, or a lap lies within ``tol`` of it."""
    done = [t for _, t in points if t is not None]
    return any(abs(t - m) <= tol * m for t in done) or any((a - m) * (b - m) < 0 for a, b in zip(done, done[1:]))


def reachable_intervals(points: list[tuple[float, float | None]]) -> list[tuple[float, float]]:
    """The lap times a scan shows the parameter can give, as disjoint intervals, fastest first. ``points``:
    (value, lap time or None for a failed lap). Neighbouring completed values are joined (t(p) taken as continuous
    between them) unless a failed lap lies between them, or their lap times differ by more than ``JUMP`` although
    the values are ``FLOOR`` apart (a step)."""
    groups: list[list[float]] = []
    last: tuple[float, float | None] | None = None
    for v, t in sorted(points):
        if t is None:
            last = (v, None)
            continue
        step = last is not None and last[1] is not None and _resolved(last[0], v) and abs(t - last[1]) > JUMP * min(t, last[1])
        if last is None or last[1] is None or step:
            groups.append([t])
        else:
            groups[-1].append(t)
        last = (v, t)
    spans = sorted((min(g), max(g)) for g in groups)
    merged: list[tuple[float, float]] = []
    for lo, hi in spans:  # the same lap times reached from two ranges of values are one interval
        if merged and lo <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], hi))
        else:
            merged.append((lo, hi))
    return merged


def _solve(twin, address, a, ta, b, tb, m, seed, nthread, max_iter, trace, k0, limits,
           noise_seeds) -> tuple[float, float, int]:
    """Safeguarded Gauss–Newton on (t − m)² inside a bracket [a, b]; returns (value, lap time, iterations). Every
    lap narrows the bracket by the sign of its residual (a failed lap counts as slower than any measurement: it
    lies beyond the limit); an iteration that does not halve the bracket makes the next one a bisection."""
    x = a + (m - ta) * (b - a) / (tb - ta)  # start at the secant
    value, lap = (a, ta) if abs(ta - m) < abs(tb - m) else (b, tb)
    k = 0
    for k in range(1, max_iter + 1):
        width = b - a
        h = min(REL_STEP * max(abs(x), 1e-3), 0.25 * width)
        xs = [x, min(x + h, b), max(x - h, a)]
        laps = _lap_times(twin, address, xs, seed, nthread, limits, noise_seeds)
        trace += [AlignPoint(k0 + k, float(v), tt, spread) for v, (tt, spread) in zip(xs, laps)]
        t = [tt for tt, _ in laps]
        for v, tt in zip(xs, t):
            if tt is not None and abs(tt - m) < abs(lap - m):
                value, lap = v, tt
            side = math.inf if tt is None else tt  # a failed lap: slower than any measurement
            if (side - m) * (ta - m) > 0:
                a, ta = v, side
            else:
                b, tb = v, side
        if abs(lap - m) <= TOLERANCE * m or _resolved(a, b):
            break  # on the measurement, or as fine as values go (near a limit the noise makes t(p) jagged below it)
        slope = None
        if None not in t and xs[1] > xs[2]:
            slope = (t[1] - t[2]) / (xs[1] - xs[2])
        step_ok = False
        if t[0] is not None and slope and abs(slope) > 1e-9 and b - a <= 0.5 * width:
            nxt = x - (t[0] - m) / slope  # Gauss–Newton on (t − m)²
            step_ok = a < nxt < b
        x = nxt if step_ok else 0.5 * (a + b)  # flat, outside the bracket or too slow: bisect
    return value, lap, k


ACCEPT_Z = 2.2  # a value is consistent when its median is within this many σ of one lap (t at 0.975, ~10 d.o.f.)


def _solutions(found: list[tuple[float, float]], trace: list[AlignPoint], m: float,
               noise_seeds: int = NOISE_SEEDS) -> list[Solution]:
    """One :class:`Solution` per disjoint range of values the laps cannot tell from the measurement: the values whose
    median lap is within ``ACCEPT_Z`` σ of one lap of m (σ: :func:`tuner.align.calibration.local_scatter`; at least
    TOLERANCE of m) or whose single laps' spread holds it, widened to the nearest value on each side whose laps do
    not (or fail): between the two, nothing was run that excludes a value."""
    done = sorted({p.value: (p.lap_time_s, p.spread_s) for p in trace}.items())  # the last laps run at a value
    scatter = local_scatter(done, noise_seeds)
    near = [t is not None and (abs(t - m) <= max(TOLERANCE * m, ACCEPT_Z * sd * math.sqrt(1 + median_variance(
        noise_seeds))) or (spread is not None and spread[0] - TOLERANCE * m <= m <= spread[1] + TOLERANCE * m))
            for (_, (t, spread)), sd in zip(done, scatter)]
    out: list[Solution] = []
    for value, lap in sorted(found):
        if abs(lap - m) > ACCEPT * m:
            continue
        i = min(range(len(done)), key=lambda j: abs(done[j][0] - value))
        lo = hi = value
        j = i
        while j - 1 >= 0 and near[j - 1]:  # widen over neighbours that are within tolerance too
            j -= 1
            lo = min(lo, done[j][0])
        if j - 1 >= 0:  # to the first value that excludes itself: the measurement may lie anywhere short of it
            lo = min(lo, done[j - 1][0])
        j = i
        while j + 1 < len(done) and near[j + 1]:
            j += 1
            hi = max(hi, done[j][0])
        if j + 1 < len(done):
            hi = max(hi, done[j + 1][0])
        if out and lo <= out[-1].consistent[1] + JUMP * abs(out[-1].consistent[1]):
            # the same range as the last solution, or one a noise-jagged stretch of t(p) splits from it by less than
            # JUMP of the value: one range, its value the nearer to the measurement
            prev = out[-1]
            keep = prev if abs(prev.lap_time_s - m) <= abs(lap - m) else Solution(value, lap, prev.consistent, True)
            span = (prev.consistent[0], max(prev.consistent[1], hi))
            narrow = span[1] - span[0] <= IDENTIFIABLE_SPAN * max(abs(keep.value), 1e-9)
            out[-1] = Solution(keep.value, keep.lap_time_s, span, narrow)
            continue
        narrow = hi - lo <= IDENTIFIABLE_SPAN * max(abs(value), 1e-9)
        out.append(Solution(value, lap, (lo, hi), narrow))
    return out


def align_lap_time(
    twin: DigitalTwin,
    measured_lap_time_s: float,
    address: str = "motion.mu",
    bounds: tuple[float, float] | None = None,
    seed: int = 0,
    max_iter: int = 20,
    nthread: int = 0,
    limits: LapLimits = LapLimits(),
    bounds_flag: str = "--bounds",
    noise_seeds: int = NOISE_SEEDS,
    interval: bool = True,
) -> LapTimeAlignment:
    """Align one parameter to a measured lap time (see the module docstring). A parameter that rebuilds the robot
    (``cad.*``) is searched too, one build per value, so it costs far more wall time. ``limits``: when a lap fails
    (a timeout near twice the measurement spares the scan laps that crawl to the default 60 s). ``bounds_flag``: how
    the caller's user searches another range (the messages name it). ``interval``: give each solution its 95 %
    interval (55 laps more per solution, up to 165 where the span widens)."""
    if not (isinstance(measured_lap_time_s, (int, float)) and math.isfinite(measured_lap_time_s) and measured_lap_time_s > 0):
        raise TunerError(f"measured lap time: must be a finite number of seconds > 0, got {measured_lap_time_s!r}")
    p = twin.space.parameter(address)
    if p.integer:
        raise TunerError(f"{address}: a whole-number parameter cannot be aligned to a lap time")
    if why := unresolved(twin.space.values, address):
        raise TunerError(why)
    twin.checked_values({address: twin.space.get(address)})  # a cad.* address of a URDF robot: refused here
    given = bounds is not None
    lo, hi = bounds if given else default_range(twin, address)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise TunerError(f"{address}: bounds [{lo:g}, {hi:g}] are inverted, empty or not finite")
    p.check(f"{address} lower bound", lo)
    p.check(f"{address} upper bound", hi)
    m = float(measured_lap_time_s)
    limits = dataclasses.replace(limits, timeout_s=min(limits.timeout_s, SLOWEST * m))
    trace: list[AlignPoint] = []
    current = twin.space.get(address)

    # 1.-2. scan, then refine where a crossing may hide (geometric spacing for a positive parameter: friction
    # acts by ratios)
    values = list(np.geomspace(lo, hi, SCAN_POINTS) if lo > 0 else np.linspace(lo, hi, SCAN_POINTS))
    points: list[tuple[float, float | None]] = []
    spreads: dict[float, tuple[float, float] | None] = {}
    for _ in range(REFINE_ROUNDS + 1):
        values = values[: max(0, SCAN_POINTS + REFINE_LAPS - len(points))]
        if not values:
            break
        laps = _lap_times(twin, address, values, seed, nthread, limits, noise_seeds)
        trace += [AlignPoint(0, float(v), t, spread) for v, (t, spread) in zip(values, laps)]
        times = [t for t, _ in laps]
        points = sorted(points + [(float(v), t) for v, t in zip(values, times)])
        spreads.update((float(v), spread) for v, (_, spread) in zip(values, laps))
        near, jumps = refine_midpoints(points, m, TOLERANCE, spreads)
        # a step far from the measurement matters to the lap times reported when nothing explains it
        values = near or ([] if _explained(points, m, TOLERANCE) else jumps)
    done = [(v, t) for v, t in points if t is not None]
    widen = (f"search another range with {bounds_flag} {address}=LO,HI" if given else
             f"the default range is {address}'s {'documented physical' if address in PHYSICAL_RANGE else 'nearby'} "
             f"range: search another with {bounds_flag} {address}=LO,HI")
    if not done:
        return _result(address, [], m, 0, trace, (), current, (lo, hi), noise_seeds,
                       f"no lap completes for {address} in [{lo:g}, {hi:g}] with these gains; {widen}")
    intervals = reachable_intervals(points)
    # 3. brackets: neighbouring completed values on either side of the measurement, and exact hits
    found = [(v, t) for v, t in done if abs(t - m) <= TOLERANCE * m]
    brackets = [(a, b) for a, b in zip(done, done[1:]) if (a[1] - m) * (b[1] - m) < 0]
    if not brackets and not found:
        where = ("faster" if m < intervals[0][0] else "slower" if m > intervals[-1][1]
                 else "between the intervals it can give")
        return _result(
            address, [], m, 0, trace, intervals, current, (lo, hi), noise_seeds,
            f"no {address} in [{lo:g}, {hi:g}] explains {m:g} s: the simulated lap (the median of {noise_seeds} "
            f"noise seeds) takes {_spans(intervals)} there{_single_laps(trace)} (the measurement is {where}); {widen}, "
            "or check the gains, the track or another parameter")
    # 4. safeguarded Gauss–Newton inside each bracket
    iterations = 0
    for (a, ta), (b, tb) in brackets:
        if any(a <= v <= b or _resolved(min(a, v), max(a, v)) or _resolved(min(b, v), max(b, v)) for v, _ in found):
            continue  # a lap already landed within tolerance here, or beside it
        value, lap, k = _solve(twin, address, a, ta, b, tb, m, seed, nthread, max_iter, trace, iterations, limits,
                               noise_seeds)
        iterations += k
        found.append((value, lap))
    result = _result(address, found, m, iterations, trace, intervals, current, (lo, hi), noise_seeds, None)
    return with_intervals(result, twin, m, seed, nthread, limits) if interval else result


def _spans(intervals: list[tuple[float, float]]) -> str:
    return " or ".join(f"{a:.3f}–{b:.3f} s" for a, b in intervals)


def _single_laps_seen(trace: list[AlignPoint]) -> tuple[float, float] | None:
    spreads = [p.spread_s for p in trace if p.spread_s is not None]
    return (min(lo for lo, _ in spreads), max(hi for _, hi in spreads)) if spreads else None


def _single_laps(trace: list[AlignPoint]) -> str:
    seen = _single_laps_seen(trace)
    return f"; single laps took {seen[0]:.3f}–{seen[1]:.3f} s" if seen else ""


def _result(address: str, found: list[tuple[float, float]], m: float, iterations: int, trace: list[AlignPoint],
            intervals, current: float, bounds: tuple[float, float], noise_seeds: int,
            message: str | None) -> LapTimeAlignment:
    intervals = tuple(tuple(x) for x in intervals)
    reachable = (intervals[0][0], intervals[-1][1]) if intervals else None
    laps = len(trace) * noise_seeds
    extra = {"reachable_intervals_s": intervals, "bounds": bounds, "single_laps_s": _single_laps_seen(trace),
             "noise_seeds": noise_seeds}
    solutions = _solutions(found, trace, m, noise_seeds)
    if not solutions:
        if found:  # brackets were searched but no lap got within ACCEPT: report the closest
            value, lap = min(found, key=lambda vt: abs(vt[1] - m))
            message = message or f"closest {address} = {value:.5g} gives {lap:.3f} s, {100 * (lap - m) / m:+.2f} % off"
            return LapTimeAlignment(address, value, lap, m, False, iterations, laps, reachable, None, False, message,
                                    tuple(trace), **extra)
        return LapTimeAlignment(address, None, None, m, False, iterations, laps, reachable, None, False,
                                message or f"no {address} explains {m:g} s", tuple(trace), **extra)
    def distance(x: Solution) -> float:  # the robot changed least: by ratio for a positive parameter
        return abs(math.log(x.value / current)) if x.value > 0 and current > 0 else abs(x.value - current)

    best = min(solutions, key=distance)
    message = (f"{address} = {best.value:.5g} gives {best.lap_time_s:.3f} s against {m:.3f} s measured "
               f"({100 * (best.lap_time_s - m) / m:+.2f} %)")
    if len(solutions) > 1:
        ranges = "; ".join(f"[{x.consistent[0]:.4g}, {x.consistent[1]:.4g}]" for x in solutions)
        message += (f"; {len(solutions)} disjoint ranges explain it ({ranges}): the one nearest the current "
                    f"{current:.4g} is given")
    if not best.identifiable:
        message += (f"; but every value in [{best.consistent[0]:.4g}, {best.consistent[1]:.4g}] gives a lap within "
                    f"{TOLERANCE * 100:g} %: the lap time hardly depends on it there, so it is not identifiable from "
                    "a lap time alone")
    return LapTimeAlignment(address, best.value, best.lap_time_s, m, True, iterations, laps, reachable,
                            best.consistent, best.identifiable and len(solutions) == 1, message, tuple(trace),
                            tuple(solutions), **extra)
