"""Alignment to a measured lap time (paper §4.1, Fig. 6): find the value of one parameter (tyre friction μ by
default) for which the simulated lap time equals the robot's measured one.

Gradient descent on (t_sim(p) − t_measured)², as in the paper, safeguarded for where it fails:

1. **Scan** (one batch): the lap at ``SCAN_POINTS`` values across the allowed range. This gives the range of
   lap times the parameter can explain; a measurement outside it is reported as unexplained, with that
   range, instead of returning the nearest bound as if it were an answer.
2. **Bracket**: two neighbouring scan values whose lap times straddle the measurement.
3. **Descend** inside the bracket. Each iteration is one batch of three laps (p and p(1 ± h)) for the residual
   r = t − t_m and its slope; the step is the Gauss–Newton step on r² (gradient descent with γ = 1/(2 r'²)).
   Where t(p) is flat (tyres that never slip give no gradient) or the step leaves the bracket, bisect
   instead; every lap narrows the bracket by the sign of its residual. Stops at |r| ≤ ``tol``·t_m.

Every lap run on the way is kept. The values whose laps land within ``TOLERANCE`` of the measurement give
the range the measurement is consistent with; when that range is wide (lap time hardly depends on the
parameter there), the result says the parameter is not identifiable from a lap time alone.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from twin.closed_loop import run_laps
from twin.digital_twin import DigitalTwin
from twin.lap import LapResult
from twin.model_space import ChangeCost
from tuner.space import TunerError

SCAN_POINTS = 8
DEFAULT_RANGES = {"motion.mu": (0.3, 2.0)}  # below ~0.3 a line follower cannot hold the track at any speed
RELATIVE_RANGE = 3.0  # other parameters: from a third to three times their current value
REL_STEP = 0.01  # finite-difference step, relative to the value
TOLERANCE = 0.001  # aim for 0.1 %; success is within 0.5 % (ACCEPT)
ACCEPT = 0.005
IDENTIFIABLE_SPAN = 0.10  # a consistent range wider than this fraction of the value: not identifiable


@dataclasses.dataclass(frozen=True)
class AlignPoint:
    """One lap of the alignment: the parameter value and its lap time (None if the lap failed)."""

    iteration: int  # 0: the scan
    value: float
    lap_time_s: float | None


@dataclasses.dataclass(frozen=True)
class LapTimeAlignment:
    parameter: str
    value: float | None  # None when no value explains the measurement
    simulated_lap_time_s: float | None
    measured_lap_time_s: float
    explained: bool  # within ACCEPT of the measurement
    iterations: int
    laps: int
    reachable_s: tuple[float, float] | None  # lap times the scan found possible, fastest first
    consistent: tuple[float, float] | None  # values whose laps were within TOLERANCE of the measurement
    identifiable: bool  # the consistent range is narrow (< IDENTIFIABLE_SPAN of the value)
    message: str
    trace: tuple[AlignPoint, ...]

    def summary(self) -> dict:
        d = dataclasses.asdict(self)
        d["trace"] = [dataclasses.asdict(p) for p in self.trace]
        return d


def _result(address, value, lap, m, iterations, trace, reachable, message) -> LapTimeAlignment:
    near = [pt.value for pt in trace if pt.lap_time_s is not None and abs(pt.lap_time_s - m) <= TOLERANCE * m]
    consistent = (min(near), max(near)) if near else None
    identifiable = bool(consistent and value is not None
                        and consistent[1] - consistent[0] <= IDENTIFIABLE_SPAN * max(abs(value), 1e-9))
    explained = lap is not None and abs(lap - m) <= ACCEPT * m
    if explained and not identifiable and consistent:
        message += (f"; but every value in [{consistent[0]:.4g}, {consistent[1]:.4g}] gives a lap within "
                    f"{TOLERANCE * 100:g} %: the lap time hardly depends on it there, so it is not identifiable from "
                    "a lap time alone")
    return LapTimeAlignment(address, value, lap, m, explained, iterations, len(trace), reachable, consistent,
                            identifiable, message, tuple(trace))


def _lap_times(twin: DigitalTwin, address: str, values, seed: int, nthread: int) -> list[float | None]:
    results: list[LapResult] = run_laps(twin, [{address: float(v)} for v in values], seed=seed, nthread=nthread,
                                        keep_traces=False)
    return [r.lap_time_s if r.completed else None for r in results]


def align_lap_time(
    twin: DigitalTwin,
    measured_lap_time_s: float,
    address: str = "motion.mu",
    bounds: tuple[float, float] | None = None,
    seed: int = 0,
    max_iter: int = 20,
    nthread: int = 0,
) -> LapTimeAlignment:
    """Align one parameter to a measured lap time (see the module docstring)."""
    if not (isinstance(measured_lap_time_s, (int, float)) and math.isfinite(measured_lap_time_s) and measured_lap_time_s > 0):
        raise TunerError(f"measured lap time: must be a finite number of seconds > 0, got {measured_lap_time_s!r}")
    p = twin.space.parameter(address)
    if p.cost is ChangeCost.REBUILD or p.integer:
        raise TunerError(f"{address}: alignment searches parameters that can differ between the laps of one batch")
    if bounds is None:  # a range of its own, else a factor of RELATIVE_RANGE either side of the current value
        v = twin.space.get(address)
        bounds = DEFAULT_RANGES.get(address) or (
            (max(p.lower, v / RELATIVE_RANGE), min(p.upper, v * RELATIVE_RANGE)) if v > 0 else (p.lower, p.upper))
    lo, hi = bounds
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise TunerError(f"{address}: bounds [{lo:g}, {hi:g}] are inverted, empty or not finite")
    p.check(f"{address} lower bound", lo)
    p.check(f"{address} upper bound", hi)
    m = float(measured_lap_time_s)
    trace: list[AlignPoint] = []

    # 1. scan: geometric spacing for a positive parameter (friction acts by ratios), else linear
    scan = np.geomspace(lo, hi, SCAN_POINTS) if lo > 0 else np.linspace(lo, hi, SCAN_POINTS)
    times = _lap_times(twin, address, scan, seed, nthread)
    trace += [AlignPoint(0, float(v), t) for v, t in zip(scan, times)]
    done = [(float(v), t) for v, t in zip(scan, times) if t is not None]
    if not done:
        return _result(address, None, None, m, 0, trace, None,
                       f"no lap completes for {address} in [{lo:g}, {hi:g}] with these gains")
    reachable = (min(t for _, t in done), max(t for _, t in done))
    best = min(done, key=lambda vt: abs(vt[1] - m))
    if abs(best[1] - m) <= TOLERANCE * m:
        return _result(address, best[0], best[1], m, 0, trace, reachable,
                       f"{address} = {best[0]:.5g} gives {best[1]:.3f} s against {m:.3f} s measured")
    # 2. bracket: neighbouring completed scan values on either side of the measurement
    brackets = [(a, b) for a, b in zip(done, done[1:]) if (a[1] - m) * (b[1] - m) < 0]
    if not brackets:
        where = "faster" if m < reachable[0] else "slower" if m > reachable[1] else "between scan points only"
        return _result(
            address, None, None, m, 0, trace, reachable,
            f"no {address} in [{lo:g}, {hi:g}] explains {m:g} s: the simulated lap takes {reachable[0]:.3f}–"
            f"{reachable[1]:.3f} s there (the measurement is {where}); check the gains, the track or another parameter")
    (a, ta), (b, tb) = min(brackets, key=lambda br: abs(br[0][1] - br[1][1]))  # the steepest crossing
    # 3. safeguarded Gauss–Newton inside [a, b]
    x = a + (m - ta) * (b - a) / (tb - ta)  # start at the secant
    value, lap = best
    k = 0
    for k in range(1, max_iter + 1):
        h = REL_STEP * max(abs(x), 1e-3)
        xs = [x, min(x + h, b), max(x - h, a)]
        t = _lap_times(twin, address, xs, seed, nthread)
        trace += [AlignPoint(k, float(v), tt) for v, tt in zip(xs, t)]
        for v, tt in zip(xs, t):  # every completed lap narrows the bracket
            if tt is None:
                continue
            if abs(tt - m) < abs(lap - m):
                value, lap = v, tt
            if (tt - m) * (ta - m) > 0:
                a, ta = v, tt
            else:
                b, tb = v, tt
        if abs(lap - m) <= TOLERANCE * m or (b - a) <= 1e-6 * max(abs(b), 1.0):
            break
        slope = None
        if None not in t and xs[1] > xs[2]:
            slope = (t[1] - t[2]) / (xs[1] - xs[2])
        step_ok = False
        if t[0] is not None and slope and abs(slope) > 1e-9:
            nxt = x - (t[0] - m) / slope  # Gauss–Newton on (t − m)²
            step_ok = a < nxt < b
        x = nxt if step_ok else 0.5 * (a + b)  # flat or outside the bracket: bisect
    explained = abs(lap - m) <= ACCEPT * m
    msg = (f"{address} = {value:.5g} gives {lap:.3f} s against {m:.3f} s measured ({100 * (lap - m) / m:+.2f} %)"
           if explained else f"closest {address} = {value:.5g} gives {lap:.3f} s, {100 * (lap - m) / m:+.2f} % off")
    return _result(address, value, lap, m, k, trace, reachable, msg)
