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

Two causes at once (models over their plane: :mod:`tuner.prognostics.plane`): a particle carries each cause's value,
rate and acceleration (each part straight or speeding up on its own), one noise scale and one edge shift; each
combination of shapes is moved by its own Liu-West kernel. With one cause the arithmetic and the random draws are
those of the one-cause filter, bit for bit.

Everything random comes from one ``numpy.random.Generator`` seeded by the caller: the same evidence and seed give
bit-identical particles.
"""

from __future__ import annotations

import dataclasses
import itertools
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
    first measurement ± 3 of its errors. Two causes at once (a :class:`tuner.prognostics.plane` model): ``span``,
    ``value_range`` and ``one_way`` hold one entry per parameter, in the model's order."""
    span: float | tuple[float, ...]
    particles: int = PARTICLES
    rate_prior: float = RATE_PRIOR
    accel_prior: float = ACCEL_PRIOR
    rate_walk: float = RATE_WALK
    renewal: float = RENEWAL
    surprise: float = SURPRISE
    value_range: tuple | None = None
    one_way: float | tuple[float, ...] = 0.0  # a part that only wears (grip, charge): the sign its rate keeps (−1,
    # +1); 0: either way
    edge_prior: float = 0.0  # how far the robot's failure edge may lie from the twin's a priori (sd, the unit),
    # beside the twin's own edge width: what the twin does not model (another cause wearing too) moves it

    @property
    def spans(self) -> np.ndarray:
        return np.atleast_1d(np.asarray(self.span, float))

    @property
    def signs(self) -> np.ndarray:
        return np.broadcast_to(np.atleast_1d(np.asarray(self.one_way, float)), self.spans.shape)

    @property
    def q(self) -> float | np.ndarray:
        """The rate's random walk per lap [unit per lap per lap]: one per parameter with two causes."""
        return self.rate_walk * self.span if np.ndim(self.span) == 0 else self.rate_walk * self.spans


@dataclasses.dataclass
class DegradationState:
    """The particles at lap ``lap`` (equally weighted), and the estimate lap by lap: for each lap filtered, the
    value's 5 %, 50 % and 95 % quantiles (with two causes, those of each in turn)."""
    lap: int
    value: np.ndarray  # (particles,); with two causes (particles, 2)
    rate: np.ndarray  # the same shape, per lap
    scale: np.ndarray  # (particles,)
    shift: np.ndarray  # (particles,) the robot's failure edge against the twin's [parameter unit]
    band: list[tuple]  # (lap, q05, median, q95[, q05, median, q95 of the second cause])
    accel: np.ndarray | None = None  # the value's shape, per lap²; None: 0
    one_way: float | np.ndarray = 0.0  # the sign the rate keeps (FilterSettings.one_way)

    def quantiles(self, q=(0.05, 0.5, 0.95), dim: int = 0) -> tuple[float, ...]:
        return tuple(float(x) for x in np.quantile(_column(self.value, dim), q))

    def rate_quantiles(self, q=(0.05, 0.5, 0.95), dim: int = 0) -> tuple[float, ...]:
        return tuple(float(x) for x in np.quantile(_column(self.rate, dim), q))

    @property
    def acceleration(self) -> np.ndarray:
        return np.zeros_like(self.rate) if self.accel is None else self.accel

    @property
    def speeding_up(self) -> np.ndarray:
        """(particles,): does any part's wear speed up?"""
        a = self.acceleration
        return a != 0 if a.ndim == 1 else (a != 0).any(axis=1)


def _column(x: np.ndarray, dim: int) -> np.ndarray:
    return x if x.ndim == 1 else x[:, dim]


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


def one_way(r: np.ndarray, sign: float | np.ndarray) -> np.ndarray:
    """The rate of a part that only wears: never against its ``sign`` (0: either way; one per column of ``r`` with
    two causes); its wear may stop."""
    return r if not np.any(sign) else np.where(np.asarray(sign) * r < 0, 0.0, r)


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


