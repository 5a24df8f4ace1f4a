"""The degradation state of one parameter, estimated lap by lap by a particle filter (sequential importance
resampling), from every measurement, every finished lap's features and every lap outcome
(:mod:`tuner.prognostics.evidence`).

A particle is (v, r, a, s, δ): the parameter's value at the current lap, its rate of change per lap, the rate's own
change per lap (wear that accelerates or slows: a straight line is a = 0; for a part that only wears, half the
particles hold a = 0 and half wear ever faster, a ≥ 0 in the wear's direction, so the evidence weighs a straight
line against a curve), how far the evidence's stated scatter is to be trusted (a scale s on it, log-uniform over
``SCALE_PRIOR`` a priori, learnt from the evidence's own scatter), and where this robot's failure edge lies against
the twin's (δ ~ N(0, width² + edge_prior²) a priori: the twin's edge is the prior, the robot's own finished and
failed laps move it). s and δ never change from lap to lap: drawn once per particle, resampling for the value
collapsed them onto a few values, a different few for each seed, and the forecast moved with the seed (the same
evidence gave a robot 13 or 39 laps to live). So each particle carries each of them as a distribution on a grid
(Rao-Blackwellised), s updated by each measurement and lap's features at the particle's value, δ by each lap
outcome, and weighs the evidence averaged over its own distribution. From one lap to the next v ← v + r,
r ← r + a + N(0, q²) (q small: what a quadratic does not describe; a part that only wears, grip or charge, never
recovers: its rate keeps its sign), and with a small probability per lap (``RENEWAL``) the part is renewed: v is
drawn again from the prior range, its rate kept (a tyre swapped, a battery charged: it wears on as before; renewals
are proposed more often, near the value the lap's own evidence gives, and weighed back to that probability, so a
renewal is followed by many particles, not a lucky few).
A measurement of laps a..b weighs a particle by the normal density of the measured value around the particle's mean
over those laps (v − r·(b − a)/2), with standard error s·σ; a finished lap's features by the observation model's
density at v, covariance s²·Σ; a lap outcome by the failure model's probability (with a small chance ``SURPRISE`` of
a failure, or a finish, that the parameter does not explain, so that one odd lap cannot overrule everything else).
When the effective number of particles falls below half, they are resampled (systematic) and moved by a multivariate
Liu-West kernel (v, r, a shrunk towards their mean and jittered with their own covariance, so their spread and how
they move together are kept), so they do not collapse to a few values.

The priors scale with ``span``: the distance the forecast cares about (from the value now to where the gains fail).

Everything random comes from one ``numpy.random.Generator`` seeded by the caller: the same evidence and seed give
bit-identical particles.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np

from tuner.prognostics.evidence import FailureModel, LapObservation, Measurement, ObservationModel, Outcome

PARTICLES = 16000  # 4000 until 2026-11-28: a robot's median life moved by a fifth of itself with the seed
SURPRISE = 0.02  # chance of a lap outcome the parameter does not explain
RATE_PRIOR = 0.05  # the prior rate's standard deviation, per lap, as a fraction of the span
ACCEL_PRIOR = 2e-3  # the prior acceleration's standard deviation, per lap², as a fraction of the span
RATE_WALK = 1e-4  # q: the rate's random change per lap (standard deviation), as a fraction of the span
RENEWAL = 2e-3  # chance per lap that the part is renewed (its value drawn again from the prior range) …
RENEWAL_PROPOSED = 0.03  # … proposed this often, near where the lap's evidence puts it, and weighed back
SCALE_PRIOR = (1.0, 3.0)  # the noise scale s, log-uniform between these: a robot scatters no less than the twin
SHIFT_GRID = 33  # the robot's edge against the twin's: ± 4 prior sd in this many steps
SCALE_GRID = 17  # the noise scale s: log-uniform over SCALE_PRIOR in this many steps
LIU_WEST = 0.98  # the kernel's shrinkage towards the mean at a resampling (√(1 − 0.98²) ≈ 0.2 of the spread)


@dataclasses.dataclass(frozen=True)
class FilterSettings:
    """span: the distance that matters in the parameter's unit (from its value to where the gains fail), which
    scales the priors; value_range: where the value may lie a priori (and where a renewed part starts), None: the
    first measurement ± 3 of its errors."""
    span: float
    particles: int = PARTICLES
    rate_prior: float = RATE_PRIOR
    accel_prior: float = ACCEL_PRIOR
    rate_walk: float = RATE_WALK
    renewal: float = RENEWAL
    surprise: float = SURPRISE
    value_range: tuple[float, float] | None = None
    one_way: float = 0.0  # a part that only wears (grip, charge): the sign its rate keeps (−1, +1); 0: either way
    edge_prior: float = 0.0  # how far the robot's failure edge may lie from the twin's a priori (sd, the unit),
    # beside the twin's own edge width: what the twin does not model (another cause wearing too) moves it

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
    accel: np.ndarray | None = None  # (particles,) per lap²; None: 0
    one_way: float = 0.0  # the sign the rate keeps (FilterSettings.one_way)

    def quantiles(self, q=(0.05, 0.5, 0.95)) -> tuple[float, ...]:
        return tuple(float(x) for x in np.quantile(self.value, q))

    def rate_quantiles(self, q=(0.05, 0.5, 0.95)) -> tuple[float, ...]:
        return tuple(float(x) for x in np.quantile(self.rate, q))

    @property
    def acceleration(self) -> np.ndarray:
        return np.zeros_like(self.rate) if self.accel is None else self.accel


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


def one_way(r: np.ndarray, sign: float) -> np.ndarray:
    """The rate of a part that only wears: never against its ``sign`` (0: either way); its wear may stop."""
    return r if not sign else np.where(sign * r < 0, 0.0, r)


def _liu_west(x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Shrink the particles ``x`` (n, k) towards their mean and jitter them with their own covariance, keeping the
    mean, the spread and how the columns move together (Liu and West 2001, multivariate)."""
    if len(x) < 2:
        return x
    m = x.mean(axis=0)
    cov = np.atleast_2d(np.cov(x, rowvar=False))
    cov += np.eye(len(m)) * (1e-12 + 1e-9 * float(np.trace(cov)))
    jitter = rng.standard_normal(x.shape) @ np.linalg.cholesky(cov).T
    return LIU_WEST * x + (1 - LIU_WEST) * m + math.sqrt(1 - LIU_WEST ** 2) * jitter


