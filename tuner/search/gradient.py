"""Gradient descent (paper Eq. 12), x_{n+1} = x_n − γ_n ∇F(x_n), in the unit box of the search space.

Two procedures share the stopping rule and the step-size rule, and differ in how laps are spent:

* :func:`descend` (batched): the 2n laps of a central-difference gradient run at once in one batch, then a
  line search tries several step lengths at once in a second batch.
* :func:`sequential` (the paper's §3.7): one lap with the current parameters, then the parameters varied
  one by one, one lap at a time (forward differences): exactly 1 + n laps per iteration.

Step-size rule: the step is α·∇F/‖∇F‖∞ (γ_n = α/‖∇F‖∞), so α is the largest change of any normalised
parameter. The batched search tries α·{2, 1, ½, ¼} and keeps the best, and α becomes the length that won; the
sequential one halves α when a step made the lap slower and goes back. Steps are projected onto the box.
Convergence: an accepted step shorter than ``xtol`` that gains less than ``ftol``, or α below ``min_step``.

The objective is any callable taking points (m, n) of the unit box and returning (m,) costs, so both
procedures are tested on analytic functions as well as laps.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Callable

import numpy as np

Objective = Callable[[np.ndarray], np.ndarray]


@dataclasses.dataclass(frozen=True)
class DescentOptions:
    """Lengths are in the unit box (fractions of each parameter's range); ftol in the objective's unit."""

    fd_step: float = 0.02
    step: float = 0.08
    min_step: float = 0.005
    max_step: float = 0.5
    xtol: float = 0.01
    ftol: float = 0.01
    max_iter: int = 30
    line_search: tuple[float, ...] = (2.0, 1.0, 0.5, 0.25)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            values = v if isinstance(v, tuple) else (v,)
            if not values or not all(isinstance(u, (int, float)) and math.isfinite(u) and u > 0 for u in values):
                raise ValueError(f"descent option {f.name}: must be finite and > 0, got {v!r}")
        if not 0 < self.fd_step < 0.5:
            raise ValueError(f"descent option fd_step: must be below 0.5 of the range, got {self.fd_step!r}")


@dataclasses.dataclass(frozen=True)
class Iteration:
    """One iteration: where it stands after it, and what it cost."""

    k: int
    z: np.ndarray  # accepted point (unit box)
    cost: float  # F there
    gradient: np.ndarray  # ∇F in the unit box, at the point the step was taken from
    step: float  # α after the iteration
    moved: float  # ‖Δz‖∞ of the accepted step (0 if rejected)
    laps: int  # objective evaluations so far
    wall_s: float  # since the start


@dataclasses.dataclass(frozen=True)
class DescentResult:
    z: np.ndarray
    cost: float
    initial_cost: float
    iterations: tuple[Iteration, ...]
    evaluations: int
    converged: bool
    reason: str


def _stop_reason(moved: float, gain: float, accepted: bool, alpha: float, o: DescentOptions) -> str | None:
    if accepted and moved < o.xtol and gain < o.ftol:
        return f"converged: step {moved:.3g} < {o.xtol:g} and gain {gain:.3g} < {o.ftol:g}"
    if alpha < o.min_step:
        return f"converged: no better point within a step of {alpha:.3g}"
    return None


def line_costs(f: Objective, candidates: np.ndarray, bound: float) -> np.ndarray:
    """The line search's costs: only the cheapest candidate, and whether it costs less than ``bound``, decide the
    step, so an objective that can stop the others early (``f.below``) is asked only that; any other is asked
    every cost."""
    below = getattr(f, "below", None)
    return below(candidates, bound) if below is not None else f(candidates)


def central_difference(f: Objective, z: np.ndarray, h: float, with_centre: bool = False):
    """∇F at z by central differences, one-sided where the box ends; all 2n (+1) points in one call.

    Returns (gradient, F(z) or None, number of evaluations).
    """
    n = len(z)
    plus, minus = np.minimum(z + h, 1.0), np.maximum(z - h, 0.0)
    points = [z.copy()] if with_centre else []
    for i in range(n):
        for v in (plus[i], minus[i]):
            p = z.copy()
            p[i] = v
            points.append(p)
    around = getattr(f, "around", None)  # an objective that can spare laps on a stencil (LapObjective.around)
    costs = around(z, np.array(points)) if around is not None else f(np.array(points))
    centre = costs[0] if with_centre else None
    c = costs[1:] if with_centre else costs
    g = (c[0::2] - c[1::2]) / (plus - minus)
    return g, centre, len(points)


def descend(f: Objective, z0: np.ndarray, o: DescentOptions = DescentOptions(),
            on_iteration: Callable[[Iteration], None] | None = None) -> DescentResult:
    """Batched gradient descent from z0; see the module docstring."""
    t0 = time.perf_counter()
    z = np.clip(np.asarray(z0, dtype=float), 0.0, 1.0)
    alpha, evals, history = o.step, 0, []
    fz = None
    reason = f"iteration cap ({o.max_iter})"
    initial = math.nan
    for k in range(o.max_iter):
        g, centre, m = central_difference(f, z, o.fd_step, with_centre=fz is None)
        evals += m
        if fz is None:
            fz = initial = float(centre)
        norm = float(np.max(np.abs(g)))
        if norm == 0.0:  # flat: no direction to go
            history.append(Iteration(k, z.copy(), fz, g, alpha, 0.0, evals, time.perf_counter() - t0))
            reason = "converged: the objective is flat around this point"
            break
        d = -g / norm
        lengths = [alpha * s for s in o.line_search]
        candidates = np.array([np.clip(z + a * d, 0.0, 1.0) for a in lengths])
        costs = line_costs(f, candidates, fz)
        evals += len(candidates)
        j = int(np.argmin(costs))
        accepted = bool(costs[j] < fz)
        moved = gain = 0.0
        if accepted:
            moved = float(np.max(np.abs(candidates[j] - z)))
            gain = fz - float(costs[j])
            z, fz = candidates[j], float(costs[j])
            alpha = min(o.max_step, lengths[j])
        else:
            alpha = alpha * min(o.line_search) / 2
        it = Iteration(k, z.copy(), fz, g, alpha, moved, evals, time.perf_counter() - t0)
        history.append(it)
        if on_iteration is not None:
            on_iteration(it)
        stop = _stop_reason(moved, gain, accepted, alpha, o)
        if stop:
            reason = stop
            break
    return DescentResult(z, fz, initial, tuple(history), evals, reason.startswith("converged"), reason)


def sequential(f: Objective, z0: np.ndarray, o: DescentOptions = DescentOptions(),
               on_iteration: Callable[[Iteration], None] | None = None) -> DescentResult:
    """The paper's procedure, one lap at a time: exactly 1 + n evaluations per iteration."""
    t0 = time.perf_counter()
    z = np.clip(np.asarray(z0, dtype=float), 0.0, 1.0)
    n = len(z)
    alpha, evals, history = o.step, 0, []
    best_z, best_f, best_g = None, math.inf, None
    initial = math.nan
    reason = f"iteration cap ({o.max_iter})"
    for k in range(o.max_iter):
        f0 = float(f(z[None])[0])
        evals += 1
        if k == 0:
            initial = f0
        g = np.zeros(n)
        for i in range(n):  # one parameter varied per lap, forward difference (backward at the upper bound)
            h = o.fd_step if z[i] + o.fd_step <= 1.0 else -o.fd_step
            p = z.copy()
            p[i] += h
            g[i] = (float(f(p[None])[0]) - f0) / h
            evals += 1
        accepted = f0 < best_f
        moved = gain = 0.0
        if accepted:
            if best_z is not None:
                moved, gain = float(np.max(np.abs(z - best_z))), best_f - f0
            else:
                moved, gain = math.inf, math.inf
            best_z, best_f, best_g = z.copy(), f0, g
        else:
            alpha /= 2  # the last step made it worse: go back, shorter
        it = Iteration(k, best_z.copy(), best_f, best_g, alpha, moved if accepted else 0.0, evals, time.perf_counter() - t0)
        history.append(it)
        if on_iteration is not None:
            on_iteration(it)
        stop = _stop_reason(moved, gain, accepted, alpha, o)
        norm = float(np.max(np.abs(best_g)))
        if stop or norm == 0.0:
            reason = stop or "converged: the objective is flat around this point"
            break
        z = np.clip(best_z - alpha * best_g / norm, 0.0, 1.0)
    return DescentResult(best_z, best_f, initial, tuple(history), evals, reason.startswith("converged"), reason)
