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
SLOW_SPEED = 0.2  # [m/s] the distance left is charged as if driven at this speed


def lap_cost(r: LapResult) -> float:
    """F for one lap (see the module docstring); for a lap stopped undecided, a lower bound: its simulated time."""
    if r.completed:
        return float(r.lap_time_s)
    if r.failure == Outcome.STOPPED.value:
        return float(r.simulated_s)
    return float(r.simulated_s + PENALTY_S + max(0.0, r.track_length_m - r.distance_m) / SLOW_SPEED)


class _Cut:
    """Between chunks: stops the laps of every point whose cost is certainly above the bound, or above the cost of a
    point of the batch that has finished (each lap's cost at least its lower bound: :func:`lap_cost` of its result,
    or its simulated time while it runs)."""

    def __init__(self, risk: Risk, per_point: int, points: int, bound: float):
        self.risk, self.per_point, self.points, self.bound = risk, per_point, points, bound

    def __call__(self, progress: list[Progress]) -> list[int]:
        lower = np.array([lap_cost(p.result) if p.result else p.time_s for p in progress]).reshape(self.points, -1)
        ended = np.array([p.result is not None for p in progress]).reshape(self.points, -1)
        stopped = np.array([bool(p.result) and p.result.failure == Outcome.STOPPED.value for p in progress])
        exact = ended.all(axis=1) & ~stopped.reshape(self.points, -1).any(axis=1)
        costs = self.risk(lower)
        bound = min([self.bound] + list(costs[exact]))
        out = []
        for k in np.flatnonzero((costs > bound) & ~ended.all(axis=1)):
            out += [k * self.per_point + j for j in np.flatnonzero(~ended[k])]
        return out


@dataclasses.dataclass(frozen=True)
class Evaluation:
    """One point of the search: parameters, its cost, and its laps (scenario-major, then seed), without traces."""

    x: np.ndarray
    cost: float
    laps: tuple[LapResult, ...]
    bounded: bool = False  # some laps were stopped: cost is a lower bound (LapObjective.below)

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
        scenarios, seeds = self.envelope.scenarios, self.envelope.seeds
        per_point = len(scenarios) * len(seeds)
        variants = [{**self.space.assignments(x), **sc} for x in xs for sc in scenarios for _ in seeds]
        bounded = self.stop_early and math.isfinite(bound)
        results = run_laps(self.twin, variants, seed=[s for _ in xs for _ in scenarios for s in seeds],
                           limits=self.limits, nthread=self.nthread, keep_traces=False, stop_decided=self.stop_early,
                           deadline_s=[self.risk.lap_bound(bound, per_point)] * len(variants) if bounded else None,
                           cut=_Cut(self.risk, per_point, len(xs), bound) if bounded else None)
        self.laps += len(results)
        lap_costs = np.array([lap_cost(r) for r in results]).reshape(len(xs), per_point)
        costs = self.risk(lap_costs)
        for i, (zi, x, c) in enumerate(zip(z, xs, costs)):
            laps = tuple(results[i * per_point:(i + 1) * per_point])
            e = Evaluation(x, float(c), laps, any(r.failure == Outcome.STOPPED.value for r in laps))
            if e.bounded:
                continue  # a lower bound: neither the best nor a point to reuse
            self._seen[np.asarray(zi, dtype=float).tobytes()] = e
            if self.first is None:
                self.first = e
            if self.best is None or c < self.best.cost:
                self.best = e
            if self.on_lap is not None:
                self.on_lap(e)
        return costs

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
