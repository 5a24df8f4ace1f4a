"""What a robot's life says about the parameter that wears (its degradation state), as the estimator reads it:

* a :class:`Measurement`: an alignment of the twin to the robot's laps ``first_lap`` to ``lap`` (their mean lap
  time, or a recorded run), the value that explains them and its standard error;
* an :class:`Outcome`: a lap run with the gains in force, finished or not. Failures are evidence too: a failed lap
  says the parameter is beyond where the twin says those gains fail, a finished lap that it is not (far) beyond;
* a :class:`FailureModel`: where the gains in force fail on the twin (raced along the parameter), as a probability
  of failing a lap at a value.

Only measurements and laps: no estimate is ever evidence.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

SQRT2 = math.sqrt(2.0)


@dataclasses.dataclass(frozen=True)
class Measurement:
    """The parameter's value over the robot's laps ``first_lap``..``lap``, with its standard error ``sigma`` (the
    parameter's unit)."""
    first_lap: int
    lap: int
    value: float
    sigma: float

    def __post_init__(self):
        if not (self.first_lap <= self.lap and math.isfinite(self.value) and self.sigma > 0):
            raise ValueError(f"bad measurement {self}")


@dataclasses.dataclass(frozen=True)
class Outcome:
    """Lap ``lap`` of the robot, run with the gains in force: ``failed`` or finished."""
    lap: int
    failed: bool


@dataclasses.dataclass(frozen=True)
class FailureModel:
    """The gains in force fail a lap with probability Φ(direction·(v − threshold)/width) at parameter value v:
    ``threshold`` where the twin first fails them, ``direction`` −1 when they fail below it (grip, battery),
    +1 above; ``width`` [parameter unit] how gradual the edge is (the racing's resolution, the robot's own
    lap-to-lap scatter)."""
    threshold: float
    width: float
    direction: float

    def p_fail(self, v: np.ndarray, shift: np.ndarray | float = 0.0) -> np.ndarray:
        """At value ``v``, for a robot whose edge lies ``shift`` beyond the twin's (the filter learns it from the
        robot's own laps, finished and failed)."""
        from scipy.special import ndtr

        return ndtr(self.direction * (np.asarray(v) - self.threshold - shift) / self.width)

    def beyond(self, v: np.ndarray) -> np.ndarray:
        """Is ``v`` past the threshold (on the failing side)?"""
        return self.direction * (np.asarray(v) - self.threshold) > 0


def measurement_sigma(value: float, interval: tuple[float, float] | None, floor_rel: float = 2e-3) -> float:
    """The standard error of an alignment: its consistent interval is the range of values whose twin laps match
    the measured lap time, every value in it equally good: a uniform spread, σ = width/√12; at least ``floor_rel``
    of the value (the twin's own resolution). The filter learns how far to trust these (a noise scale per
    particle)."""
    width = abs(interval[1] - interval[0]) if interval else 0.0
    return max(width / math.sqrt(12.0), floor_rel * abs(value), 1e-9)
