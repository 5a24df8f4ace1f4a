"""The objective of the learning model: lap time, with a penalty for a lap that fails, over an envelope.

F(x) = lap time [s] for a completed lap. A failed lap (off track, line lost, timeout, …) costs

    F = t_fail + PENALTY_S + (L − d) / SLOW_SPEED

where t_fail is when it failed, L the track length and d the distance covered. So a failure always costs more
than finishing (by at least ``PENALTY_S``), and one that gets further costs less: near the failure boundary
the objective still points the way back to laps that finish.

A gain vector is judged over an :class:`tuner.search.envelope.Envelope` (scenarios × noise seeds; by default the twin
as it is, with one seed) and its lap costs are aggregated by a :class:`tuner.search.envelope.Risk`. Every evaluation of
m points is one batch of m × scenarios × seeds laps (``twin.core.closed_loop.run_laps``); the seeds are the same for
every point (common random numbers), so differences between points come from the parameters, not the noise.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable

import numpy as np

from twin.core.closed_loop import Progress, run_laps
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapLimits, LapResult
from twin.core.outcomes import Outcome
from tuner.search.envelope import Envelope, Risk, label
from tuner.search.space import SearchSpace
from twin.errors import TwinError

PENALTY_S = 5.0  # [s] added to any failed lap
SCREEN_MARGIN = 0.05  # a lap this much faster than those deciding the centre's cost is not run around it (around)
SLOW_SPEED = 0.2  # [m/s] the distance left is charged as if driven at this speed


def lap_cost(r: LapResult) -> float:
    """F for one lap (see the module docstring); for a lap stopped undecided, a lower bound: its simulated time."""
    if r.completed:
        return float(r.lap_time_s)
    if r.failure == Outcome.STOPPED.value:
        return float(r.simulated_s)
    return float(r.simulated_s + PENALTY_S + max(0.0, r.track_length_m - r.distance_m) / SLOW_SPEED)


class _Cut:
    """Between chunks of a run of some laps of some points: stops the laps of every point whose cost is certainly
    above the bound, or above the cost of a point that has finished. Each lap's cost is at least its lower bound
    (:func:`lap_cost` of its result, its simulated time while it runs, 0 before it runs); ``before`` holds the laps
    of earlier runs, ``slots`` the (point, lap) of each lap of this run."""

    def __init__(self, risk: Risk, before: list[list[LapResult | None]], slots: list[tuple[int, int]], bound: float):
        self.risk, self.before, self.slots, self.bound = risk, before, slots, bound

    def __call__(self, progress: list[Progress]) -> list[int]:
        lower, ended, exact = _lower_bounds(self.risk, self.before, self.slots, progress)
        bound = min([self.bound] + list(lower[exact]))
        out = {k for k in range(len(lower)) if lower[k] > bound}
        return [i for i, (k, j) in enumerate(self.slots) if k in out and not ended[k, j]]


def _lower_bounds(risk: Risk, before: list[list[LapResult | None]], slots=(), progress=()):
    """Per point: the risk of its laps' lower bounds, whether each lap has ended, and whether the point is exact
    (every lap ended, none stopped)."""
    n = len(before[0])
    lower, ended, stopped = np.zeros((len(before), n)), np.zeros((len(before), n), bool), np.zeros((len(before), n), bool)
    for k, row in enumerate(before):
        for j, r in enumerate(row):
            if r is not None:
                lower[k, j], ended[k, j], stopped[k, j] = lap_cost(r), True, r.failure == Outcome.STOPPED.value
    for (k, j), p in zip(slots, progress):
        r = p.result
        lower[k, j], ended[k, j] = (lap_cost(r), True) if r is not None else (p.time_s, False)
        stopped[k, j] = r is not None and r.failure == Outcome.STOPPED.value
    return risk(lower), ended, ended.all(axis=1) & ~stopped.any(axis=1)


@dataclasses.dataclass(frozen=True)
class Evaluation:
    """One point of the search: parameters, its cost, and its laps (scenario-major, then seed), without traces."""

    x: np.ndarray
    cost: float
    laps: tuple[LapResult, ...]

    @property
    def lap(self) -> LapResult:
        """The first scenario's lap with the first seed (the only lap of a plain tuning)."""
        return self.laps[0]


