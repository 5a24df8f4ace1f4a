"""What the learning model searches: model-space addresses with bounds, normalised to the unit box.

x = (v_max, K_B, K_P, K_I, K_D) by default (paper Eq. 13). The search runs in z ∈ [0, 1]ⁿ, z = (x − lo)/(hi − lo),
so one step size suits parameters of different units and scales. Any parameter that can differ between the
laps of one batch (controller or model-field cost) can be searched, e.g. ``motion.mu`` for alignment.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Mapping, Sequence

import numpy as np

from twin.errors import TwinError
from twin.model.space import ChangeCost, ModelSpace

# Eq. 13 and default search bounds: wide enough for the default robot to go from cautious to reckless
DEFAULT_BOUNDS: dict[str, tuple[float, float]] = {
    "control.v_max": (0.3, 1.5),  # [m/s]; the 3pi+ tops out near 1.2–1.5 m/s at 6 V
    "control.kb": (0.0, 3.0),  # [m/s/rad]
    "control.kp": (1.0, 60.0),  # [1/s]
    "control.ki": (0.0, 20.0),  # [1/s²]
    "control.kd": (0.0, 2.0),  # [-]
}


# the robot the default bounds were set for: the 3pi-class default robot's top speed (30:1 MP motors at 6 V on
# 16 mm wheels: 75.4 rad/s × 16 mm) and sensor distance
REFERENCE_TOP_SPEED = 1.206  # [m/s]
REFERENCE_S = 0.040  # [m]


def robot_bounds(twin) -> dict[str, tuple[float, float]]:
    """Default search bounds for the twin's robot and motor: :data:`DEFAULT_BOUNDS`, set for the 3pi-class default
    robot, scaled to this one: speeds (v_max, K_B) by its top speed v_top (the firmware's full wheel speed ×
    wheel radius) against the reference robot's, and K_P, K_I, K_D by v_top · S: on the same track a faster
    robot needs proportionally faster turns, and an array further ahead sees a smaller line angle
    (e ≈ offset / S) for the same offset from the line. The wheel base needs no scaling: the firmware turns ω
    into wheel speeds with the robot's own L. The default robot gets :data:`DEFAULT_BOUNDS` exactly."""
    twin.model()
    v_top = twin.space.get("control.full_speed") * twin.info.wheel_radius
    speed = v_top / REFERENCE_TOP_SPEED
    turn = speed * twin.sensor_distance / REFERENCE_S
    if abs(speed - 1) < 1e-3 and abs(turn - 1) < 1e-3:
        return dict(DEFAULT_BOUNDS)
    scale = {"control.v_max": speed, "control.kb": speed, "control.kp": turn, "control.ki": turn, "control.kd": turn}
    out = {}
    for a, (lo, hi) in DEFAULT_BOUNDS.items():
        p = twin.space.parameter(a)  # within what the parameter allows
        out[a] = (max(lo * scale[a], p.lower), min(hi * scale[a], p.upper))
    return out


class TunerError(TwinError):
    """Bad input to the learning model; the message names the input and the fault."""


AT_BOUND = 1e-4  # a value this close to a bound (fraction of its range) ended on it


@dataclasses.dataclass(frozen=True)
class Bounded:
    """One searched parameter: its address and closed bounds [lower, upper] in its own unit."""

    address: str
    lower: float
    upper: float


class SearchSpace:
    """The searched parameters, checked against the model space, and the map to and from the unit box.

    Args:
      space: the model space (addresses, units, allowed ranges).
      addresses: what to search, in order; default Eq. 13's five gains.
      bounds: {address: (lower, upper)} overriding the default bounds.
    """

    def __init__(self, space: ModelSpace, addresses: Sequence[str] = (), bounds: Mapping[str, tuple[float, float]] = {}):
        addresses = list(addresses) or list(DEFAULT_BOUNDS)
        if len(set(addresses)) != len(addresses):
            raise TunerError(f"search space: an address is given twice ({', '.join(addresses)})")
        for a in bounds:
            if a not in addresses:
                raise TunerError(f"bounds of {a}: not a searched parameter (searched: {', '.join(addresses)})")
        self.params: list[Bounded] = []
        for a in addresses:
            p = space.parameter(a)  # unknown address: one-line error
            if p.cost is ChangeCost.REBUILD:
                raise TunerError(f"{a}: rebuilds the robot or track, so it cannot differ between the laps of one batch")
            if p.integer:
                raise TunerError(f"{a}: a whole-number parameter cannot be searched by gradient descent")
            lo, hi = bounds.get(a, DEFAULT_BOUNDS.get(a, (p.lower, p.upper)))
            for name, v in (("lower", lo), ("upper", hi)):
                if not (isinstance(v, (int, float)) and math.isfinite(v)):
                    raise TunerError(f"{a}: {name} bound must be a finite number, got {v!r}")
            if not lo < hi:
                raise TunerError(f"{a}: bounds [{lo:g}, {hi:g}] are inverted or empty")
            p.check(f"{a} lower bound", lo)
            p.check(f"{a} upper bound", hi)
            self.params.append(Bounded(a, float(lo), float(hi)))
        self.lower = np.array([p.lower for p in self.params])
        self.upper = np.array([p.upper for p in self.params])

    @property
    def addresses(self) -> list[str]:
        return [p.address for p in self.params]

    def __len__(self) -> int:
        return len(self.params)

    def to_unit(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x, dtype=float) - self.lower) / (self.upper - self.lower)

    def from_unit(self, z: np.ndarray) -> np.ndarray:
        return self.lower + np.clip(np.asarray(z, dtype=float), 0.0, 1.0) * (self.upper - self.lower)

    def start(self, space: ModelSpace) -> np.ndarray:
        """The model space's current values, which must lie inside the bounds."""
        x = np.array([space.get(a) for a in self.addresses])
        for p, v in zip(self.params, x):
            if not p.lower <= v <= p.upper:
                raise TunerError(f"{p.address}: the start value {v:g} is outside its bounds [{p.lower:g}, {p.upper:g}]")
        return x

    def bounds_hit(self, x: np.ndarray) -> list[tuple[str, str, float]]:
        """(address, "lower" or "upper", bound) of each value within :data:`AT_BOUND` of its range from a bound:
        the search could not go on that way, so the best may lie beyond."""
        z = self.to_unit(x)
        return [(p.address, side, bound) for p, zi in zip(self.params, z)
                for side, bound, hit in (("lower", p.lower, zi <= AT_BOUND), ("upper", p.upper, zi >= 1 - AT_BOUND)) if hit]

    def assignments(self, x: np.ndarray) -> dict[str, float]:
        return {a: float(v) for a, v in zip(self.addresses, x)}
