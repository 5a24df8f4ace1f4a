"""Re-tuning the gains for the aligned twin, between laps (the learning model during operation, paper §5).

The gains must keep finishing as the robot goes on changing, so they are judged over an envelope: the aligned
value of the re-aligned parameter and a value further along its change (``low``: the aligned value less a margin,
or where its trend will be a few laps on), each with a few noise seeds, by the worst lap
(:data:`tuner.search.envelope.ROBUST_RISK`, as the ``--robust`` preset). Descent starts from the gains in force
(warm start: a few iterations suffice when the robot changed a little), inside the tuner's bounds for this robot
(:func:`tuner.search.space.robot_bounds`); when the gains in force fail there, from the fastest of them slowed
down (v_max scaled by :data:`SLOWER`, one batch) that finishes every lap, and failing that from the best of a
small grid (:func:`tuner.search.start.rescue_start`). A lap slower than ``timeout_s`` (twice the robot's lap,
say) counts as failed: it would be no answer, and a lap left to run to the twin's 60 s limit costs eight laps.

A re-tune has a ``deadline`` (wall clock: the robot does not wait): the descent stops when what is left of it
would not cover the last race (descent's best point alone, on more seeds; its slower variants only when it fails
there and time is left), which is then run on the best point found so far; when even the first races
overrun it (or ``stop()``: the run is ending), no gains are proposed, and the note says which (``in_time``).

Everything is rounded to what the wire carries (:func:`twin.telemetry.wire.on_the_wire`) before it is raced: the
twin predicts exactly the gains it will send.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Callable

import numpy as np

from tuner.search.envelope import ROBUST_RISK, Envelope, Risk
from tuner.search.gradient import DescentOptions, descend
from tuner.search.objective import LapObjective
from tuner.search.space import SearchSpace, robot_bounds
from tuner.search.start import rescue_start
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapLimits
from twin.telemetry.wire import GAIN_ADDRESSES, on_the_wire

# a few iterations from a warm start: a re-tuning must end within a few laps at real time
RETUNE_DESCENT = DescentOptions(step=0.05, max_iter=6, ftol=0.02)
SLOWER = (0.95, 0.9, 0.85, 0.8, 0.7, 0.6)  # v_max of the gains in force scaled by these: the warm starts tried
FINAL_SLOWER = (0.97, 0.93, 0.88)  # descent's best point slowed by these, raced with it before anything is sent …
FINAL_SEEDS = 6  # … on this many seeds per envelope value: a lap at the edge fails on some seeds only
# the envelope's values: a set of gains may fail inside the range and finish at both ends (a band of grip where
# the robot slides out of a curve that a lower grip takes slower), so the search races its middle too, and what
# is kept or sent is raced at more values still
SEARCH_VALUES, FINAL_VALUES = 3, 6


@dataclasses.dataclass(frozen=True)
class Retune:
    """A re-tuning's outcome: the gains to send (or the gains in force, when they already finish everywhere)."""

    gains: dict[str, float]
    changed: bool  # the gains differ from those in force
    completes: bool  # every lap of the envelope finishes with them
    envelope: dict[str, tuple[float, ...]]
    worst_lap_time_s: float | None  # their worst envelope lap (None if one fails)
    laps: int
    wall_s: float
    note: str
    in_time: bool = True  # False: the deadline (or a stop) cut it short: the best gains by then, or none (changed False)


    def summary(self) -> dict:
        return dataclasses.asdict(self)


def clip_to_bounds(gains: dict[str, float], bounds: dict[str, tuple[float, float]]) -> dict[str, float]:
    return {a: float(np.clip(v, *bounds[a])) if a in bounds else v for a, v in gains.items()}


def bounds_for(twin: DigitalTwin) -> dict[str, tuple[float, float]]:
    """The tuner's bounds for this robot: what acting may send."""
    return {a: b for a, b in robot_bounds(twin).items() if a in GAIN_ADDRESSES}


def _slowed_start(objective: LapObjective, z0: np.ndarray) -> tuple[np.ndarray, str | None]:
    """The gains in force slowed down: the fastest of them that finishes every envelope lap (one batch)."""
    space = objective.space
    i = space.addresses.index("control.v_max")
    x0 = space.from_unit(z0)
    points = []
    for f in SLOWER:
        x = x0.copy()
        x[i] = max(space.lower[i], x0[i] * f)
        points.append(space.to_unit(x))
    objective(np.array(points))
    for f, z in zip(SLOWER, points):
        e = objective.at(z)
        if all(r.completed for r in e.laps):
            return z, f"descent starts from the gains in force with v_max × {f:g}"
    return rescue_start(objective, z0)