class LapObjective:
    """F over the search space, evaluated many points at a time.

    Args:
      twin: the robot on its track; its values are the base of every lap.
      space: the searched parameters.
      seed: sensor-noise seed of every lap when ``envelope`` is None (common random numbers).
      limits: lap failure thresholds.
      nthread: batch threads, 0 for all cores.
      envelope: scenarios × seeds each point is judged on (default: the twin as it is, with ``seed``).
      risk: how a point's lap costs add up (default: their mean).
      stop_early: laps stop the tick they are decided, and :meth:`below` stops those that could no longer matter;
        False runs every lap to the end of its chunk (the answers are the same).
    """

    def __init__(self, twin: DigitalTwin, space: SearchSpace, seed: int = 0, limits: LapLimits = LapLimits(),
                 nthread: int = 0, envelope: Envelope | None = None, risk: Risk = Risk("mean"), stop_early: bool = True):
        self.twin, self.space, self.limits, self.nthread, self.stop_early = twin, space, limits, nthread, stop_early
        self.envelope = envelope if envelope is not None else Envelope.of({}, [seed])
        self.risk = risk
        for address, _ in self.envelope.axes:
            if address in space.addresses:
                raise TwinError(f"{address}: is searched, so it cannot also be a scenario")
        self.laps = 0  # laps simulated so far
        self.first: Evaluation | None = None  # the first point: both procedures start at the starting point
        self.best: Evaluation | None = None
        self.on_lap: Callable[[Evaluation], None] | None = None
        self._seen: dict[bytes, Evaluation] = {}
        self._screened: dict[tuple, float] = {}  # stencil points judged on some laps (around): (point, laps) → cost

    def __call__(self, z: np.ndarray) -> np.ndarray:
        """F at points z (m, n) of the unit box: one batch of m × scenarios × seeds laps. Returns (m,) costs in [s].
        A point evaluated before is not simulated again: its laps would be bit-identical."""
        return self.below(z, math.inf)

    def below(self, z: np.ndarray, bound: float) -> np.ndarray:
        """F at points z (m, n), exact for every point that costs at most ``bound`` [s] and for the cheapest point;
        a point that cannot cost less than ``bound``, or than a point of the same batch that has finished, may come
        back as a lower bound above it, its laps stopped as soon as that is certain (a lap's cost is at least its
        simulated time, and the risk measure never falls when a lap's cost rises). So the cheapest point, and
        whether it beats ``bound``, are those of the exact costs: what a line search asks."""
        z = np.atleast_2d(z)
        known = [self.at(zi) for zi in z]
        if all(e is not None for e in known):
            return np.array([e.cost for e in known])
        if any(e is not None for e in known):
            fresh = [i for i, e in enumerate(known) if e is None]
            costs = np.array([np.nan if e is None else e.cost for e in known])
            if math.isfinite(bound):  # a known point cheaper than the bound bounds the others too
                bound = min([bound] + [e.cost for e in known if e is not None])
            costs[fresh] = self.below(z[fresh], bound)
            return costs
        xs = [self.space.from_unit(zi) for zi in z]
        per_point = len(self.envelope)
        results: list[list[LapResult | None]] = [[None] * per_point for _ in xs]
        everything = [(k, j) for k in range(len(xs)) for j in range(per_point)]
        if not (self.stop_early and math.isfinite(bound)):
            self._run(xs, everything, results, math.inf)
        else:
            self._race(xs, results, bound)
        costs, _, exact = _lower_bounds(self.risk, results)
        for zi, x, c, row, whole in zip(z, xs, costs, results, exact):
            if whole:  # else a lower bound: neither the best nor a point to reuse
                self._keep(zi, Evaluation(x, float(c), tuple(row)))
        return costs

    def _keep(self, z: np.ndarray, e: Evaluation) -> None:
        """An exact evaluation: reused when the point comes again, and a candidate for the first and the best."""
        self._seen[np.asarray(z, dtype=float).tobytes()] = e
        if self.first is None:
            self.first = e
        if self.best is None or e.cost < self.best.cost:
            self.best = e
        if self.on_lap is not None:
            self.on_lap(e)

    def around(self, centre: np.ndarray, points: np.ndarray) -> np.ndarray:
        """F at ``points`` near ``centre``: a gradient's stencil, each one fraction ``fd_step`` of a range away.

        Under the worst lap (or cvar), a lap that the centre completed more than :data:`SCREEN_MARGIN` faster than
        the laps deciding its cost is not run at the stencil points: a step that small moves a completed lap by far
        less (≤ 1.3 % between stencil points in the robust preset, ``benchmarks/bench_tuner.py``), so it cannot
        decide their cost either. A stencil point's cost is then the measure of the laps run, equal to the full
        one while the laps not run stay below them. A point that would be the best so far runs its other laps too,
        so the best point, the tuner's answer, is always judged on every lap. The mean, which every lap makes up,
        runs every lap."""
        points = np.atleast_2d(points)
        per_point = len(self.envelope)
        if not self.stop_early or self.risk.worst_k(per_point) is None or per_point == 1:
            return self(points)
        e = self.at(centre)
        if e is None:
            self(np.asarray(centre, dtype=float)[None])
            e = self.at(centre)
        keep = tuple(self.risk.deciding(np.array([lap_cost(r) for r in e.laps]), SCREEN_MARGIN))
        if len(keep) == per_point:
            return self(points)
        costs = np.full(len(points), np.nan)
        fresh = []
        for i, zi in enumerate(points):
            known = self.at(zi)
            screened = self._screened.get((np.asarray(zi, dtype=float).tobytes(), keep))
            if known is not None or screened is not None:
                costs[i] = known.cost if known is not None else screened
            else:
                fresh.append(i)
        if not fresh:
            return costs
        xs = [self.space.from_unit(points[i]) for i in fresh]
        results: list[list[LapResult | None]] = [[None] * per_point for _ in fresh]
        self._run(xs, [(k, j) for k in range(len(fresh)) for j in keep], results, math.inf)
        part = self.risk.of_worst(np.array([[lap_cost(row[j]) for j in keep] for row in results]), per_point)
        best = self.best.cost
        whole = [k for k in range(len(fresh)) if part[k] < best]  # would be the best: judged on every lap
        self._run(xs, [(k, j) for k in whole for j in range(per_point) if results[k][j] is None], results, math.inf)
        for k, i in enumerate(fresh):
            if k in whole:
                costs[i] = float(self.risk(np.array([lap_cost(r) for r in results[k]]))[0])
                self._keep(points[i], Evaluation(xs[k], costs[i], tuple(results[k])))
            else:
                costs[i] = float(part[k])
                self._screened[(np.asarray(points[i], dtype=float).tobytes(), keep)] = costs[i]
        return costs

    def _race(self, xs: list[np.ndarray], results: list[list[LapResult | None]], bound: float) -> None:
        """Only the cheapest point must be exact, and only if it costs at most ``bound``. Every point first runs the
        laps that decided the risk of the best point so far (for the worst lap: its slowest scenario and seed);
        then the points still in the race run their other laps one point at a time, the most promising first, each
        exact one lowering the bar for the rest. Without such laps (the mean, one lap a point) all run at once."""
        per_point = len(results[0])
        deciding = self.risk.deciding(np.array([lap_cost(r) for r in self.best.laps])) if self.best else None
        if deciding is None or len(deciding) >= per_point:
            return self._run(xs, [(k, j) for k in range(len(xs)) for j in range(per_point)], results, bound)
        self._run(xs, [(k, j) for k in range(len(xs)) for j in deciding], results, bound)
        while True:
            lower, ended, exact = _lower_bounds(self.risk, results)
            bar = min([bound] + list(lower[exact]))
            racing = [k for k in range(len(xs)) if not ended[k].all() and lower[k] <= bar]
            if not racing:
                return
            k = min(racing, key=lambda k: lower[k])
            self._run(xs, [(k, j) for j in range(per_point) if results[k][j] is None], results, bar)

    def _run(self, xs: list[np.ndarray], slots: list[tuple[int, int]], results: list[list[LapResult | None]],
             bound: float) -> None:
        """One batch: the laps ``slots`` ((point, lap) pairs, lap = scenario-major then seed) into ``results``,
        stopping those that could no longer matter against ``bound``."""
        scenarios, seeds = self.envelope.scenarios, self.envelope.seeds
        per_point = len(scenarios) * len(seeds)
        variants = [{**self.space.assignments(xs[k]), **scenarios[j // len(seeds)]} for k, j in slots]
        bounded = self.stop_early and math.isfinite(bound)
        laps = run_laps(self.twin, variants, seed=[seeds[j % len(seeds)] for _, j in slots], limits=self.limits,
                        nthread=self.nthread, keep_traces=False, stop_decided=self.stop_early,
                        deadline_s=[self.risk.lap_bound(bound, per_point)] * len(slots) if bounded else None,
                        cut=_Cut(self.risk, results, slots, bound) if bounded else None)
        self.laps += len(laps)
        for (k, j), r in zip(slots, laps):
            results[k][j] = r

    def at(self, z: np.ndarray) -> Evaluation | None:
        """The evaluation of a point already evaluated (e.g. an iteration's accepted point)."""
        return self._seen.get(np.asarray(z, dtype=float).tobytes())

    def by_scenario(self, e: Evaluation) -> list[dict]:
        """Per scenario: its label, lap times of the completed laps, and how many of its seeds completed."""
        k = len(self.envelope.seeds)
        out = []
        for j, sc in enumerate(self.envelope.scenarios):
            laps = e.laps[j * k:(j + 1) * k]
            done = [r.lap_time_s for r in laps if r.completed]
            out.append({"scenario": label(sc), "values": sc, "lap_times_s": done, "completed": len(done),
                        "laps": len(laps), "failures": sorted({r.failure for r in laps if not r.completed})})
        return out
