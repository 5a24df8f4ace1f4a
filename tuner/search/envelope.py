"""The conditions gains must survive, and how their laps add up to one cost.

An **envelope** is a set of scenarios (each a few batchable model-space values: tyre μ, supply voltage, …, the
cross product of the given axes) times a set of sensor-noise seeds. A gain vector's cost aggregates the costs
of all its laps by a **risk measure**:

* ``mean``: the average lap cost;
* ``worst``: the largest, so every scenario and seed must go well;
* ``cvar:α``: the mean of the worst ⌈α·n⌉ lap costs (conditional value at risk), between the two.

The plain tuner is the envelope of one scenario (the twin as it is) and one seed, with either measure.

The ``--robust`` preset (:data:`ROBUST_AXES`, :data:`ROBUST_SEEDS`, :data:`ROBUST_RISK`) is a realistic envelope
for the default robot, a Pololu 3pi+ 32U4 class:

* ``motion.mu`` ∈ {0.6, 0.9}: nominal 0.9 (the model's assumption for rubber on a laminated board) down to ⅔ of
  it, dusty tyres or floor (the paper's case 2: dirty tyres make the robot slower);
* ``motor.supply_voltage`` ∈ {4.8, 6.0} V: the model's 6 V drive, and 80 % of it. Four AAA NiMH cells give
  4.8 V nominal (Pololu 3pi+ 32U4 user's guide, §5.7); a cell ends its discharge at 1.0 V (Panasonic HHR70AAAJ
  data sheet: discharge to 1.0 V) against ≈ 1.25 V fresh under load, so a tired pack supplies 1.0/1.25 = 80 %.
  The 3pi+ regulates its motor voltage, which hides most of this; robots that drive their motors from the pack
  (most hobby builds) see all of it;
* 3 noise seeds, and the ``worst`` measure: the gains must finish every corner with every seed.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from typing import Mapping, Sequence

import numpy as np

from twin.errors import TwinError

ROBUST_AXES: dict[str, tuple[float, ...]] = {"motion.mu": (0.6, 0.9), "motor.supply_voltage": (4.8, 6.0)}
ROBUST_SEEDS = 8
ROBUST_RISK = "worst"
HELD_OUT_OFFSET = 1000  # held-out seeds start this far above the tuning seeds


@dataclasses.dataclass(frozen=True)
class Risk:
    """How the lap costs of one gain vector add up to its cost."""

    kind: str  # "mean", "worst" or "cvar"
    alpha: float = 1.0  # cvar: the worst fraction averaged

    @classmethod
    def parse(cls, text: str) -> "Risk":
        """``mean``, ``worst`` or ``cvar:ALPHA`` with 0 < ALPHA ≤ 1."""
        kind, _, alpha = str(text).partition(":")
        if kind in ("mean", "worst") and not alpha:
            return cls(kind)
        if kind == "cvar":
            try:
                a = float(alpha)
            except ValueError:
                a = math.nan
            if 0 < a <= 1:
                return cls("cvar", a)
        raise TwinError(f"risk {text!r}: expected mean, worst or cvar:ALPHA with 0 < ALPHA <= 1")

    def __call__(self, costs: np.ndarray) -> np.ndarray:
        """Aggregate (m, n) lap costs to (m,) costs, row by row."""
        c = np.atleast_2d(np.asarray(costs, dtype=float))
        if self.kind == "mean":
            return c.mean(axis=1)
        if self.kind == "worst":
            return c.max(axis=1)
        k = max(1, math.ceil(self.alpha * c.shape[1]))
        return np.sort(c, axis=1)[:, -k:].mean(axis=1)

    def worst_k(self, n: int) -> int | None:
        """How many of ``n`` lap costs make up this measure: the worst lap's 1, cvar's ⌈α·n⌉; None for the mean."""
        if self.kind == "mean":
            return None
        return 1 if self.kind == "worst" else max(1, math.ceil(self.alpha * n))

    def deciding(self, costs: np.ndarray, margin: float = 0.0) -> list[int] | None:
        """The laps of ``costs`` (n,) that make up this measure (the worst lap, or cvar's worst ⌈α·n⌉), and any lap
        within ``margin`` (relative) of the cheapest of them; None for the mean, which every lap makes up."""
        k = self.worst_k(len(costs))
        if k is None:
            return None
        c = np.asarray(costs, dtype=float)
        order = np.argsort(-c, kind="stable")
        floor = c[order[k - 1]] * (1.0 - margin)
        return sorted(set(int(i) for i in order[:k]) | set(int(i) for i in np.flatnonzero(c >= floor)))

    def of_worst(self, costs: np.ndarray, n: int) -> np.ndarray:
        """This measure of (m, j) lap costs out of ``n`` laps a point has, when the other n − j cost less than these:
        the worst lap, or the mean of the worst ⌈α·n⌉ (j must be at least that many). Equal, bit for bit, to the
        measure of all n costs in that case."""
        c = np.atleast_2d(np.asarray(costs, dtype=float))
        k = self.worst_k(n)
        if k is None or c.shape[1] < k:
            raise ValueError(f"risk {self}: needs the worst {k} of {n} laps, got {c.shape[1]}")
        return c.max(axis=1) if self.kind == "worst" else np.sort(c, axis=1)[:, -k:].mean(axis=1)

    def lap_bound(self, bound: float, n: int) -> float:
        """The lap cost above which a point of ``n`` laps costs more than ``bound``, whatever its other laps cost
        (each at least 0): the worst lap counts whole, the mean 1/n of it, cvar 1/⌈α·n⌉."""
        if self.kind == "worst":
            return bound
        return bound * (n if self.kind == "mean" else max(1, math.ceil(self.alpha * n)))

    def __str__(self) -> str:
        return f"cvar:{self.alpha:g}" if self.kind == "cvar" else self.kind


@dataclasses.dataclass(frozen=True)
class Envelope:
    """Scenarios (the cross product of ``axes``) × noise ``seeds``."""

    axes: tuple[tuple[str, tuple[float, ...]], ...]
    seeds: tuple[int, ...]

    @classmethod
    def of(cls, axes: Mapping[str, Sequence[float]], seeds: Sequence[int]) -> "Envelope":
        if not seeds:
            raise TwinError("envelope: at least one noise seed")
        for address, values in axes.items():
            if not values:
                raise TwinError(f"--scenario {address}: give at least one value")
        return cls(tuple((a, tuple(float(v) for v in vs)) for a, vs in axes.items()), tuple(int(s) for s in seeds))

    @property
    def scenarios(self) -> list[dict[str, float]]:
        names = [a for a, _ in self.axes]
        return [dict(zip(names, combo)) for combo in itertools.product(*(vs for _, vs in self.axes))]

    @property
    def corners(self) -> list[dict[str, float]]:
        """The scenarios at the ends of every axis (all of them when each axis has at most two values)."""
        names = [a for a, _ in self.axes]
        return [dict(zip(names, combo)) for combo in itertools.product(*({vs[0], vs[-1]} for _, vs in self.axes))]

    def __len__(self) -> int:
        return len(self.scenarios) * len(self.seeds)


def label(scenario: Mapping[str, float]) -> str:
    """``motion.mu=0.6, motor.supply_voltage=4.8``, or ``nominal`` for the twin as it is."""
    return ", ".join(f"{a}={v:g}" for a, v in scenario.items()) or "nominal"


def held_out_seeds(envelope: Envelope, count: int) -> tuple[int, ...]:
    """Seeds never used in tuning: ``count`` of them from HELD_OUT_OFFSET above the largest tuning seed."""
    start = max(envelope.seeds) + HELD_OUT_OFFSET
    return tuple(range(start, start + count))
