"""The exact posterior of the one-cause particle filter's model, by adaptive importance sampling: an independent
check of the filter (:mod:`tuner.prognostics.particle_filter`: sequential importance resampling, Liu-West moves,
noise scale and edge shift on grids), which approximates the same posterior lap by lap.

The model, as the filter states it, for a part that only wears (``one_way`` ≠ 0), without the rate's random walk and
without renewals (``rate_walk`` = ``renewal`` = 0), so that a life is three numbers at the first lap with evidence,
``start``: the value v₀ ~ U(value_range), the rate r₀ (half-normal, sd ``rate_prior``·span, in the wear's
direction), and the acceleration a: 0 for half the lives (straight wear), half-normal (sd ``accel_prior``·span, in
the wear's direction) for the other half (speeding up). At lap start + k the value is v₀ + k·r₀ + a·k(k − 1)/2 and
the rate r₀ + k·a (the filter's v ← v + r, r ← r + a). Given a life, each measurement is normal about the value's
mean over its laps with standard error s·σ, each finished lap's features (where there are) normal about the
observation model's at the value with covariance s²·Σ, each lap outcome fails with probability
ε + (1 − 2ε)·p_fail(v, δ); the noise scale s is uniform over the filter's grid of scales and the edge shift δ
normal over its grid of shifts, both summed out exactly for each life.

The posterior of (v₀, r₀, a) for each shape is sampled by population Monte Carlo: prior draws, then rounds of draws
from a Student-t fitted to the weighted draws of the round before, each weighed prior × likelihood / proposal; the
last round gives the shape's evidence (the mean weight) and its posterior. The shares of the two shapes are their
evidence (each with prior 1/2). The remaining life is then carried forward by the program's own Monte Carlo
(:func:`tuner.prognostics.remaining_life`) from the exact posterior's lives, so a difference is the filter's.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np
from scipy.special import logsumexp
from scipy.stats import multivariate_t

from tuner.prognostics import (FailureModel, FilterSettings, LapObservation, Measurement, ObservationModel, Outcome,
                               remaining_life)
from tuner.prognostics.monte_carlo import RemainingLife
from tuner.prognostics.particle_filter import SCALE_GRID, SCALE_PRIOR, SHIFT_GRID, DegradationState

ROUNDS = 3  # proposal refits: the effective sample size settles by the second on the tests' lives


@dataclasses.dataclass(frozen=True)
class ExactPosterior:
    """``speeding_up``: the posterior probability that the wear speeds up; ``life``: the remaining life from the
    exact posterior; ``effective``: each shape's effective number of draws in the last round (straight, speeding
    up), how far to trust the rest."""
    speeding_up: float
    life: RemainingLife
    effective: tuple[float, float]


def _at(theta: np.ndarray, curved: bool, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(value, rate, acceleration) of each life (v₀, r₀[, a]) ``k`` laps after its first."""
    a = theta[:, 2] if curved else np.zeros(len(theta))
    return theta[:, 0] + k * theta[:, 1] + a * k * (k - 1) / 2, theta[:, 1] + k * a, a


def _shifts(failure: FailureModel, settings: FilterSettings) -> np.ndarray:
    """The filter's grid of edge shifts (± 4 prior sd)."""
    return math.hypot(failure.width, settings.edge_prior) * np.linspace(-4.0, 4.0, SHIFT_GRID)


def _log_likelihood(theta: np.ndarray, curved: bool, evidence: tuple, start: int, settings: FilterSettings,
                    failure: FailureModel) -> tuple[np.ndarray, np.ndarray]:
    """(log likelihood of each life (n,), the log posterior of each life's shift on the grid (n, SHIFT_GRID))."""
    measurements, outcomes, observations, model = evidence

    def at(lap: int) -> tuple[np.ndarray, np.ndarray]:
        return _at(theta, curved, lap - start)[:2]

    scales = np.exp(np.linspace(math.log(SCALE_PRIOR[0]), math.log(SCALE_PRIOR[1]), SCALE_GRID))
    by_scale = np.zeros((len(theta), SCALE_GRID))
    for m in measurements:
        v, r = at(m.lap)
        z2 = ((m.value - (v - r * (m.lap - m.first_lap) / 2)) / m.sigma) ** 2
        by_scale += -0.5 * z2[:, None] / scales ** 2 - np.log(scales * m.sigma)
    for o in observations:
        d2, logdet = model.distance(o.features, at(o.lap)[0])
        by_scale += -0.5 * d2[:, None] / scales ** 2 - len(model.names) * np.log(scales) - 0.5 * logdet[:, None]
    log_scale = logsumexp(by_scale, axis=1) - math.log(SCALE_GRID)
    grid = np.linspace(-4.0, 4.0, SHIFT_GRID)
    shifts = _shifts(failure, settings)
    by_shift = np.tile(-0.5 * grid ** 2 - logsumexp(-0.5 * grid ** 2), (len(theta), 1))
    for o in outcomes:
        v, _ = at(o.lap)
        p = settings.surprise + (1 - 2 * settings.surprise) * failure.p_fail(v[:, None], shifts[None, :])
        by_shift += np.log(p if o.failed else 1 - p)
    log_shift = logsumexp(by_shift, axis=1)
    return log_scale + log_shift, by_shift - log_shift[:, None]


