"""The degradation state of one parameter, estimated lap by lap by a particle filter (sequential importance
resampling), from every measurement and every lap outcome (:mod:`tuner.prognostics.evidence`).

A particle is (v, r, s, δ): the parameter's value at the current lap, its rate of change per lap, how far the
alignments' stated standard errors are to be trusted (a scale on them, learnt from their scatter), and where this
robot's failure edge lies against the twin's (δ ~ N(0, width²) a priori: the twin's edge is the prior, the robot's
own finished and failed laps move it). From one lap to
the next v ← v + r and r ← r + N(0, q²): wear at a rate that may itself change (accelerating, slowing), so the
longer the forecast the wider it grows. A measurement of laps a..b weighs a particle by the normal density of the
measured value around the particle's mean over those laps (v − r·(b − a)/2), with standard error s·σ; a lap
outcome by the failure model's probability (with a small chance ``SURPRISE`` of a failure, or a finish, that the
parameter does not explain, so that one odd lap cannot overrule everything else). When the effective number of
particles falls below half, they are resampled (systematic), and the noise scale is jittered so it does not
collapse to a single value.

Everything random comes from one ``numpy.random.Generator`` seeded by the caller: the same evidence and seed give
bit-identical particles.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np

from tuner.prognostics.evidence import FailureModel, Measurement, Outcome

PARTICLES = 4000
SURPRISE = 0.02  # chance of a lap outcome the parameter does not explain
RATE_PRIOR = 0.01  # the prior rate's standard deviation, per lap, as a fraction of the parameter's range
RATE_WALK = 5e-4  # q: the rate's change per lap (standard deviation), as a fraction of the parameter's range
SCALE_PRIOR = (0.5, 4.0)  # the noise scale s, log-uniform between these
SCALE_JITTER = 0.05  # log s jitter at a resampling


@dataclasses.dataclass(frozen=True)
class FilterSettings:
    """span: the parameter's plausible range (upper − lower) in its unit, which scales the priors."""
    span: float
    particles: int = PARTICLES
    rate_prior: float = RATE_PRIOR
    rate_walk: float = RATE_WALK
    surprise: float = SURPRISE

    @property
    def q(self) -> float:
        return self.rate_walk * self.span


@dataclasses.dataclass
class DegradationState:
    """The particles at lap ``lap`` (equally weighted), and the estimate lap by lap: for each lap filtered, the
    value's 5 %, 50 % and 95 % quantiles."""
    lap: int
    value: np.ndarray  # (particles,)
    rate: np.ndarray  # (particles,) per lap
    scale: np.ndarray  # (particles,)
    shift: np.ndarray  # (particles,) the robot's failure edge against the twin's [parameter unit]
    band: list[tuple[int, float, float, float]]  # (lap, q05, median, q95)

    def quantiles(self, q=(0.05, 0.5, 0.95)) -> tuple[float, ...]:
        return tuple(float(x) for x in np.quantile(self.value, q))

    def rate_quantiles(self, q=(0.05, 0.5, 0.95)) -> tuple[float, ...]:
        return tuple(float(x) for x in np.quantile(self.rate, q))


def weighted_quantiles(x: np.ndarray, w: np.ndarray, q: Sequence[float]) -> list[float]:
    order = np.argsort(x, kind="stable")
    cw = np.cumsum(w[order])
    cw /= cw[-1]
    return [float(x[order][min(np.searchsorted(cw, p), len(x) - 1)]) for p in q]


def systematic_resample(w: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    n = len(w)
    positions = (rng.random() + np.arange(n)) / n
    cw = np.cumsum(w)
    cw[-1] = 1.0
    return np.searchsorted(cw, positions)


def estimate(measurements: Sequence[Measurement], outcomes: Sequence[Outcome], until_lap: int,
             settings: FilterSettings, failure: FailureModel | None = None, seed: int = 0) -> DegradationState:
    """Filter from the first measured lap to ``until_lap``; ``outcomes`` count only with a ``failure`` model (laps
    before the first measurement are not used). Needs at least one measurement."""
    if not measurements:
        raise ValueError("no measurement to start from")
    rng = np.random.default_rng(seed)
    n, q = settings.particles, settings.q
    ms = sorted(measurements, key=lambda m: (m.lap, m.first_lap, m.value, m.sigma))
    start = min(m.first_lap for m in ms)
    first = ms[0]
    # prior at the first lap measured: around the first measurement, wide enough for any scale of its error
    v = first.value + rng.standard_normal(n) * max(3 * SCALE_PRIOR[1] * first.sigma, 0.02 * settings.span)
    r = rng.standard_normal(n) * settings.rate_prior * settings.span
    log_s = rng.uniform(math.log(SCALE_PRIOR[0]), math.log(SCALE_PRIOR[1]), n)
    shift = rng.standard_normal(n) * (failure.width if failure is not None else 0.0)
    logw = np.zeros(n)
    by_lap: dict[int, list] = {}
    for m in ms:
        by_lap.setdefault(m.lap, []).append(m)
    outs: dict[int, list[Outcome]] = {}
    if failure is not None:
        for o in sorted(outcomes, key=lambda o: (o.lap, o.failed)):
            if start <= o.lap <= until_lap:
                outs.setdefault(o.lap, []).append(o)
    band = []
    for lap in range(start, max(until_lap, ms[-1].lap) + 1):
        if lap > start:
            v = v + r
            r = r + q * rng.standard_normal(n)
        for m in by_lap.get(lap, ()):
            sd = np.exp(log_s) * m.sigma
            mean = v - r * (m.lap - m.first_lap) / 2
            logw += -0.5 * ((m.value - mean) / sd) ** 2 - np.log(sd)
        for o in outs.get(lap, ()):
            p = settings.surprise + (1 - 2 * settings.surprise) * failure.p_fail(v, shift)
            logw += np.log(p if o.failed else 1 - p)
        w = np.exp(logw - logw.max())
        w /= w.sum()
        band.append((lap, *weighted_quantiles(v, w, (0.05, 0.5, 0.95))))
        if 1.0 / np.sum(w ** 2) < n / 2:
            idx = systematic_resample(w, rng)
            v, r, shift = v[idx], r[idx], shift[idx]
            log_s = log_s[idx] + SCALE_JITTER * rng.standard_normal(n)
            logw = np.zeros(n)
    w = np.exp(logw - logw.max())
    w /= w.sum()
    idx = systematic_resample(w, rng)  # equally weighted particles for the prediction
    return DegradationState(band[-1][0], v[idx], r[idx], np.exp(log_s[idx]), shift[idx], band)
