"""Where the gains in force stop finishing, asked of the twin: it races them at a ladder of values of the wearing
parameter, several noise seeds each (one batch), then more finely across the first failures, and reads from those
laps:

* the failure model (:class:`tuner.prognostics.FailureModel`): the probability that a lap fails at a value,
  a normal CDF fitted by maximum likelihood to every raced lap, finished or failed (a grid over the edge and its
  width: deterministic);
* how well a lap time pins the parameter: the mean lap time's slope over the ladder's values before its first
  failure [s per unit], and the scatter of a lap time around it over noise seeds [s]; an alignment on n laps then knows
  the parameter to about scatter/√n/|slope|, whatever its own consistent interval says.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.special import log_ndtr

from tuner.prognostics import FailureModel
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapLimits

LADDER = 12  # values raced from the least worn measured value to the end of the range, one batch
REFINE = 8  # then across the first failures, one more batch
SEEDS = 4  # noise seeds per value
EDGE_GRID, WIDTH_GRID = 241, 40  # the maximum-likelihood grid


@dataclasses.dataclass(frozen=True)
class TwinEdge:
    failure: FailureModel | None  # None: no lap failed in the range raced
    finished: float | None  # the last value raced where every lap finished (None: none did)
    failing: float | None  # the first value where one failed
    seconds_per_unit: float | None  # d(mean lap time)/d(value) where every lap finished [s per parameter unit]
    lap_time_sd_s: float | None  # a lap time's scatter over noise seeds [s]
    raced: tuple[float, float]
    laps: int

    def value_sd_per_lap(self) -> float | None:
        """How far one lap time pins the parameter (its unit), or None if the laps cannot tell."""
        if not self.seconds_per_unit or self.lap_time_sd_s is None:
            return None
        return self.lap_time_sd_s / abs(self.seconds_per_unit)


def _race(twin, gains, address, values, seeds, seed, limits):
    laps = run_laps(twin, [{**gains, address: float(v)} for v in values for _ in range(seeds)],
                    seed=[seed + k for _ in values for k in range(seeds)], limits=limits, keep_traces=False)
    return [(float(v), [(not r.completed, r.lap_time_s) for r in laps[i * seeds:(i + 1) * seeds]])
            for i, v in enumerate(values)]


def fit_failure(points: list[tuple[float, bool]], direction: float, span: float) -> FailureModel:
    """The normal-CDF failure model of largest likelihood for (value, failed) laps."""
    v = np.array([p[0] for p in points])
    failed = np.array([p[1] for p in points])
    edges = np.linspace(v.min(), v.max(), EDGE_GRID)
    widths = np.geomspace(span * 1e-3, span * 0.2, WIDTH_GRID)
    z = direction * (v[None, None, :] - edges[:, None, None]) / widths[None, :, None]
    ll = np.where(failed, log_ndtr(z), log_ndtr(-z)).sum(axis=2)
    i, j = np.unravel_index(np.argmax(ll), ll.shape)  # first of equals: deterministic
    return FailureModel(float(edges[i]), float(widths[j]), direction)


def _lap_times(rows) -> tuple[float | None, float | None]:
    """(slope [s per unit], scatter [s]) over the values where every lap finished."""
    done = [(v, [t for _, t in laps]) for v, laps in rows if not any(f for f, _ in laps)]
    if len(done) < 2:
        return None, None
    x = np.array([v for v, ts in done for _ in ts])
    y = np.array([t for _, ts in done for t in ts])
    slope = float(np.polyfit(x, y, 1)[0])
    within = [np.var(ts, ddof=1) for _, ts in done if len(ts) > 1]
    return slope, (math.sqrt(float(np.mean(within))) if within else None)


def twin_edge(twin: DigitalTwin, gains: dict, address: str, start: float, end: float, direction: float, seed: int,
              limits: LapLimits, seeds: int = SEEDS) -> TwinEdge:
    """Race ``gains`` from ``address`` = ``start`` towards ``end`` (where the wear goes: ``direction``)."""
    p = twin.space.parameter(address)
    rows = _race(twin, gains, address, np.linspace(start, end, LADDER), seeds, seed, limits)
    any_fail = [any(f for f, _ in laps) for _, laps in rows]
    # the lap time's slope and scatter where the robot runs well: the ladder's values before its first failure
    slope, sd = _lap_times(rows[:any_fail.index(True)] if any(any_fail) else rows)
    if any(any_fail) and not any_fail[0]:
        i = any_fail.index(True)
        hi = min(i + 1, len(rows) - 1)  # across the first failures and one step beyond
        rows += _race(twin, gains, address, np.linspace(rows[i - 1][0], rows[hi][0], REFINE + 2)[1:-1], seeds, seed,
                      limits)
    rows.sort(key=lambda r: direction * r[0])  # from the least worn
    laps = sum(len(l) for _, l in rows)
    fails = [any(f for f, _ in l) for _, l in rows]
    if not any(fails):
        return TwinEdge(None, float(end), None, slope, sd, (start, end), laps)
    k = fails.index(True)
    all_fail = [all(f for f, _ in l) for _, l in rows]
    upto = all_fail.index(True) + 1 if any(all_fail) else len(rows)  # beyond where every lap fails, nothing to learn
    failure = fit_failure([(v, f) for v, l in rows[:upto] for f, _ in l], direction, float(p.upper - p.lower))
    return TwinEdge(failure, rows[k - 1][0] if k else None, rows[k][0], slope, sd, (start, end), laps)