class _OutOfTime(Exception):
    """The descent must stop here to leave time for the last race (its best point so far goes with it)."""

    def __init__(self, z: np.ndarray):
        self.z = z


class _Clock:
    """The re-tune's time: what is left before ``deadline`` (``time.monotonic``), and what a lap costs (the
    cheapest per lap of the batches so far: a larger batch shares its overhead among more laps, as the last race's
    will)."""

    def __init__(self, deadline: float | None, stop: Callable[[], bool]):
        self.deadline, self.stop, self.t0 = deadline, stop, time.monotonic()
        self.per_lap_s = 0.0
        self.batch: tuple[float, int] = (self.t0, 0)

    def start(self, laps_so_far: int) -> None:
        """A batch (or a run of batches) begins, after ``laps_so_far`` laps."""
        self.batch = (time.monotonic(), laps_so_far)

    def ran(self, laps_so_far: int) -> None:
        t, n = self.batch
        if laps_so_far > n:
            cost = (time.monotonic() - t) / (laps_so_far - n)
            self.per_lap_s = cost if not self.per_lap_s else min(self.per_lap_s, cost)

    def over(self, laps_ahead: int = 0) -> bool:
        """The run stops, or ``laps_ahead`` more laps would end after the deadline."""
        if self.stop():
            return True
        return self.deadline is not None and time.monotonic() + laps_ahead * self.per_lap_s > self.deadline


def _values(low: float, high: float, n: int) -> list[float]:
    return sorted({float(v) for v in np.linspace(float(low), float(high), n)})


def retune_gains(twin: DigitalTwin, address: str, low: float, high: float, seeds: tuple[int, ...], timeout_s: float = 60.0,
           descent: DescentOptions = RETUNE_DESCENT, deadline: float | None = None,
           stop: Callable[[], bool] = lambda: False, progress: Callable[[int, int], None] | None = None) -> Retune:
    """Gains for the twin (its current values are the gains in force and the aligned parameter) that finish
    every lap with ``address`` at ``low`` and ``high`` and each of ``seeds``; the gains in force when they
    already do. ``deadline`` (``time.monotonic``): the best found by then, or none; ``stop()``: none.
    ``progress(done, planned)``: steps of the re-tune (the race of the gains in force, each descent iteration, the
    final race), ending with done = planned at its real end."""
    planned, done = descent.max_iter + 2, 0

    def step() -> None:
        nonlocal done
        done += 1
        if progress:
            progress(done, planned)

    try:
        return _retune(twin, address, low, high, seeds, timeout_s, descent, deadline, stop, step)
    finally:
        if progress:
            progress(done, done)  # its real end: fewer steps when the gains in force were kept or descent converged


def _retune(twin: DigitalTwin, address: str, low: float, high: float, seeds: tuple[int, ...], timeout_s: float,
            descent: DescentOptions, deadline: float | None, stop: Callable[[], bool], step: Callable[[], None]) -> Retune:
    t0 = time.perf_counter()
    clock = _Clock(deadline, stop)
    bounds = bounds_for(twin)
    current = {a: twin.space.get(a) for a in GAIN_ADDRESSES}
    start = on_the_wire(clip_to_bounds(current, bounds))
    envelope = Envelope.of({address: _values(low, high, SEARCH_VALUES)}, seeds)
    space = SearchSpace(twin.space, GAIN_ADDRESSES, bounds)
    base = twin.clone(start)
    limits = LapLimits(timeout_s=timeout_s)
    objective = LapObjective(base, space, limits=limits, envelope=envelope, risk=Risk.parse(ROBUST_RISK))
    z0 = space.to_unit(np.array([start[a] for a in GAIN_ADDRESSES]))
    clock.start(0)
    objective(z0[None])
    clock.ran(objective.laps)
    step()
    first = objective.at(z0)
    axes = {a: vs for a, vs in envelope.axes}
    final = Envelope.of({address: _values(low, high, FINAL_VALUES)},
                        range(seeds[0], seeds[0] + max(FINAL_SEEDS, len(seeds))))
    if all(r.completed for r in first.laps) and start == on_the_wire(current):
        clock.start(0)
        kept = _race_all(twin, [start], final, limits)  # kept only if they finish on as many seeds as a change
        clock.ran(len(kept))
        if all(r.completed for r in kept):
            return Retune(current, False, True, axes, max(r.lap_time_s for r in kept), objective.laps + len(kept),
                          time.perf_counter() - t0, "the gains in force finish every lap of the envelope")
    last_race = len(final.scenarios) * len(final.seeds)  # the final race of descent's best point (the rest if it fails)

    def none_in_time(why: str) -> Retune:
        return Retune(current, False, False, axes, None, objective.laps, time.perf_counter() - t0,
                      f"{why}: no gains proposed, the robot keeps its gains", in_time=False)

    if clock.over(last_race):
        return none_in_time(_late(clock, "before the descent"))
    clock.start(objective.laps)
    z, rescue = (z0, None) if all(r.completed for r in first.laps) else _slowed_start(objective, z0)
    clock.ran(objective.laps)
    if clock.over(last_race):
        return none_in_time(_late(clock, "before the descent"))
    clock.start(objective.laps)

    def in_time(it) -> None:
        step()
        clock.ran(objective.laps)
        if clock.over(last_race):
            raise _OutOfTime(it.z)

    try:
        result = descend(objective, z, descent, on_iteration=in_time)
        best, iterations, cut = result.z, f"{len(result.iterations)} iterations", ""
    except _OutOfTime as e:
        best, iterations, cut = e.z, "descent stopped", f"; the best found by the deadline ({_allowed(clock)})"
    if clock.stop():
        return none_in_time("the run is stopping")
    clock.start(0)  # the final race's laps count from here
    gains, worst, raced, late = _final(twin, space, [best, z], final, limits, clock)
    step()
    if late:
        cut = cut or (f"; descent's best failed the final race, and the slower candidates would pass the deadline "
                      f"({_allowed(clock)})")
    note = (f"{iterations} from the gains in force" + (f" ({rescue})" if rescue else "") + cut
            + ("" if worst is not None else "; no gains found that finish every lap of the envelope"))
    return Retune(gains, gains != on_the_wire(current), worst is not None, axes, worst, objective.laps + raced,
                  time.perf_counter() - t0, note, in_time=not cut)


