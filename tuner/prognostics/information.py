"""How well any forecast could do from a part's laps: the Cramér–Rao bound on its remaining life.

A part wears along a polynomial in laps (the particle filter's family: value, rate and acceleration, degree 2) and
each lap reads its value to a standard error (the twin's observation model: :meth:`ObservationModel.pins`). No
unbiased estimate of the lap at which the polynomial crosses the failure edge, from those laps, has a smaller
standard deviation than √(∇Tᵀ F⁻¹ ∇T), F the laps' Fisher information on the coefficients and ∇T the crossing's
sensitivity to them (implicit: ∂T/∂θₖ = −Tᵏ/p′(T)). ``bench_forecast`` states it beside α-λ: how often a forecast
could be within ±α of the truth at all, before asking how often this one is.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np


def crossing(coefficients: np.ndarray, threshold: float, after: float) -> float:
    """The first lap after ``after`` at which the polynomial (``coefficients`` in increasing powers of the lap)
    reaches ``threshold``; inf if it never does."""
    shifted = np.array(coefficients, float)
    shifted[0] -= threshold
    p = np.polynomial.Polynomial(shifted)
    if p(after) == 0:
        return float(after)
    roots = [float(r.real) for r in p.roots() if abs(r.imag) < 1e-9 and r.real > after]
    return min(roots, default=math.inf)


def remaining_life_bound(values: Sequence[float], sd_per_lap: Sequence[float], threshold: float, now: int,
                         degree: int = 2) -> tuple[float, float]:
    """(the laps after ``now`` until the part crosses ``threshold``, the Cramér–Rao bound on their standard
    deviation) for a part whose value at laps 0, 1, …, len(values) − 1 is ``values`` (the polynomial of ``degree``
    fitted to them by weighted least squares: exactly the path when it is one), each lap read to ``sd_per_lap``
    (the same unit; inf: a lap that says nothing), the polynomial's coefficients unknown. (inf, inf) if it never
    crosses."""
    t = np.arange(len(values), dtype=float)
    sd = np.asarray(sd_per_lap, float)
    if sd.shape != t.shape or np.any(sd <= 0) or np.isfinite(sd).sum() <= degree:
        raise ValueError("a bound needs more laps that say something (a finite standard error) than coefficients")
    g = np.vander(t, degree + 1, increasing=True)
    w = 1.0 / sd ** 2
    information = g.T @ (w[:, None] * g)
    theta = np.linalg.solve(information, g.T @ (w * np.asarray(values, float)))
    lap = crossing(theta, threshold, float(now))
    if not math.isfinite(lap):
        return math.inf, math.inf
    slope = float(np.polynomial.Polynomial(theta).deriv()(lap))
    grad = -lap ** np.arange(degree + 1) / slope
    return lap - now, float(math.sqrt(grad @ np.linalg.solve(information, grad)))


def within_alpha(remaining: float, sd: float, alpha: float) -> float:
    """The probability that an unbiased normal estimate with standard deviation ``sd`` lies within ±``alpha`` of
    ``remaining`` (an upper bound on how often a forecast meets α-λ, at the scatter the bound was given)."""
    if not math.isfinite(sd):
        return 0.0
    if sd <= 0:
        return 1.0
    return math.erf(alpha * remaining / (sd * math.sqrt(2.0)))
