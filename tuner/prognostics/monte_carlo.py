"""Remaining useful life by Monte Carlo: each particle of the degradation state (:mod:`tuner.prognostics.
particle_filter`) is carried forward lap by lap (v ← v + r, r ← r + a + N(0, q²), as the filter does; no renewal:
the forecast is of the part as it is) and each lap is
raced against the failure model: it fails with probability p_fail(v). The first lap that fails is that future's
end of life; over all particles, the distribution of the number of laps, after the last lap seen, to the first
failed lap of the gains in force. Futures that have not failed within ``horizon`` laps are censored (+∞): a
quantile beyond the horizon is an open end, never a made-up number.

The same futures give when the parameter reaches a service limit (the worn end of the robust envelope).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from tuner.prognostics.evidence import FailureModel
from tuner.prognostics.particle_filter import DegradationState, one_way

HORIZON = 1000  # [laps]
QUANTILES = (0.05, 0.10, 0.25, 0.50, 0.75, 0.90, 0.95)


@dataclasses.dataclass(frozen=True)
class RemainingLife:
    """Laps after the last lap seen to the first failed lap, per future (``inf`` beyond the horizon)."""
    laps: np.ndarray  # (futures,) 1 = the next lap fails
    horizon: int
    service_laps: np.ndarray | None = None  # (futures,) laps until the service limit is reached (0: already);
    # with two causes (futures, 2), each its own
    speeding_up: np.ndarray | None = None  # (futures,) does this future's wear speed up (None: not a part that only
    # wears, whose filter weighs a straight line against a curve)

    def quantile(self, q: float) -> float:
        x = float(np.quantile(self.laps, q, method="inverted_cdf"))
        return x if x <= self.horizon else math.inf

    def quantiles(self) -> dict[str, float | None]:
        """{"5": …, …, "95": …} in laps; None for an open end (beyond the horizon)."""
        return {f"{round(q * 100)}": _finite(self.quantile(q)) for q in QUANTILES}

    def within(self, laps: float) -> float:
        """The probability that the first failure comes within ``laps`` laps."""
        return float(np.mean(self.laps <= laps))

    def by_shape(self) -> dict | None:
        """{"straight": …, "speeding_up": …}, each {"share": of the futures, "median": laps (None: beyond the
        horizon, or no such future)}; None when the wear's shape was not weighed."""
        if self.speeding_up is None:
            return None
        out = {}
        for name, these in (("straight", ~self.speeding_up), ("speeding_up", self.speeding_up)):
            median = RemainingLife(self.laps[these], self.horizon).quantile(0.5) if these.any() else math.inf
            out[name] = {"share": float(np.mean(these)), "median": _finite(median)}
        return out

    def service_median(self, dim: int = 0) -> float | None:
        if self.service_laps is None:
            return None
        laps = self.service_laps if self.service_laps.ndim == 1 else self.service_laps[:, dim]
        x = float(np.quantile(laps, 0.5, method="inverted_cdf"))
        return None if x > self.horizon else x


def _finite(x: float) -> float | None:
    return None if math.isinf(x) else x


def remaining_life(state: DegradationState, failure: FailureModel, q: float | np.ndarray, seed: int = 0,
                   horizon: int = HORIZON, service_limit: float | np.ndarray | None = None) -> RemainingLife:
    """The distribution of laps to the first failure from ``state`` (its last lap), rate walk ``q`` [unit per lap
    per lap]; with a ``service_limit`` (on the failing side) also when it is reached. Two causes at once: ``state``
    and ``failure`` over their plane, ``q`` and ``service_limit`` one per cause."""
    rng = np.random.default_rng(seed)
    v, r, a = state.value.copy(), state.rate.copy(), state.acceleration
    n = len(v)
    first = np.full(n, np.inf)
    service = None
    worn = np.asarray(failure.direction)  # the way each part wears
    if service_limit is not None:
        service_limit = np.asarray(service_limit, float)
        service = np.where(worn * (v - service_limit) >= 0, 0.0, np.inf)
    alive = np.ones(n, dtype=bool)
    for k in range(1, horizon + 1):
        v = v + r
        r = one_way(r + a + q * rng.standard_normal(v.shape), state.one_way)
        fails = alive & (rng.random(n) < failure.p_fail(v, state.shift))
        first[fails] = k
        alive &= ~fails
        if service is not None:
            service[np.isinf(service) & (worn * (v - service_limit) >= 0)] = k
        if not alive.any() and (service is None or not np.isinf(service).any()):
            break
    return RemainingLife(first, horizon, service, state.speeding_up if np.any(state.one_way) else None)
