"""The interval of a parameter value from one measured output: inverse prediction (the calibration problem), free of
any assumed shape of the noise.

A lap's time is a smooth function of the parameter plus the lap-to-lap noise of the sensors, and that noise is not
Gaussian: on the oval with tuned gains it is skewed towards slow laps (skewness 0.7–1.1 over 300 seeds; its 97.5 %
quantile 2.3–2.6 standard deviations above the mean, not 1.96), so an interval built on a normal scatter (Fieller's)
misses robots whose one lap was a slow one. Instead:

* **the noise**: ``n`` laps at the solution ``x0`` on ``n`` seeds. One more lap on another seed (the robot's) is
  exchangeable with them, so it falls between their fastest and slowest with probability ``(n − 1)/(n + 1)``
  whatever the noise's shape (a distribution-free prediction interval from order statistics: Hahn & Meeker,
  *Statistical Intervals*, 1991, §5.2; Wilks 1941). ``n = 39`` gives 95 %.
* **the slope**: laps at ``x0 (1 ± span)`` on the same seeds (common random numbers: each seed's difference cancels
  most of its noise), their mean difference and its Student-t 95 % interval.
* **the inversion**: the values whose laps' range, shifted along the slope, holds the measurement:
  ``x0 + (y0 − max)/b … x0 + (y0 − min)/b``, taken over both ends of the slope's interval (a slope that may be 0
  pins nothing: None).

It holds where the noise's shape is the same across the interval and the lap time is straight over it: the laps at
``x0`` on the sides' seeds must lie, on average, within ``STRAIGHT`` of their range of the chord between the sides
(near the grip limit a lap's time moves by slips, and a chord over a wide span is no line); the caller widens
``span`` until the interval lies inside the values it was fitted on. Written here: no library inverts a
prediction interval (scipy gives the t quantile).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np
from scipy import stats

LEVEL = 0.95
STRAIGHT = 0.25  # the chord between the sides may miss the laps at x0 (same seeds, mean) by this much of their range


def seeds_for(level: float = LEVEL) -> int:
    """Laps whose fastest and slowest hold one more with probability ``level``: (n − 1)/(n + 1) ≥ level."""
    return math.ceil((1 + level) / (1 - level) - 1e-9)


@dataclasses.dataclass(frozen=True)
class InverseInterval:
    """The values that explain one measurement, and what they come from."""

    interval: tuple[float, float] | None  # None: the slope is not told apart from 0
    slope: tuple[float, float]  # its 95 % interval [output per unit of x]
    spread: tuple[float, float]  # the fastest and slowest of the laps at x0 [output]
    inside: bool  # the interval lies within the values the slope was taken over (no extrapolation)
    straight: bool  # the output is straight over them: at x0 its laps miss the chord by under STRAIGHT of the spread


def inverse_interval(x0: float, at_x0: Sequence[float], x_lo: float, at_lo: Sequence[float], x_hi: float,
                     at_hi: Sequence[float], y0: float) -> InverseInterval:
    """The values whose single output would be ``y0`` (see the module docstring): ``at_x0`` the outputs at ``x0`` on
    n seeds, ``at_lo`` and ``at_hi`` those at ``x_lo`` < ``x_hi`` on the same k ≥ 2 seeds, in the same order."""
    at_x0, at_lo, at_hi = (np.asarray(a, float) for a in (at_x0, at_lo, at_hi))
    if len(at_x0) < 2 or len(at_lo) < 2 or len(at_lo) != len(at_hi) or not x_lo < x_hi:
        raise ValueError("inverse_interval: 2 or more outputs at x0, and paired ones at x_lo < x_hi, are needed")
    d = (at_hi - at_lo) / (x_hi - x_lo)
    k = len(d)
    half = float(stats.t.ppf(0.5 + LEVEL / 2, k - 1)) * float(d.std(ddof=1)) / math.sqrt(k)
    slope = (float(d.mean()) - half, float(d.mean()) + half)
    spread = (float(at_x0.min()), float(at_x0.max()))
    chord = at_lo + (x0 - x_lo) / (x_hi - x_lo) * (at_hi - at_lo)
    bend = abs(float((at_x0[:k] - chord).mean())) if len(at_x0) >= k else math.inf
    straight = bend <= STRAIGHT * (spread[1] - spread[0])
    if slope[0] <= 0 <= slope[1]:
        return InverseInterval(None, slope, spread, False, straight)
    ends = [x0 + (y0 - y) / b for y in spread for b in slope]
    lo, hi = min(ends), max(ends)
    return InverseInterval((lo, hi), slope, spread, bool(x_lo <= lo and hi <= x_hi), straight)


# --- the scatter of laps raced on a few seeds a value (the consistent ranges of tuner.align.lap_time)

D2 = {2: 1.128, 3: 1.693, 4: 2.059, 5: 2.326}  # E[range] / σ of n normal draws (Montgomery, SQC, Table VI)
SCATTER_POINTS = 5  # values whose ranges are pooled for the lap-to-lap scatter at a value


def median_variance(n: int) -> float:
    """Var(median of n normal draws) / σ²: exact for 1–3 (1, 0.5, 0.4487), else π / (2n)."""
    return {1: 1.0, 2: 0.5, 3: 0.4487}.get(n, math.pi / (2 * n))


def local_scatter(done: list, noise_seeds: int) -> list[float]:
    """The lap-to-lap σ at each value: the mean range of single laps at the ``SCATTER_POINTS`` nearest values (by
    ratio for positive ones) over d2 (the range estimator of process control); 0 with one seed a value."""
    if noise_seeds not in D2:
        return [0.0] * len(done)
    spans = [(v, sp[1] - sp[0]) for v, (t, sp) in done if t is not None and sp is not None]
    out = []
    for v, _ in done:
        key = (lambda u: abs(math.log(u / v))) if v > 0 and all(u > 0 for u, _ in spans) else (lambda u: abs(u - v))
        near = sorted(spans, key=lambda us: key(us[0]))[:SCATTER_POINTS]
        out.append(float(np.mean([r for _, r in near])) / D2[noise_seeds] if near else 0.0)
    return out
