"""The exact posterior of the particle filter's model, by adaptive importance sampling: an independent
check of the filter (:mod:`tuner.prognostics.particle_filter`: sequential importance resampling, Liu-West moves,
noise scale and edge shift on grids), which approximates the same posterior lap by lap.

The model, as the filter states it, for a part that only wears (``one_way`` ≠ 0), without the rate's random walk
(``rate_walk`` = 0), so that a life without a renewal is three numbers at the first lap with evidence,
``start``: the value v₀ ~ U(value_range), the rate r₀ (half-normal, sd ``rate_prior``·span, in the wear's
direction), and the acceleration a: 0 for half the lives (straight wear), half-normal (sd ``accel_prior``·span, in
the wear's direction) for the other half (speeding up). At lap start + k the value is v₀ + k·r₀ + a·k(k − 1)/2 and
the rate r₀ + k·a (the filter's v ← v + r, r ← r + a). Given a life, each measurement is normal about the value's
mean over its laps with standard error s·σ, each finished lap's features (where there are) normal about the
observation model's at the value with covariance s²·Σ, each lap outcome fails with probability
ε + (1 − 2ε)·p_fail(v, δ); the noise scale s is uniform over the filter's grid of scales and the edge shift δ
normal over its grid of shifts, both summed out exactly for each life.

With renewals (``renewal`` = ρ > 0: a tyre swapped, a battery charged) a part is renewed at a lap with probability ρ:
its value drawn again from ``value_range``, its rate and acceleration kept (the filter's v ← u after v ← v + r,
r ← r + a). The lives with one renewal are enumerated by its lap K (each a fourth number, the value u it starts
from), each with prior ρ(1 − ρ)^(n − 1) over the n laps filtered, against (1 − ρ)^n for none; lives with two or more
are left out (prior mass about (nρ)²/2: 0.2 % for 30 laps at the filter's ρ = 0.002), so this is the posterior
given at most one renewal.

Two causes at once (grip and battery, read through their plane: :mod:`tuner.prognostics.plane`): a life is each
part's (v₀, r₀[, a]), each part straight or speeding up on its own (four combinations, prior 1/4 each), every lap's
features read at both values, each lap outcome at the plane's edge; no renewal, no measurements (as the joint
filter takes them).

The posterior of each shape's life (and renewal lap) is sampled by population Monte Carlo: prior draws, then
rounds of draws from a Student-t fitted to the weighted draws of the round before, each weighed
prior × likelihood / proposal (two causes: the first rounds' weights of the likelihood tempered, since the prior's
draws hardly find lives of 4 to 6 numbers that every lap pins); the last round gives the shape's evidence (the
mean weight) and its posterior. The shares of the shapes (and of the renewal laps) are their evidence times their
prior. The remaining life is then carried forward by the program's own Monte Carlo
(:func:`tuner.prognostics.remaining_life`) from the exact posterior's lives, so a difference is the filter's.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from typing import Sequence

import numpy as np
from scipy.special import logsumexp
from scipy.stats import multivariate_t

from tuner.prognostics import (FailureModel, FilterSettings, LapObservation, Measurement, ObservationModel, Outcome,
                               estimate, remaining_life)
from tuner.prognostics.monte_carlo import HORIZON, RemainingLife
from tuner.prognostics.particle_filter import SCALE_GRID, SCALE_PRIOR, SHIFT_GRID, DegradationState

ROUNDS = 3  # proposal refits: the effective sample size settles by the second on the tests' lives


@dataclasses.dataclass(frozen=True)
class ExactPosterior:
    """``speeding_up``: the posterior probability that the wear speeds up; ``life``: the remaining life from the
    exact posterior; ``effective``: each shape's effective number of draws in the last round (straight, speeding
    up; with renewals, of the shape's most probable renewal lap), how far to trust the rest; ``renewal``: the
    posterior probability of each renewal lap ({lap: p}, none: the rest; empty without renewals); ``value``: the
    value's 5 %, 50 % and 95 % quantiles at the lap the posterior is of."""
    speeding_up: float
    life: RemainingLife
    effective: tuple[float, float]
    renewal: dict[int, float] = dataclasses.field(default_factory=dict)
    value: tuple[float, ...] = (math.nan, math.nan, math.nan)  # (two causes: the first's, then the second's)
    shapes: dict[tuple[bool, ...], float] = dataclasses.field(default_factory=dict)  # each cause speeding up?

    @property
    def renewed(self) -> float:
        """The posterior probability that the part was renewed (at most once) in the laps filtered."""
        return float(sum(self.renewal.values()))


