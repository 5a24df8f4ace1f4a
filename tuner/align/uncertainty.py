"""What a trace alignment (:mod:`tuner.align.trace`) can say about each parameter: the set of values that fit the
run as well as the best fit does, and a 95 % interval only where the run pins the value.

Values are searched as ratios to the parameter's current value; everything reported is in its own unit.

1. **What "fits as well" means.** The misfit (sum of squared scaled residuals) of a value is the least over
   ``SCAN_SEEDS`` twin noise seeds (the alignment's own first): at the grip limit a lap is chaotic and can be
   bimodal (most seeds slip once in a corner and lose 0.1 s, a few do not), and the robot's one run may be a
   lucky one; with one seed such a value would be excluded although it explains the run. Where a value's seeds
   disagree (they moved its misfit by at least 1/``PIN_MARGIN`` of its distance to the floor) and none fits as
   well, ``MORE_SEEDS`` more are tried, so a mode the first seeds hint at is missed only with probability
   (1 − q)¹² (q: its share of laps). A value fits as well as the best fit when that misfit is below
   ``best + PIN_MARGIN · max(noise_spread, PROFILE_TOLERANCE · best)``, ``best`` the least misfit seen anywhere
   and ``noise_spread`` how much the misfit at the solution changes when only the twin's noise seed does
   (``NOISE_SEEDS`` of them, :func:`tuner.align.trace.align_telemetry`). Not a χ² quantile: where the lap is
   chaotic, moving a parameter a little reshuffles the trace like a new seed, so the misfit is rugged on the
   scale of ``noise_spread``, not of the residuals' variance; where the traces are smooth, the floor is wider
   than a likelihood-ratio bound (a seed changes a sum of m squares by ~√m of them, a parameter fit by ~1), so
   the set errs towards too wide.
2. **Consistent set** (:func:`profile_scan`): for each parameter, ``SCAN_POINTS`` values log-spaced over its
   search range, ±``PIN`` around the solution and ``EDGE_GUESSES`` times the edge the Jacobian predicts, all in
   one batch, each at two settings of the others: at the solution, and moved along their linearised
   conditional optimum (−(J_oᵀJ_o)⁻¹J_oᵀJ_i per unit, clipped to the bounds); the lower misfit counts (each is
   an upper bound on the profile, so the set only grows towards the true profile's). The set is the hull of
   the values below the floor (gaps included: a far value that fits as well is evidence, not an outlier). Each
   open end is then bisected ``EDGE_ROUNDS`` times (one batch per round for all ends) and reported as the outer
   end of its last bracket, so the grid never understates it.
3. **Identified** only if the consistent set reaches neither bound and stays inside ±``PIN`` of the solution,
   the Jacobian sees the parameter, the solution is among the best fits, and the interval below lies within
   ±``IDENTIFIABLE_REL`` of the value. Otherwise no interval is given (``ci95`` None), only the consistent set.
4. **ci95** of an identified parameter: the hull of the consistent set and the local interval
   mean ± t₀.₉₇₅,ₖ₋₁·√((1 + 1/k)σ²_noise + σ²_J) (k fits over twin noise seeds, mean and σ_noise from their
   spread, σ_J from s²(JᵀJ)⁻¹ with s² inflated by (1 + ρ₁)/(1 − ρ₁) for residuals correlated in time). The local
   interval alone was over-confident wherever the misfit is rugged (a curvature fitted to noise, an interval
   that excluded the hidden value); the hull with the consistent set is what keeps coverage. Measured in
   ``tests/test_case2.py`` (runs recorded with random hidden values over 20 robot seeds): 20 of 20 covered.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable, Sequence

import numpy as np

SCAN_POINTS = 11  # profile values per parameter, log-spaced over its search range (one batch)
SCAN_SEEDS = 4  # twin noise seeds per profile value (the alignment's own first): a lucky run is matched ...
MORE_SEEDS = 8  # ... and this many more where those seeds disagree (a bimodal lap: slip or not)
EDGE_GUESSES = (1.0, 2.0)  # extra profile values at these multiples of the Jacobian's predicted edge
EDGE_ROUNDS = 3  # bisections of each open end of a consistent set (one batch each): a grid step ÷ 8
PIN = 0.25  # profile step either side of the solution, as a fraction of the value
PIN_MARGIN = 2.0  # fits as well: the misfit rises by less than this many times what another noise seed alone changes
PROFILE_TOLERANCE = 0.05  # ... or by less than this fraction of the best misfit, however small the noise
IDENTIFIABLE_REL = 0.25  # an interval wider than this fraction of the value either side: not identified
T_975 = {2: 12.71, 3: 4.303, 4: 3.182, 5: 2.776, 6: 2.571, 7: 2.447, 8: 2.365, 9: 2.306, 10: 2.262}  # t(0.975, K − 1)


Misfit = Callable[[np.ndarray, Sequence[int]], np.ndarray]  # (points (n, k) of ratios, a seed each) → k misfits


@dataclasses.dataclass(frozen=True)
class FittedParameter:
    """One fitted parameter, in its model-space unit."""

    address: str
    value: float  # the mean of the fits over the twin's noise seeds
    stderr: float  # local standard error (Jacobian and noise refits); inf where the traces do not change with it
    ci95: tuple[float, float] | None  # only when identified
    identifiable: bool
    note: str
    consistent: tuple[float, float]  # every value that fits as well as the best fit (hull)


@dataclasses.dataclass(frozen=True)
class Profile:
    """One parameter's profile as ratios to its current value: the values tried (sorted), the least misfit found at
    each, the outermost values that fit as well (``inner``) and the reported set (``consistent``: the outer ends
    of the edge brackets, or a bound the set reaches)."""

    values: np.ndarray
    misfits: np.ndarray
    inner: tuple[float, float]
    consistent: tuple[float, float]
    reaches: tuple[bool, bool]  # the lower, the upper bound fits as well

    def at(self, v: float) -> float:
        return float(self.misfits[int(np.argmin(np.abs(self.values - v)))])

    def loose(self, x: float) -> bool:
        """The set reaches ±PIN of the solution ``x`` or beyond."""
        return self.inner[0] <= x * (1 - PIN) * (1 + 1e-12) or self.inner[1] >= x * (1 + PIN) * (1 - 1e-12)

    def pinned(self, x: float, floor: float) -> bool:
        """The solution ``x`` fits as well, and the set reaches neither bound nor ±PIN: an interval may follow."""
        return self.at(x) <= floor and not any(self.reaches) and not self.loose(x)


def noise_floor(best: float, noise_spread: float) -> float:
    """The misfit below which a value fits as well as the best fit ``best``, given how much another noise seed alone
    changes it (both sums of squared scaled residuals, dimensionless)."""
    return best + PIN_MARGIN * max(noise_spread, PROFILE_TOLERANCE * best)


class _Values:
    """Misfits of profile values (parameter i at value v): the least over the twin's noise seeds and two settings
    of the others (at ``x``, and moved along their linearised conditional optimum, clipped to the bounds)."""

    def __init__(self, misfit: Misfit, x, lo, hi, J, seeds: Sequence[int], more_seeds: Sequence[int]):
        self.misfit, self.x, self.lo, self.hi = misfit, x, lo, hi
        self.seeds, self.more_seeds = list(seeds), list(more_seeds)
        self.best_misfit, self.best_point = math.inf, x  # the least misfit any point tried has, and that point
        n = len(x)
        live = _live(J)
        # per unit of parameter i, the others at their least misfit: −(J_oᵀJ_o)⁻¹J_oᵀJ_i, over the parameters the
        # traces respond to (a column at rounding level would send the others to their bounds)
        self.slopes = []
        for i in range(n):
            others = [j for j in range(n) if j != i]
            slope = np.zeros(len(others))
            use = [k for k, j in enumerate(others) if live[j]]
            if live[i] and use:
                slope[use] = np.linalg.lstsq(J[:, [others[k] for k in use]], -J[:, i], rcond=None)[0]
            self.slopes.append(slope)

    def _run(self, pairs, seeds) -> tuple[np.ndarray, np.ndarray]:
        """Least and largest misfit of each pair over ``seeds`` and the settings: one batch."""
        x, cols, owner = self.x, [], []
        for k, (i, v) in enumerate(pairs):
            p = x.copy()
            p[i] = v
            cols.append(p)
            owner.append(k)
            if len(x) > 1:
                q = x.copy()
                others = [j for j in range(len(x)) if j != i]
                q[others] = np.clip(x[others] + self.slopes[i] * (v - x[i]), self.lo[others], self.hi[others])
                q[i] = v
                if np.any(np.abs(q - p) > 1e-9 * np.abs(p)):
                    cols.append(q)
                    owner.append(k)
        least, most = np.full(len(pairs), np.inf), np.full(len(pairs), -np.inf)
        if cols:
            S = self.misfit(np.repeat(np.column_stack(cols), len(seeds), axis=1), [s for _ in cols for s in seeds])
            who = np.repeat(np.array(owner, dtype=int), len(seeds))
            np.minimum.at(least, who, S)
            if float(S.min()) < self.best_misfit:
                self.best_misfit, self.best_point = float(S.min()), cols[int(np.argmin(S)) // len(seeds)]
            np.maximum.at(most, who, S)
        return least, most

    def first(self, pairs) -> tuple[np.ndarray, np.ndarray]:
        return self._run(pairs, self.seeds)

    def settle(self, pairs, least: np.ndarray, most: np.ndarray, floor: float) -> np.ndarray:
        """More seeds where a value does not fit as well yet but its seeds moved its misfit by at least 1/PIN_MARGIN
        of the way to the floor: a bimodal lap (slip or not) whose other mode the first seeds missed. One batch."""
        noisy = [k for k in range(len(pairs))
                 if least[k] > floor and PIN_MARGIN * (most[k] - least[k]) >= least[k] - floor]
        if noisy and self.more_seeds:
            more, _ = self._run([pairs[k] for k in noisy], self.more_seeds)
            least = least.copy()
            least[noisy] = np.minimum(least[noisy], more)
        return least


@dataclasses.dataclass(frozen=True)
class Scan:
    """What :func:`profile_scan` found: each parameter's profile, the floor below which a misfit fits as well as
    the best fit, and the point (ratios) with the least misfit tried, which lies below the floor only when the
    solution it scanned around is not among the best fits (a fit stopped in the wrong basin)."""

    profiles: list[Profile]
    floor: float
    solution_fits: bool  # the solution scanned around fits as well as the best point tried
    best_point: np.ndarray


def profile_scan(misfit: Misfit, x: np.ndarray, lo: np.ndarray, hi: np.ndarray, J: np.ndarray,
                 at_solution: np.ndarray, noise_spread: float, seeds: Sequence[int],
                 more_seeds: Sequence[int]) -> Scan:
    """Each parameter's consistent set (module docstring, 2.). ``misfit(X, seeds)`` maps points (n, k) of ratios and
    one noise seed each to their k misfits; ``at_solution``: the misfits at the solution ``x`` over the twin's
    seeds, its own first; ``seeds`` for every value, ``more_seeds`` where those disagree (:meth:`_Values.settle`).
    A parameter none of whose values tried fits as well (another's scan found a far better point) gets the whole
    search range as its set: nothing is known of it until the fit starts from that point."""
    n = len(x)
    sse = float(at_solution[0])
    values = _Values(misfit, x, lo, hi, J, seeds, more_seeds)
    # where the misfit is smooth, a set is far narrower than a grid step: values around the edge the Jacobian
    # predicts (profile curvature 1/[(JᵀJ)⁺]ᵢᵢ) give the bisection a tight bracket to start from
    live = _live(J)
    variance = np.zeros(n)
    variance[live] = np.diag(np.linalg.pinv(J[:, live].T @ J[:, live]))
    predicted = np.sqrt((noise_floor(sse, noise_spread) - sse) * variance)  # 0 where the traces do not respond
    grids = []
    for i in range(n):
        near = x[i] + np.outer([-1, 1], predicted[i] * np.array(EDGE_GUESSES)).ravel()
        near = near[(np.abs(near - x[i]) < PIN * x[i]) & (near != x[i])]
        grids.append(np.unique(np.clip(np.concatenate([np.geomspace(lo[i], hi[i], SCAN_POINTS), near,
                                                        x[i] * np.array([1 - PIN, 1 + PIN])]), lo[i], hi[i])))
    pairs = [(i, float(v)) for i in range(n) for v in grids[i]]
    least, most = values.first(pairs)
    here = float(np.min(at_solution))
    floor = noise_floor(min(here, float(least.min())), noise_spread)  # fixed from here on: the scan is one test
    least = values.settle(pairs, least, most, floor)
    tried: list[list[tuple[float, float]]] = [[(float(x[i]), here)] for i in range(n)]
    for (i, v), s in zip(pairs, least):
        tried[i].append((v, float(s)))

    def brackets(i: int) -> list[list[float] | None]:
        """[inner, outer] at each end of parameter i's set, None where the set reaches the bound."""
        vs = sorted(tried[i])
        ok = [k for k, (_, s) in enumerate(vs) if s <= floor]
        if not ok:
            return [None, None]
        a, b = ok[0], ok[-1]
        return [None if a == 0 else [vs[a][0], vs[a - 1][0]], None if b == len(vs) - 1 else [vs[b][0], vs[b + 1][0]]]

    ends = [brackets(i) for i in range(n)]
    for _ in range(EDGE_ROUNDS):  # each round: one midpoint per open end, all in one batch (two if noisy)
        todo = [(i, e) for i in range(n) for e in ends[i] if e is not None]
        if not todo:
            break
        mids = [(i, math.sqrt(e[0] * e[1])) for i, e in todo]
        least = values.settle(mids, *values.first(mids), floor)
        for (i, e), (_, m), s in zip(todo, mids, least):
            tried[i].append((m, float(s)))
            e[0 if s <= floor else 1] = m
    profiles = []
    for i in range(n):
        vs = sorted(tried[i])
        good = [v for v, s in vs if s <= floor] or [lo[i], hi[i]]
        lower, upper = ends[i]
        profiles.append(Profile(np.array([v for v, _ in vs]), np.array([s for _, s in vs]), (good[0], good[-1]),
                                (lo[i] if lower is None else lower[1], hi[i] if upper is None else upper[1]),
                                (lower is None, upper is None)))
    return Scan(profiles, floor, here <= floor, np.array(values.best_point, dtype=float))


def _live(J: np.ndarray) -> np.ndarray:
    """The parameters the traces respond to: Jacobian columns above 1e-6 of the largest (bool, n)."""
    scale = np.linalg.norm(J, axis=0)
    return scale > 1e-6 * max(float(scale.max()), 1e-300)


def _covariance(J: np.ndarray, r0: np.ndarray, sse: float) -> np.ndarray:
    """s²(JᵀJ)⁻¹ over the parameters the traces respond to (NaN elsewhere, or where JᵀJ is singular)."""
    m, n = J.shape
    live = list(np.flatnonzero(_live(J)))
    cov = np.full((n, n), np.nan)
    if live:
        JtJ = J[:, live].T @ J[:, live]
        if np.linalg.cond(JtJ) < 1e12:
            # residuals along a trace are correlated in time: m of them carry only about m·(1 − ρ₁)/(1 + ρ₁)
            # independent ones (ρ₁: lag-1 autocorrelation), so s² is inflated by m / that
            rho = float(np.corrcoef(r0[:-1], r0[1:])[0, 1]) if m > 2 and np.std(r0) > 0 else 0.0
            inflation = (1 + max(rho, 0.0)) / max(1 - max(rho, 0.0), 1e-3)
            cov[np.ix_(live, live)] = inflation * sse / max(1, m - n) * np.linalg.inv(JtJ)
    return cov


def fitted_parameters(addresses: Sequence[str], nominal: np.ndarray, x: np.ndarray, J: np.ndarray, r0: np.ndarray,
                      estimates: np.ndarray, noise_spread: float, profiles: Sequence[Profile],
                      floor: float) -> tuple[list[FittedParameter], list[list[float]]]:
    """Each parameter's value, verdict, consistent set and (when identified) 95 % interval, and the local
    correlation matrix. ``estimates``: (k, n) ratios from the fits over k twin noise seeds (k = 1, the fit alone,
    when no profile is :meth:`Profile.pinned`)."""
    n, k = len(x), len(estimates)
    sse = float(r0 @ r0)
    cov = _covariance(J, r0, sse)
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr = (cov / np.outer(sd, sd)).tolist()
    centre = estimates.mean(axis=0)  # the twin's own noise averaged out over its seeds
    noise_sd = estimates.std(axis=0, ddof=1) if k > 1 else np.zeros(n)  # k = 1: nothing pinned, no interval
    t = T_975.get(k, 1.96)
    fitted = []
    for i, a in enumerate(addresses):
        prof, nom = profiles[i], nominal[i]
        value = float(centre[i] * nom)
        cons = (float(prof.consistent[0] * nom), float(prof.consistent[1] * nom))
        span = f"[{cons[0]:.4g}, {cons[1]:.4g}]"
        minus, plus = prof.at(x[i] * (1 - PIN)), prof.at(x[i] * (1 + PIN))
        evidence = (f"misfit ×{minus / sse:.2f} at −{PIN * 100:g} %, ×{plus / sse:.2f} at +{PIN * 100:g} % "
                    f"(another noise seed alone: up to ×{(sse + noise_spread) / sse:.2f})")
        # the robot's run is one more noise realisation than the k the estimates average: (1 + 1/k)
        se = float(np.sqrt((1 + 1 / k) * noise_sd[i] ** 2 + sd[i] ** 2) * nom) if np.isfinite(cov[i, i]) else math.inf
        bounds = [name for name, hit in zip(("lower", "upper"), prof.reaches) if hit]
        ci = None
        if prof.at(x[i]) > floor:
            best_at = prof.values[int(np.argmin(prof.misfits))] * nom
            note = (f"the fit stopped in a local basin: {a} = {best_at:.4g} fits clearly better (misfit "
                    f"×{prof.misfits.min() / sse:.2f}); fits as well anywhere in {span}: not identified ({evidence})")
        elif not math.isfinite(se):
            note = (f"the traces do not change with it near the fit; fits as well anywhere in {span}: "
                    f"not identifiable from this run ({evidence})")
        elif bounds:
            note = (f"fits as well anywhere in {span} (to its {' and '.join(bounds)} bound): not identifiable from "
                    f"this run ({evidence})")
        elif prof.loose(x[i]):
            note = (f"fits as well anywhere in {span}, beyond ±{PIN * 100:g} % of the fit: not identifiable from "
                    f"this run ({evidence})")
        else:
            hull = (min(value - t * se, cons[0]), max(value + t * se, cons[1]))
            wide = max(value - hull[0], hull[1] - value) / abs(value)
            if wide > IDENTIFIABLE_REL:
                note = (f"95 % interval ±{100 * wide:.0f} %: noise moves it too much; fits as well in {span}: "
                        f"not identifiable ({evidence})")
            else:
                ci = hull
                partner = [f"{addresses[j]} (ρ = {corr[i][j]:+.2f})" for j in range(n)
                           if j != i and np.isfinite(corr[i][j]) and abs(corr[i][j]) > 0.9]
                note = (f"identified: fits as well in {span} ({evidence})"
                        + (f"; strongly correlated with {', '.join(partner)}" if partner else ""))
        fitted.append(FittedParameter(a, value, se, ci, ci is not None, note, cons))
    return fitted, corr
