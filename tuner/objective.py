"""The objective of the learning model: lap time, with a penalty for a lap that fails.

F(x) = lap time [s] for a completed lap. A failed lap (off track, line lost, timeout, …) costs

    F = t_fail + PENALTY_S + (L − d) / SLOW_SPEED

where t_fail is when it failed, L the track length and d the distance covered. So a failure always costs more
than finishing (by at least ``PENALTY_S``), and one that gets further costs less: near the failure boundary
the objective still points the way back to laps that finish.

Every evaluation is a batch of laps (``twin.closed_loop.run_laps``) with the same noise seed (common random
numbers): differences between laps come from the parameters, not the noise.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from twin.closed_loop import run_laps
from twin.digital_twin import DigitalTwin
from twin.lap import LapLimits, LapResult
from tuner.space import SearchSpace

PENALTY_S = 5.0  # [s] added to any failed lap
SLOW_SPEED = 0.2  # [m/s] the distance left is charged as if driven at this speed


def lap_cost(r: LapResult) -> float:
    """F for one lap (see the module docstring)."""
    if r.completed:
        return float(r.lap_time_s)
    return float(r.simulated_s + PENALTY_S + max(0.0, r.track_length_m - r.distance_m) / SLOW_SPEED)


@dataclasses.dataclass(frozen=True)
class Evaluation:
    """One lap of the search: parameters, cost, and the lap itself (without its trace)."""

    x: np.ndarray
    cost: float
    lap: LapResult


class LapObjective:
    """F over the search space, evaluated many points at a time.

    Args:
      twin: the robot on its track; its values are the base of every lap.
      space: the searched parameters.
      seed: sensor-noise seed shared by every lap (common random numbers).
      limits: lap failure thresholds.
      nthread: batch threads, 0 for all cores.
    """

    def __init__(self, twin: DigitalTwin, space: SearchSpace, seed: int = 0, limits: LapLimits = LapLimits(), nthread: int = 0):
        self.twin, self.space, self.seed, self.limits, self.nthread = twin, space, seed, limits, nthread
        self.laps = 0  # laps simulated so far
        self.first: Evaluation | None = None  # the first lap: both procedures start at the starting point
        self.best: Evaluation | None = None
        self.on_lap: Callable[[Evaluation], None] | None = None

    def __call__(self, z: np.ndarray) -> np.ndarray:
        """F at points z (m, n) of the unit box: one batch of m laps. Returns (m,) costs in [s]."""
        z = np.atleast_2d(z)
        xs = [self.space.from_unit(zi) for zi in z]
        results = run_laps(self.twin, [self.space.assignments(x) for x in xs], seed=self.seed, limits=self.limits,
                           nthread=self.nthread, keep_traces=False)
        self.laps += len(results)
        costs = np.array([lap_cost(r) for r in results])
        for x, c, r in zip(xs, costs, results):
            e = Evaluation(x, float(c), r)
            if self.first is None:
                self.first = e
            if self.best is None or c < self.best.cost:
                self.best = e
            if self.on_lap is not None:
                self.on_lap(e)
        return costs