def _columns(curved: tuple[bool, ...]) -> list[tuple[int, int, int | None]]:
    """The columns of each cause's (v₀, r₀, a) in a life θ: causes one after another, a straight part without its a
    (a renewed value u, one cause only, after them all)."""
    out, c = [], 0
    for cv in curved:
        out.append((c, c + 1, c + 2 if cv else None))
        c += 2 + cv
    return out


def _at(theta: np.ndarray, curved: tuple[bool, ...], k: int, renewed: int | None = None
        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(value, rate, acceleration), each (n, causes), of each life ``k`` laps after its first; ``renewed``: the lap
    (after the first) its part was renewed at, to u (θ's last column), rate and acceleration kept."""
    vs, rs, accs = [], [], []
    for iv, ir, ia in _columns(curved):
        a = theta[:, ia] if ia is not None else np.zeros(len(theta))
        if renewed is None or k < renewed:
            v = theta[:, iv] + k * theta[:, ir] + a * k * (k - 1) / 2
        else:  # v_K = u; then v ← v + r with r_K = r₀ + K·a onwards
            j = renewed
            v = theta[:, -1] + (k - j) * theta[:, ir] + a * (k * (k - 1) - j * (j - 1)) / 2
        vs.append(v)
        rs.append(theta[:, ir] + k * a)
        accs.append(a)
    return np.stack(vs, axis=1), np.stack(rs, axis=1), np.stack(accs, axis=1)


def _shifts(failure, settings: FilterSettings) -> np.ndarray:
    """The filter's grid of edge shifts (± 4 prior sd)."""
    return math.hypot(failure.width, settings.edge_prior) * np.linspace(-4.0, 4.0, SHIFT_GRID)


def _log_likelihood(theta: np.ndarray, curved: tuple[bool, ...], evidence: tuple, start: int,
                    settings: FilterSettings, failure, renewed: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(log likelihood of each life (n,), the log posterior of each life's shift on the grid (n, SHIFT_GRID))."""
    measurements, outcomes, observations, model = evidence
    one = len(curved) == 1

    def at(lap: int) -> tuple[np.ndarray, np.ndarray]:
        return _at(theta, curved, lap - start, renewed)[:2]

    scales = np.exp(np.linspace(math.log(SCALE_PRIOR[0]), math.log(SCALE_PRIOR[1]), SCALE_GRID))
    by_scale = np.zeros((len(theta), SCALE_GRID))
    for m in measurements:  # (one cause: an alignment of two causes is not evidence of both)
        v, r = (x[:, 0] for x in at(m.lap))
        z2 = ((m.value - (v - r * (m.lap - m.first_lap) / 2)) / m.sigma) ** 2
        by_scale += -0.5 * z2[:, None] / scales ** 2 - np.log(scales * m.sigma)
    for o in observations:
        v = at(o.lap)[0]
        d2, logdet = model.distance(o.features, v[:, 0] if one else v)
        by_scale += -0.5 * d2[:, None] / scales ** 2 - len(model.names) * np.log(scales) - 0.5 * logdet[:, None]
    log_scale = logsumexp(by_scale, axis=1) - math.log(SCALE_GRID)
    grid = np.linspace(-4.0, 4.0, SHIFT_GRID)
    shifts = _shifts(failure, settings)
    by_shift = np.tile(-0.5 * grid ** 2 - logsumexp(-0.5 * grid ** 2), (len(theta), 1))
    for o in outcomes:
        v = at(o.lap)[0]
        p = settings.surprise + (1 - 2 * settings.surprise) * failure.p_fail(
            v[:, 0][:, None] if one else v[:, None, :], shifts[None, :])
        by_shift += np.log(p if o.failed else 1 - p)
    log_shift = logsumexp(by_shift, axis=1)
    return log_scale + log_shift, by_shift - log_shift[:, None]


def _half_normal(x: np.ndarray, sd: float) -> np.ndarray:
    return math.log(2 / (sd * math.sqrt(2 * math.pi))) - 0.5 * (x / sd) ** 2


def _log_prior(theta: np.ndarray, curved: tuple[bool, ...], settings: FilterSettings,
               renewed: bool = False) -> np.ndarray:
    """The prior's log density (−inf outside its support): per cause a uniform value, half-normal rate and
    acceleration (in the wear's direction); a renewed value uniform too."""
    lo, hi, signs, spans = _ranges(settings)
    inside, out = np.ones(len(theta), dtype=bool), np.zeros(len(theta))
    for j, (iv, ir, ia) in enumerate(_columns(curved)):
        inside &= (theta[:, iv] >= lo[j]) & (theta[:, iv] <= hi[j]) & (signs[j] * theta[:, ir] >= 0)
        out = out - math.log(hi[j] - lo[j]) + _half_normal(theta[:, ir], settings.rate_prior * spans[j])
        if ia is not None:
            inside &= signs[j] * theta[:, ia] >= 0
            out = out + _half_normal(theta[:, ia], settings.accel_prior * spans[j])
    if renewed:
        inside &= (theta[:, -1] >= lo[0]) & (theta[:, -1] <= hi[0])
        out = out - math.log(hi[0] - lo[0])
    return np.where(inside, out, -np.inf)


def _ranges(settings: FilterSettings) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(lo, hi, signs, spans), one each per cause."""
    d = len(settings.spans)
    lo, hi = np.array(settings.value_range, float).reshape(d, 2).T
    return lo, hi, settings.signs, settings.spans


def _sample_shape(curved: tuple[bool, ...], draws: int, rng: np.random.Generator, evidence: tuple, start: int,
                  settings, failure, renewed: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(lives (draws, dim), their log weights, their shifts' log posteriors, log evidence) for one shape (and
    renewal lap, laps after the first)."""
    lo, hi, signs, spans = _ranges(settings)
    columns = []
    for j, cv in enumerate(curved):
        columns += [rng.uniform(lo[j], hi[j], draws),
                    signs[j] * np.abs(rng.standard_normal(draws)) * settings.rate_prior * spans[j]]
        if cv:
            columns.append(signs[j] * np.abs(rng.standard_normal(draws)) * settings.accel_prior * spans[j])
    if renewed is not None:
        columns.append(rng.uniform(lo[0], hi[0], draws))
    theta = np.stack(columns, axis=1)
    dim = theta.shape[1]
    log_proposal = _log_prior(theta, curved, settings, renewed is not None)
    # two causes' lives (4 to 6 numbers, pinned by every lap's two features) lie in a corner of the prior that its
    # draws hardly find: their first proposals are fitted to the likelihood tempered (the last rounds untempered)
    powers = (0.001, 0.01, 0.05, 0.2, 0.5) * (len(curved) > 1) + (1.0,) * ROUNDS
    for round_ in range(len(powers) + 1):
        prior = _log_prior(theta, curved, settings, renewed is not None)
        ok = np.isfinite(prior)
        lik, shift_post = np.full(draws, -np.inf), np.zeros((draws, SHIFT_GRID))
        lik[ok], shift_post[ok] = _log_likelihood(theta[ok], curved, evidence, start, settings, failure, renewed)
        logw = np.where(ok, prior + lik - log_proposal, -np.inf)
        if round_ == len(powers):
            break
        if powers[round_] < 1:
            logw = np.where(ok, prior + powers[round_] * lik - log_proposal, -np.inf)
        w = np.exp(logw - logw.max())
        w /= w.sum()
        mean = w @ theta
        cov = (theta - mean).T @ ((theta - mean) * w[:, None]) * 1.5 + 1e-12 * np.eye(dim)
        proposal = multivariate_t(mean, cov, df=5, seed=rng)
        theta = proposal.rvs(draws).reshape(draws, dim)
        log_proposal = proposal.logpdf(theta).reshape(draws)
    return theta, logw, shift_post, float(logsumexp(logw) - math.log(draws))


def exact_posterior(measurements: Sequence[Measurement], outcomes: Sequence[Outcome], now: int,
                    settings: FilterSettings, failure, draws: int = 20_000, seed: int = 0,
                    horizon: int = 1000, futures: int = 16_000, observations: Sequence[LapObservation] = (),
                    model=None, renewal_draws: int = 4000) -> ExactPosterior:
    """The posterior after lap ``now`` of the filter's model for this evidence (measurements, outcomes and lap
    ``observations`` read through ``model``, up to ``now``; ``settings`` with a value range, one_way ≠ 0, no walk)
    and the remaining life from it. With ``settings.renewal`` > 0 (one cause), ``renewal_draws`` draws for each
    renewal lap and shape (a lap the evidence does not favour needs few: its share is tiny however well it is
    sampled). Two causes at once: ``failure`` and ``model`` over their plane (:mod:`tuner.prognostics.plane`),
    ``settings`` with a span, range and sign per cause, no renewal, no measurements; every combination of the
    parts' shapes a hypothesis of its own (prior 1/4 each)."""
    d = len(settings.spans)
    if not (settings.value_range and np.all(settings.signs != 0) and settings.rate_walk == 0):
        raise ValueError("the exact posterior is of parts that only wear, in a range, without walk")
    if d > 1 and (settings.renewal > 0 or measurements):
        raise ValueError("two causes at once: lap observations and outcomes only, no renewal")
    rng = np.random.default_rng(seed)
    ms = [m for m in measurements if m.lap <= now]
    obs = [o for o in observations if o.lap <= now] if model is not None else []
    start = min([m.first_lap for m in ms] + [o.lap for o in obs])
    evidence = (ms, [o for o in outcomes if start <= o.lap <= now], [o for o in obs if o.lap >= start], model)
    n, rho = now - start, settings.renewal
    # (shapes, renewal lap after the first or None, log prior): at most one renewal, at any of the n laps filtered
    laps = [None] + (list(range(1, n + 1)) if rho > 0 else [])
    hypotheses = [(curved, k, d * math.log(0.5) + (n * math.log1p(-rho) if k is None else
                                                   math.log(rho) + (n - 1) * math.log1p(-rho)))
                  for curved in itertools.product((False, True), repeat=d) for k in laps]
    samples = [_sample_shape(curved, draws if k is None else renewal_draws, rng, evidence, start, settings, failure, k)
               for curved, k, _ in hypotheses]
    log_post = np.array([h[2] + s[3] for h, s in zip(hypotheses, samples)])
    share = np.exp(log_post - logsumexp(log_post))
    shapes: dict[tuple[bool, ...], float] = {}
    renewal = {}
    for p, (curved, k, _) in zip(share, hypotheses):
        shapes[curved] = shapes.get(curved, 0.0) + float(p)
        if k is not None:
            renewal[start + k] = renewal.get(start + k, 0.0) + float(p)
    speeding_up = float(sum(p for curved, p in shapes.items() if any(curved)))
    # equally weighted lives for the prediction: each hypothesis its share of them, by its own weights
    counts = [int(round(futures * p)) for p in share]
    lives = {"v": [], "r": [], "a": [], "shift": []}
    grid = _shifts(failure, settings)
    step = grid[1] - grid[0]
    effective: dict[bool, tuple[float, float]] = {}  # straight / speeding up: (share, draws) of its likeliest
    for (curved, k, _), (theta, logw, shift_post, _), p, count in zip(hypotheses, samples, share, counts):
        w = np.exp(logw - logw.max())
        w /= w.sum()
        if p > effective.get(any(curved), (-1.0, 0.0))[0]:
            effective[any(curved)] = (p, float(1 / np.sum(w ** 2)))
        idx = rng.choice(len(w), size=count, p=w)
        for name, x in zip(("v", "r", "a"), _at(theta[idx], curved, n, k)):
            lives[name].append(x)
        cb = np.cumsum(np.exp(shift_post[idx]), axis=1)  # each life's shift by its own posterior on the grid
        pick = np.minimum((cb < rng.random(count)[:, None] * cb[:, -1:]).sum(axis=1), SHIFT_GRID - 1)
        lives["shift"].append(grid[pick] + step * (rng.random(count) - 0.5))
    v, r, a, shift = (np.concatenate(lives[x]) for x in ("v", "r", "a", "shift"))
    value = tuple(float(x) for j in range(d) for x in np.quantile(v[:, j], (0.05, 0.5, 0.95)))
    if d == 1:  # one cause: the filter's state holds (particles,) arrays
        v, r, a = v[:, 0], r[:, 0], a[:, 0]
    state = DegradationState(now, v, r, np.ones(len(v)), shift, [], a,
                             settings.one_way if d == 1 else settings.signs.copy())
    life = remaining_life(state, failure, 0.0, seed=seed, horizon=horizon)
    return ExactPosterior(speeding_up, life, (effective[False][1], effective[True][1]), renewal, value, shapes)


def filter_on_seeds(measurements: Sequence[Measurement], outcomes: Sequence[Outcome], now: int,
                    settings: FilterSettings, failure, observations: Sequence[LapObservation] = (), model=None,
                    horizon: int = HORIZON, seeds: int = 3) -> list[tuple[DegradationState, RemainingLife]]:
    """The filter on the evidence up to lap ``now``, on filter seeds 0 … ``seeds`` − 1: [(its state, the remaining
    life from it, no walk)], to hold against the exact posterior."""
    runs = []
    for seed in range(seeds):
        state = estimate([m for m in measurements if m.lap <= now], [o for o in outcomes if o.lap <= now], now,
                         settings, failure, seed=seed, observations=[o for o in observations if o.lap <= now],
                         model=model)
        runs.append((state, remaining_life(state, failure, 0.0, seed=seed, horizon=horizon)))
    return runs


def assert_life_near(exact: ExactPosterior, lives: Sequence[RemainingLife], now: int) -> None:
    """The filter's 10 %, 50 % and 90 % remaining-life quantiles, the seeds' mean, within 10 % and a lap of the
    exact posterior's."""
    quantiles = [[life.quantile(q) for q in (0.1, 0.5, 0.9)] for life in lives]
    for q, filtered in zip((0.1, 0.5, 0.9), np.mean(quantiles, axis=0)):
        assert abs(filtered - exact.life.quantile(q)) <= 0.1 * exact.life.quantile(q) + 1, (now, q, quantiles)
