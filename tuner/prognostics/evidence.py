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


def mahalanobis(r: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rᵀ·cov⁻¹·r, log det cov) for each of n residuals ``r`` (n, d) and covariances ``cov`` (n, d, d). Up to three
    features (lap time, the line's offset and side) in closed form (cofactors): the filter asks this of every
    particle at every lap, and numpy's batched inverse and determinant of 2×2 matrices took most of its time; more
    features by numpy."""
    d = r.shape[1]
    if d == 1:
        c = cov[:, 0, 0]
        return r[:, 0] ** 2 / c, np.log(c)
    if d == 2:
        a, b, c = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
        det = a * c - b * b
        x, y = r[:, 0], r[:, 1]
        return (x * x * c - 2.0 * x * y * b + y * y * a) / det, np.log(det)
    if d == 3:
        a, b, c = cov[:, 0, 0], cov[:, 0, 1], cov[:, 0, 2]
        e, f, g = cov[:, 1, 1], cov[:, 1, 2], cov[:, 2, 2]
        ca, cb, cc = e * g - f * f, c * f - b * g, b * f - c * e  # cofactors: the adjugate's first row …
        ce, cf, cg = a * g - c * c, b * c - a * f, a * e - b * b  # … and the rest of its upper triangle
        det = a * ca + b * cb + c * cc
        x, y, z = r[:, 0], r[:, 1], r[:, 2]
        q = x * x * ca + y * y * ce + z * z * cg + 2.0 * (x * y * cb + x * z * cc + y * z * cf)
        return q / det, np.log(det)
    return np.einsum("ni,nij,nj->n", r, np.linalg.inv(cov), r), np.log(np.linalg.det(cov))


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


@dataclasses.dataclass(frozen=True)
class LapObservation:
    """What one finished lap of the robot, run with the gains in force, shows: its ``features`` (in the order of the
    :class:`ObservationModel`'s ``names``: the lap time [s] and, where the link carries the telemetry, the mean
    |offset| of the line from the sensor array's centre and its mean signed offset [m])."""
    lap: int
    features: tuple[float, ...]


SLOW = 1.25  # a finished lap this much slower than the lap before it on the wear's way (the twin's mean at the
# value raced next to it, or for a robot's lap the slowest the twin reads) lost the line and found it again


@dataclasses.dataclass(frozen=True)
class ObservationModel:
    """What the twin says a finished lap shows at a value of the parameter: the mean of each feature over noise
    seeds at the raced ``values`` (ascending; piecewise linear between them, straight on beyond the ends), and the
    features' covariance over noise seeds at each (interpolated the same way: the scatter grows towards the edge;
    lap time and line offset move together, so one lap is not counted twice). Only regular laps: a lap ``SLOW``
    times slower than the slowest mean lost the line and found it again, which the model does not describe
    (:meth:`reads`)."""
    names: tuple[str, ...]
    values: np.ndarray  # (k,) ascending
    means: np.ndarray  # (k, d)
    covariances: np.ndarray  # (k, d, d)

    def __post_init__(self):
        k, d = len(self.values), len(self.names)
        if k < 2 or self.means.shape != (k, d) or self.covariances.shape != (k, d, d):
            raise ValueError("an observation model needs at least two raced values")

    def _interp(self, v: np.ndarray, y: np.ndarray, extrapolate: bool) -> np.ndarray:
        x = self.values
        m = np.interp(v, x, y)
        if extrapolate:
            m = np.where(v < x[0], y[0] + (v - x[0]) * (y[1] - y[0]) / (x[1] - x[0]), m)
            m = np.where(v > x[-1], y[-1] + (v - x[-1]) * (y[-1] - y[-2]) / (x[-1] - x[-2]), m)
        return m

    def mean(self, v: np.ndarray) -> np.ndarray:
        """(n, d): the features the twin expects at the values ``v`` (n,)."""
        v = np.asarray(v, float)
        return np.stack([self._interp(v, self.means[:, j], True) for j in range(len(self.names))], axis=1)

    def covariance(self, v: np.ndarray) -> np.ndarray:
        """(n, d, d): one lap's scatter at the values ``v`` (held at the ends beyond them)."""
        v = np.asarray(v, float)
        d = len(self.names)
        out = np.empty((len(v), d, d))
        for i in range(d):
            for j in range(d):
                out[:, i, j] = self._interp(v, self.covariances[:, i, j], False)
        return out

    def reads(self, features: tuple[float, ...]) -> bool:
        """Is this a lap the model describes (not one that lost the line and found it again)? Against the slowest
        mean it gives, at its most worn value: against the fastest, a part that slows every lap (a battery running
        down: 6.9 s a lap at 6.24 V, 8.5 s at 4.96 V, regular to its edge at 4.0 V) went unread for the last 40 %
        of its way to the edge (issue 35)."""
        return features[0] <= SLOW * float(self.means[:, 0].max())

    def log_likelihood(self, features: tuple[float, ...], v: np.ndarray, scale: np.ndarray) -> np.ndarray:
        """log N(features; mean(v), scale²·covariance(v)) per particle (constants dropped)."""
        q, logdet = self.distance(features, v)
        return -0.5 * q / scale ** 2 - len(self.names) * np.log(scale) - 0.5 * logdet

    def distance(self, features: tuple[float, ...], v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(the squared Mahalanobis distance of a lap's features from what the twin gives at each value ``v``, the
        log determinant of the covariance there): the log density at any noise scale s is
        −½·q/s² − d·log s − ½·logdet."""
        return mahalanobis(np.asarray(features)[None, :] - self.mean(v), self.covariance(v))

    def pins(self, v: float) -> float:
        """How far one lap pins the parameter near ``v`` (one standard error, the parameter's unit): from the
        features' slopes there and their covariance (Fisher information)."""
        dv = 1e-3 * max(abs(self.values[-1] - self.values[0]), 1e-9)
        j = (self.mean(np.array([v + dv])) - self.mean(np.array([v - dv])))[0] / (2 * dv)
        info = float(j @ np.linalg.inv(self.covariance(np.array([v]))[0]) @ j)
        return math.inf if info <= 0 else 1.0 / math.sqrt(info)

    def nearest(self, features: tuple[float, ...], span: tuple[float, float],
                points: int = 2001) -> tuple[float, float]:
        """(the value in ``span`` whose features the twin gives nearest a lap's, the squared Mahalanobis distance
        there): about χ² with d − 1 degrees of freedom when the parameter alone explains the lap (0 for one
        feature, which some value always fits)."""
        grid = np.linspace(span[0], span[1], points)
        d2, _ = self.distance(features, grid)
        i = int(np.argmin(d2))
        return float(grid[i]), float(d2[i])

    def misfit(self, features: tuple[float, ...], span: tuple[float, float]) -> float:
        """How far a lap's features lie from anything the parameter alone gives in ``span`` (:meth:`nearest`)."""
        return self.nearest(features, span)[1]

    def subset(self, names: tuple[str, ...]) -> "ObservationModel":
        """The model of the features ``names`` alone (some of its own, in any order)."""
        k = [self.names.index(n) for n in names]
        return ObservationModel(tuple(names), self.values, self.means[:, k], self.covariances[:, k][:, :, k])