def _log_prior(theta: np.ndarray, curved: bool, lo: float, hi: float, sign: float, sd_r: float,
               sd_a: float) -> np.ndarray:
    """The prior's log density (−inf outside its support): uniform value, half-normal rate and acceleration."""
    inside = (theta[:, 0] >= lo) & (theta[:, 0] <= hi) & (sign * theta[:, 1] >= 0)
    out = -math.log(hi - lo) + math.log(2 / (sd_r * math.sqrt(2 * math.pi))) - 0.5 * (theta[:, 1] / sd_r) ** 2
    if curved:
        inside &= sign * theta[:, 2] >= 0
        out = out + math.log(2 / (sd_a * math.sqrt(2 * math.pi))) - 0.5 * (theta[:, 2] / sd_a) ** 2
    return np.where(inside, out, -np.inf)


def _sample_shape(curved: bool, draws: int, rng: np.random.Generator, evidence: tuple, start: int, settings,
                  failure) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(lives (draws, dim), their log weights, their shifts' log posteriors, log evidence) for one shape."""
    (lo, hi), sign = settings.value_range, float(settings.one_way)
    sd_r, sd_a = settings.rate_prior * settings.span, settings.accel_prior * settings.span
    dim = 3 if curved else 2
    theta = np.stack([rng.uniform(lo, hi, draws), sign * np.abs(rng.standard_normal(draws)) * sd_r]
                     + ([sign * np.abs(rng.standard_normal(draws)) * sd_a] if curved else []), axis=1)
    log_proposal = _log_prior(theta, curved, lo, hi, sign, sd_r, sd_a)
    for round_ in range(ROUNDS + 1):
        prior = _log_prior(theta, curved, lo, hi, sign, sd_r, sd_a)
        ok = np.isfinite(prior)
        lik, shift_post = np.full(draws, -np.inf), np.zeros((draws, SHIFT_GRID))
        lik[ok], shift_post[ok] = _log_likelihood(theta[ok], curved, evidence, start, settings, failure)
        logw = np.where(ok, prior + lik - log_proposal, -np.inf)
        if round_ == ROUNDS:
            break
        w = np.exp(logw - logw.max())
        w /= w.sum()
        mean = w @ theta
        cov = (theta - mean).T @ ((theta - mean) * w[:, None]) * 1.5 + 1e-12 * np.eye(dim)
        proposal = multivariate_t(mean, cov, df=5, seed=rng)
        theta = proposal.rvs(draws).reshape(draws, dim)
        log_proposal = proposal.logpdf(theta).reshape(draws)
    return theta, logw, shift_post, float(logsumexp(logw) - math.log(draws))


def exact_posterior(measurements: Sequence[Measurement], outcomes: Sequence[Outcome], now: int,
                    settings: FilterSettings, failure: FailureModel, draws: int = 20_000, seed: int = 0,
                    horizon: int = 1000, futures: int = 16_000, observations: Sequence[LapObservation] = (),
                    model: ObservationModel | None = None) -> ExactPosterior:
    """The posterior after lap ``now`` of the filter's model for this evidence (measurements, outcomes and lap
    ``observations`` read through ``model``, up to ``now``; ``settings`` with a value range, one_way ≠ 0, no walk,
    no renewal) and the remaining life from it."""
    if not (settings.value_range and settings.one_way and settings.rate_walk == 0 and settings.renewal == 0):
        raise ValueError("the exact posterior is of a part that only wears, in a range, without walk or renewal")
    rng = np.random.default_rng(seed)
    ms = [m for m in measurements if m.lap <= now]
    obs = [o for o in observations if o.lap <= now] if model is not None else []
    start = min([m.first_lap for m in ms] + [o.lap for o in obs])
    evidence = (ms, [o for o in outcomes if start <= o.lap <= now], [o for o in obs if o.lap >= start], model)
    shapes = [_sample_shape(curved, draws, rng, evidence, start, settings, failure) for curved in (False, True)]
    log_z = np.array([s[3] for s in shapes])
    speeding_up = float(np.exp(log_z[1] - logsumexp(log_z)))
    # equally weighted lives for the prediction: each shape its share of them, by its own weights
    lives = {"v": [], "r": [], "a": [], "shift": []}
    grid = _shifts(failure, settings)
    step = grid[1] - grid[0]
    effective = []
    for curved, (theta, logw, shift_post, _) in zip((False, True), shapes):
        w = np.exp(logw - logw.max())
        w /= w.sum()
        effective.append(float(1 / np.sum(w ** 2)))
        n = int(round(futures * (speeding_up if curved else 1 - speeding_up)))
        idx = rng.choice(len(w), size=n, p=w)
        for name, x in zip(("v", "r", "a"), _at(theta[idx], curved, now - start)):
            lives[name].append(x)
        cb = np.cumsum(np.exp(shift_post[idx]), axis=1)  # each life's shift by its own posterior on the grid
        pick = np.minimum((cb < rng.random(n)[:, None] * cb[:, -1:]).sum(axis=1), SHIFT_GRID - 1)
        lives["shift"].append(grid[pick] + step * (rng.random(n) - 0.5))
    v, r, a, shift = (np.concatenate(lives[x]) for x in ("v", "r", "a", "shift"))
    state = DegradationState(now, v, r, np.ones(len(v)), shift, [], a, settings.one_way)
    life = remaining_life(state, failure, 0.0, seed=seed, horizon=horizon)
    return ExactPosterior(speeding_up, life, (effective[0], effective[1]))