def _allowed(clock: _Clock) -> str:
    return f"{max(0.0, clock.deadline - clock.t0):.3g} s allowed"


def _late(clock: _Clock, where: str) -> str:
    if clock.stop():
        return "the run is stopping"
    return f"the deadline ({_allowed(clock)}) would pass {where}"


def _final(twin: DigitalTwin, space: SearchSpace, points: list[np.ndarray], envelope: Envelope, limits: LapLimits,
           clock: _Clock | None = None):
    """The gains to send: descent's best point as the wire will carry it, or (when rounding, or a seed the search
    did not race, tips a lap that ran at the very edge into failing) that point a little slower, or the start; the
    fastest of them that finishes every lap (more seeds than the search: the best point alone first, then the rest
    in one batch if it fails, and if the ``clock`` leaves time for them). (gains, their worst lap or None if none
    finishes everywhere, laps run, whether the deadline left the slower ones unraced)."""
    i = space.addresses.index("control.v_max")
    candidates = []
    for z in (points[0], *[_slower(space, points[0], i, f) for f in FINAL_SLOWER], points[1]):
        gains = on_the_wire(space.assignments(space.from_unit(z)))
        if gains not in candidates:
            candidates.append(gains)
    # descent's best first (it is the fastest, and usually finishes: one small batch), the rest only if it fails
    first = _race_all(twin, candidates[:1], envelope, limits)
    if clock is not None:
        clock.ran(len(first))
    if all(r.completed for r in first):
        return candidates[0], max(r.lap_time_s for r in first), len(first), False
    rest = candidates[1:]
    if clock is not None and clock.over(len(rest) * len(first)):
        return candidates[0], None, len(first), True
    laps = _race_all(twin, rest, envelope, limits) if rest else []
    k = len(laps) // len(rest) if rest else 0
    best, worst = candidates[0], None
    for j, gains in enumerate(rest):
        mine = laps[j * k:(j + 1) * k]
        if all(r.completed for r in mine):
            w = max(r.lap_time_s for r in mine)
            if worst is None or w < worst:
                best, worst = gains, w
    return best, worst, len(first) + len(laps), False


def _slower(space: SearchSpace, z: np.ndarray, i: int, factor: float) -> np.ndarray:
    x = space.from_unit(z)
    x[i] = max(space.lower[i], x[i] * factor)
    return space.to_unit(x)


def _race_all(twin: DigitalTwin, candidates: list[dict], envelope: Envelope, limits: LapLimits):
    """Gains exactly as they will be sent, each over the whole envelope (the twin races what it sends): one batch,
    candidate-major."""
    scenarios = envelope.scenarios
    return run_laps(twin, [{**g, **sc} for g in candidates for sc in scenarios for _ in envelope.seeds],
                    seed=[s for _ in candidates for _ in scenarios for s in envelope.seeds], limits=limits,
                    keep_traces=False)


def predict(twin: DigitalTwin, gains: dict[str, float], seed: int):
    """The lap the twin expects from the robot with these gains (its own noise seed): a :class:`LapResult`."""
    return run_laps(twin, [dict(gains)], seed=seed, keep_traces=False)[0]