def _near(ms, obs, lap: int, model, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Where lap ``lap``'s own evidence puts the value (one per cause), and how widely to look around it: the value
    that best explains its features (or its measurement), ± 4 of its errors at the largest noise scale; None if it
    has none (or says too little to narrow the prior ``lo``..``hi``)."""
    here = [o for o in obs if o.lap == lap]
    centre = sd = None
    if here and model is not None:
        found = model.nearest(here[0].features, (lo[0], hi[0]) if len(lo) == 1 else (lo, hi))[0]
        centre, sd = np.atleast_1d(found), 4 * SCALE_PRIOR[1] * np.atleast_1d(model.pins(found))
    else:
        firsts = [m for m in ms if m.lap == lap]
        if firsts:
            centre, sd = np.array([firsts[0].value]), np.array([4 * SCALE_PRIOR[1] * firsts[0].sigma])
    if centre is None or not np.all(np.isfinite(sd)) or np.any(sd <= 0) or np.any(sd > (hi - lo) / 4):
        return None
    return centre, sd


def _draw(n: int, lo: np.ndarray, hi: np.ndarray, near: tuple[np.ndarray, np.ndarray] | None,
          rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``n`` values (n, causes) from the uniform prior ``lo``..``hi``, drawn ``near`` what a lap's evidence says
    when it says something, with their log weights prior/proposal per cause (0 when drawn from the prior itself):
    the evidence, far sharper than the prior, then does not leave a handful of particles to carry the rest."""
    d = len(lo)
    if near is None:
        return rng.uniform(lo, hi, (n, d)), np.zeros((n, d))
    centre, sd = near
    v = centre + sd * rng.standard_normal((n, d))
    inside = (v >= lo) & (v <= hi)
    if not inside.any(axis=0).all():
        return rng.uniform(lo, hi, (n, d)), np.zeros((n, d))
    # prior/proposal: 1/(hi − lo) over sd·√(2π)·exp(−z²/2), so the same scale whichever way a particle was drawn
    logw = np.where(inside, 0.5 * ((v - centre) / sd) ** 2 + np.log(sd * math.sqrt(2 * math.pi) / (hi - lo)),
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
    used). Needs a measurement or an observation. Two causes at once: ``model`` and ``failure`` over their plane
    (:mod:`tuner.prognostics.plane`), ``settings`` with one span, range and sign per cause, no measurements (an
    alignment of one parameter explains the laps by it alone)."""
    obs = sorted(observations, key=lambda o: (o.lap, o.features)) if model is not None else []
    if not measurements and not obs:
        raise ValueError("no measurement or lap observation to start from")
    rng = np.random.default_rng(seed)
    n, q, spans, signs = settings.particles, settings.q, settings.spans, settings.signs
    d = len(spans)
    if d > 1 and (measurements or settings.value_range is None):
        raise ValueError("two causes at once: laps read through their plane, and a value range for each")
    ms = sorted(measurements, key=lambda m: (m.lap, m.first_lap, m.value, m.sigma))
    start = min([m.first_lap for m in ms] + [o.lap for o in obs])
    if settings.value_range is not None:
        lo, hi = np.array(settings.value_range, float).reshape(d, 2).T
    else:
        first = ms[0]
        wide = max(3 * SCALE_PRIOR[1] * first.sigma, 0.1 * settings.span)
        lo, hi = np.array([first.value - wide]), np.array([first.value + wide])
    v, logw = _draw(n, lo, hi, _near(ms, obs, start, model, lo, hi), rng)
    logw = logw.sum(axis=1)
    logw = logw - logw[np.isfinite(logw)].max()
    r = rng.standard_normal((n, d)) * settings.rate_prior * spans
    r = np.where(signs != 0, signs * np.abs(r), r)
    a = rng.standard_normal((n, d)) * settings.accel_prior * spans
    curved = np.ones((n, d), dtype=bool)
    if signs.any():  # half the particles wear in a straight line, half speed up (a worn part wears faster)
        curved = (rng.random((n, d)) < 0.5) | (signs == 0)
        a = np.where(signs == 0, a, np.where(curved, signs * np.abs(a), 0.0))
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
    # the shapes the particles' (value, rate, acceleration) take: one Liu-West kernel each (straight parts have
    # no acceleration to move)
    shapes = [np.array(p, dtype=bool) for p in itertools.product((True, False), repeat=d)]
    band = []
    last = max([until_lap] + [m.lap for m in ms])
    for lap in range(start, last + 1):
        if lap > start:
            v = v + r
            r = one_way(r + a + q * rng.standard_normal((n, d)), signs)
            if settings.renewal > 0:  # renewals proposed RENEWAL_PROPOSED of the time, weighed back to the model's
                renewed = rng.random((n, d)) < RENEWAL_PROPOSED
                fresh, fresh_logw = _draw(n, lo, hi, _near(ms, obs, lap, model, lo, hi), rng)
                v = np.where(renewed, fresh, v)
                logw = logw + np.where(renewed, fresh_logw + math.log(settings.renewal / RENEWAL_PROPOSED),
                                       math.log((1 - settings.renewal) / (1 - RENEWAL_PROPOSED))).sum(axis=1)
        for m in by_lap.get(lap, ()):
            z2 = ((m.value - (v[:, 0] - r[:, 0] * (m.lap - m.first_lap) / 2)) / m.sigma) ** 2
            logw, log_p = _on_grid(logw, log_p, -0.5 * z2[:, None] / scales ** 2 - np.log(scales * m.sigma))
        for o in seen.get(lap, ()):
            d2, logdet = model.distance(o.features, v[:, 0] if d == 1 else v)
            logw, log_p = _on_grid(logw, log_p, -0.5 * d2[:, None] / scales ** 2 - len(model.names) *
                                    np.log(scales) - 0.5 * logdet[:, None])
        for o in outs.get(lap, ()):
            p = settings.surprise + (1 - 2 * settings.surprise) * failure.p_fail(
                v[:, 0][:, None] if d == 1 else v[:, None, :], edges[None, :])
            logw, log_q = _on_grid(logw, log_q, np.log(p if o.failed else 1 - p))
        w = np.exp(logw - logw.max())
        w /= w.sum()
        band.append((lap, *(x for j in range(d) for x in weighted_quantiles(v[:, j], w, (0.05, 0.5, 0.95)))))
        if 1.0 / np.sum(w ** 2) < n / 2:
            idx = systematic_resample(w, rng)
            v, r, a, curved, log_q, log_p = v[idx], r[idx], a[idx], curved[idx], log_q[idx], log_p[idx]
            for shape in shapes:
                group = (curved == shape).all(axis=1)
                cols = [(x, j) for j in range(d) for x in ((v, r, a) if shape[j] else (v, r))]
                if group.sum() > len(cols):
                    moved = _liu_west(np.stack([x[group, j] for x, j in cols], axis=1), rng)
                    for k, (x, j) in enumerate(cols):
                        x[group, j] = moved[:, k]
            r = one_way(r, signs)
            a = np.where(signs != 0, signs * np.abs(a), a)
            logw = np.zeros(n)
    w = np.exp(logw - logw.max())
    w /= w.sum()
    idx = systematic_resample(w, rng)  # equally weighted particles for the prediction
    v, r, a, log_q, log_p = v[idx], r[idx], a[idx], log_q[idx], log_p[idx]
    # each particle's edge and noise scale drawn from its own distribution (the edge within a grid step)
    step = edges[1] - edges[0] if SHIFT_GRID > 1 else 0.0
    shift = edges[_pick(log_q, rng)] + step * (rng.random(n) - 0.5)
    if d == 1:
        v, r, a = v[:, 0], r[:, 0], a[:, 0]
    return DegradationState(band[-1][0], v, r, scales[_pick(log_p, rng)], shift, band, a,
                            settings.one_way if d == 1 else signs.copy())