def _near(ms, obs, lap: int, model: ObservationModel | None, prior: tuple[float, float]) -> tuple[float, float] | None:
    """Where lap ``lap``'s own evidence puts the value, and how widely to look around it: the value that best
    explains its features (or its measurement), ± 4 of its errors at the largest noise scale; None if it has none
    (or says too little to narrow the prior)."""
    lo, hi = prior
    here = [o for o in obs if o.lap == lap]
    centre = sd = None
    if here and model is not None:
        centre = model.nearest(here[0].features, (lo, hi))[0]
        sd = 4 * SCALE_PRIOR[1] * model.pins(centre)
    else:
        firsts = [m for m in ms if m.lap == lap]
        if firsts:
            centre, sd = firsts[0].value, 4 * SCALE_PRIOR[1] * firsts[0].sigma
    if centre is None or not math.isfinite(sd) or sd <= 0 or sd > (hi - lo) / 4:
        return None
    return centre, sd


def _draw(n: int, prior: tuple[float, float], near: tuple[float, float] | None,
          rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``n`` values from the uniform ``prior``, drawn ``near`` what a lap's evidence says when it says something,
    with their log weights prior/proposal (0 when drawn from the prior itself): the evidence, far sharper than
    the prior, then does not leave a handful of particles to carry the rest."""
    lo, hi = prior
    if near is None:
        return rng.uniform(lo, hi, n), np.zeros(n)
    centre, sd = near
    v = centre + sd * rng.standard_normal(n)
    inside = (v >= lo) & (v <= hi)
    if not inside.any():
        return rng.uniform(lo, hi, n), np.zeros(n)
    # prior/proposal: 1/(hi − lo) over sd·√(2π)·exp(−z²/2), so the same scale whichever way a particle was drawn
    logw = np.where(inside, 0.5 * ((v - centre) / sd) ** 2 + math.log(sd * math.sqrt(2 * math.pi) / (hi - lo)),
                    -np.inf)
    return v, logw


def _on_grid(logw: np.ndarray, log_p: np.ndarray, lik: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A piece of evidence whose log likelihood at each point of a particle's grid (its noise scale, its edge) is
    ``lik`` (n, grid): each particle weighed by it averaged over its belief ``log_p`` on the grid, and that belief
    updated."""
    belief = log_p - log_p.max(axis=1, keepdims=True)
    both = belief + lik
    top = both.max(axis=1, keepdims=True)
    logw = logw + (top[:, 0] + np.log(np.exp(both - top).sum(axis=1))) - np.log(np.exp(belief).sum(axis=1))
    return logw, both - top


def _pick(log_b: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """For each row of log beliefs over a grid, a grid index drawn from it."""
    cb = np.cumsum(np.exp(log_b - log_b.max(axis=1, keepdims=True)), axis=1)
    return np.minimum((cb < rng.random(len(log_b))[:, None] * cb[:, -1:]).sum(axis=1), log_b.shape[1] - 1)


def estimate(measurements: Sequence[Measurement], outcomes: Sequence[Outcome], until_lap: int,
             settings: FilterSettings, failure: FailureModel | None = None, seed: int = 0,
             observations: Sequence[LapObservation] = (), model: ObservationModel | None = None) -> DegradationState:
    """Filter from the first lap with evidence to ``until_lap``; ``outcomes`` count only with a ``failure`` model
    and ``observations`` only with their ``model`` (laps before the first measurement or observation are not
    used). Needs a measurement or an observation."""
    obs = sorted(observations, key=lambda o: (o.lap, o.features)) if model is not None else []
    if not measurements and not obs:
        raise ValueError("no measurement or lap observation to start from")
    rng = np.random.default_rng(seed)
    n, q, span = settings.particles, settings.q, settings.span
    ms = sorted(measurements, key=lambda m: (m.lap, m.first_lap, m.value, m.sigma))
    start = min([m.first_lap for m in ms] + [o.lap for o in obs])
    if settings.value_range is not None:
        lo, hi = settings.value_range
    else:
        first = ms[0]
        wide = max(3 * SCALE_PRIOR[1] * first.sigma, 0.1 * span)
        lo, hi = first.value - wide, first.value + wide
    v, logw = _draw(n, (lo, hi), _near(ms, obs, start, model, (lo, hi)), rng)
    logw = logw - logw[np.isfinite(logw)].max()
    r = rng.standard_normal(n) * settings.rate_prior * span
    if settings.one_way:
        r = settings.one_way * np.abs(r)
    a = rng.standard_normal(n) * settings.accel_prior * span
    curved = np.ones(n, dtype=bool)
    if settings.one_way:  # half the particles wear in a straight line, half speed up (a worn part wears faster)
        curved = rng.random(n) < 0.5
        a = np.where(curved, settings.one_way * np.abs(a), 0.0)
    # the noise scale, per particle as a distribution on a grid too (Rao-Blackwellised): drawn once per particle,
    # resampling collapsed it onto a few values, a different few for each seed, and the forecast with it (issue 35)
    scales = np.exp(np.linspace(math.log(SCALE_PRIOR[0]), math.log(SCALE_PRIOR[1]), SCALE_GRID))
    log_p = np.zeros((n, SCALE_GRID))
    shift_sd = math.hypot(failure.width, settings.edge_prior) if failure is not None else 0.0
    # the robot's edge against the twin's, per particle as a distribution on a grid (Rao-Blackwellised): only lap
    # outcomes inform it, and drawn once per particle it would wander with every resampling meant for the value
    edges = shift_sd * np.linspace(-4.0, 4.0, SHIFT_GRID)
    log_q = np.tile(-0.5 * np.linspace(-4.0, 4.0, SHIFT_GRID) ** 2, (n, 1))
    by_lap: dict[int, list] = {}
    for m in ms:
        by_lap.setdefault(m.lap, []).append(m)
    seen: dict[int, list[LapObservation]] = {}
    for o in obs:
        if start <= o.lap <= until_lap:
            seen.setdefault(o.lap, []).append(o)
    outs: dict[int, list[Outcome]] = {}
    if failure is not None:
        for o in sorted(outcomes, key=lambda o: (o.lap, o.failed)):
            if start <= o.lap <= until_lap:
                outs.setdefault(o.lap, []).append(o)
    band = []
    last = max([until_lap] + [m.lap for m in ms])
    for lap in range(start, last + 1):
        if lap > start:
            v = v + r
            r = one_way(r + a + q * rng.standard_normal(n), settings.one_way)
            if settings.renewal > 0:  # renewals proposed RENEWAL_PROPOSED of the time, weighed back to the model's
                renewed = rng.random(n) < RENEWAL_PROPOSED
                fresh, fresh_logw = _draw(n, (lo, hi), _near(ms, obs, lap, model, (lo, hi)), rng)
                v = np.where(renewed, fresh, v)
                logw = logw + np.where(renewed, fresh_logw + math.log(settings.renewal / RENEWAL_PROPOSED),
                                       math.log((1 - settings.renewal) / (1 - RENEWAL_PROPOSED)))
        for m in by_lap.get(lap, ()):
            z2 = ((m.value - (v - r * (m.lap - m.first_lap) / 2)) / m.sigma) ** 2
            logw, log_p = _on_grid(logw, log_p, -0.5 * z2[:, None] / scales ** 2 - np.log(scales * m.sigma))
        for o in seen.get(lap, ()):
            d2, logdet = model.distance(o.features, v)
            logw, log_p = _on_grid(logw, log_p, -0.5 * d2[:, None] / scales ** 2 - len(model.names) *
                                    np.log(scales) - 0.5 * logdet[:, None])
        for o in outs.get(lap, ()):
            p = settings.surprise + (1 - 2 * settings.surprise) * failure.p_fail(v[:, None], edges[None, :])
            logw, log_q = _on_grid(logw, log_q, np.log(p if o.failed else 1 - p))
        w = np.exp(logw - logw.max())
        w /= w.sum()
        band.append((lap, *weighted_quantiles(v, w, (0.05, 0.5, 0.95))))
        if 1.0 / np.sum(w ** 2) < n / 2:
            idx = systematic_resample(w, rng)
            v, r, a, curved, log_q, log_p = v[idx], r[idx], a[idx], curved[idx], log_q[idx], log_p[idx]
            for group, cols in ((curved, (v, r, a)), (~curved, (v, r))):
                if group.sum() > len(cols):
                    moved = _liu_west(np.stack([c[group] for c in cols], axis=1), rng)
                    for j, c in enumerate(cols):
                        c[group] = moved[:, j]
            r = one_way(r, settings.one_way)
            if settings.one_way:
                a = settings.one_way * np.abs(a)
            logw = np.zeros(n)
    w = np.exp(logw - logw.max())
    w /= w.sum()
    idx = systematic_resample(w, rng)  # equally weighted particles for the prediction
    v, r, a, log_q, log_p = v[idx], r[idx], a[idx], log_q[idx], log_p[idx]
    # each particle's edge and noise scale drawn from its own distribution (the edge within a grid step)
    step = edges[1] - edges[0] if SHIFT_GRID > 1 else 0.0
    shift = edges[_pick(log_q, rng)] + step * (rng.random(n) - 0.5)
    return DegradationState(band[-1][0], v, r, scales[_pick(log_p, rng)], shift, band, a, settings.one_way)
