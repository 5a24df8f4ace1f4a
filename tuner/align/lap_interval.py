"""A lap-time alignment's 95 % intervals (step 5 of :mod:`tuner.align.lap_time`): for each value that explains the
measured lap, the values whose single lap could be the measured one, from laps raced at it and either side of it on
the twin's noise seeds (:func:`tuner.align.calibration.inverse_interval`)."""

from __future__ import annotations

import dataclasses

from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapLimits
from twin.model.space import ChangeCost
from tuner.align.calibration import inverse_interval, seeds_for

INTERVAL_SEEDS = seeds_for(0.95)  # laps at a solution whose range holds one more at 95 %: 39
SLOPE_SEEDS = 8  # laps either side of it, on the same seeds, for the slope
START_SPAN = 0.01  # either side of the solution, as a fraction of it, at first
INTERVAL_ROUNDS = 3  # span widenings until the interval lies inside the values it was fitted on
MAX_SPAN = 0.10  # the widest span: beyond it the value is not pinned anyway (lap_time.IDENTIFIABLE_SPAN)


def laps_on_seeds(twin: DigitalTwin, address: str, values, seed: int, nthread: int, limits: LapLimits,
                  noise_seeds: int) -> list:
    """Each value's laps on ``noise_seeds`` seeds from ``seed``, value by value: one batch, or, for a parameter that
    rebuilds the robot, one build per value."""
    seeds = [seed + k for k in range(noise_seeds)]
    if twin.space.parameter(address).cost is ChangeCost.REBUILD:
        return [r for v in values for r in run_laps(twin.clone({address: float(v)}), [{}] * noise_seeds, seed=seeds,
                                                    nthread=nthread, limits=limits, keep_traces=False)]
    return run_laps(twin, [{address: float(v)} for v in values for _ in seeds], seed=seeds * len(values),
                    nthread=nthread, limits=limits, keep_traces=False)


def solution_interval(twin: DigitalTwin, address: str, value: float, m: float, bounds: tuple[float, float],
                      seed: int, nthread: int, limits: LapLimits) -> tuple[tuple[float, float] | None, int]:
    """(the 95 % interval of the values whose single lap would be the measured one, or None if the lap time cannot
    pin it; laps run): ``INTERVAL_SEEDS`` laps at the value (their range holds one more lap at 95 %, whatever the
    noise's shape), ``SLOPE_SEEDS`` on the same seeds at ``span`` either side for the slope, inverted by
    :func:`tuner.align.calibration.inverse_interval`. The span starts at ``START_SPAN`` and widens
    (``INTERVAL_ROUNDS`` at most) until the interval lies inside the values the slope was taken over; a failed lap
    there, or an interval still wider, gives None (not pinned by a straight line)."""
    span, laps, centre = START_SPAN, 0, None
    for _ in range(INTERVAL_ROUNDS):
        lo_x, hi_x = max(value * (1 - span), bounds[0]), min(value * (1 + span), bounds[1])
        if not lo_x < value < hi_x:
            return None, laps
        if centre is None:  # the same laps each round (a lap is deterministic): raced once
            centre = laps_on_seeds(twin, address, [value], seed, nthread, limits, INTERVAL_SEEDS)
            laps += len(centre)
        sides = laps_on_seeds(twin, address, [lo_x, hi_x], seed, nthread, limits, SLOPE_SEEDS)
        laps += len(sides)
        if not all(r.completed for r in centre + sides):
            return None, laps  # a limit lies within the span: no straight line through it
        fit = inverse_interval(value, [r.lap_time_s for r in centre], lo_x,
                               [r.lap_time_s for r in sides[:SLOPE_SEEDS]], hi_x,
                               [r.lap_time_s for r in sides[SLOPE_SEEDS:]], m)
        if fit.interval is None or not fit.straight:
            return None, laps
        if fit.inside:
            return fit.interval, laps
        lo, hi = fit.interval
        span = min(max(2 * span, 1.2 * max(abs(lo - value), abs(hi - value)) / abs(value)), MAX_SPAN)
    return None, laps


def with_intervals(result, twin: DigitalTwin, m: float, seed: int, nthread: int, limits: LapLimits):
    """``result`` (a :class:`tuner.align.lap_time.LapTimeAlignment`) with each solution's 95 % interval
    (:func:`solution_interval`), the chosen one's in the result and its message."""
    solutions, laps = [], 0
    for x in result.solutions:
        ci, n = solution_interval(twin, result.parameter, x.value, m, result.bounds, seed, nthread, limits)
        solutions.append(dataclasses.replace(x, ci95=ci))
        laps += n
    best = next((x for x in solutions if x.value == result.value), None)
    ci = best.ci95 if best else None
    message = result.message + (
        f"; 95 % interval [{ci[0]:.5g}, {ci[1]:.5g}] (the values whose single lap could be the measured one: the "
        f"range of {INTERVAL_SEEDS} laps on the twin's noise seeds, along the slope)" if ci else
        "; no 95 % interval: near it the lap time is not a straight, clearly sloped function of the value (a limit, "
        "or too flat for one lap to pin it)" if best else "")
    return dataclasses.replace(result, solutions=tuple(solutions), ci95=ci, laps=result.laps + laps, message=message)
