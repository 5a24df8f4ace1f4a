"""Alignment to a recorded run: fit parameters so the twin's lap reproduces the robot's telemetry traces.

Residuals, all from the telemetry (:mod:`twin.telemetry.jsonl`): left and right encoder wheel speeds (per 10 rad/s)
compared at the same *odometric distance* (∫ R(ω_l + ω_r)/2 dt, from the encoders on both sides), so a run that
is a little ahead or behind is not a mismatch everywhere after it; and the lap time (per 20 ms) when the run
has a lap event. Each parameter is searched as a ratio to its current value.

1. **Coarse grid** (one batch of ``GRID``ⁿ laps, plus the twin's own values and, when the run has a lap time, each
   parameter's lap-time alignment with the others as they are): where friction does not limit the robot, a
   trace does not change with μ at all, so a local method started there never moves; the best of these picks
   the basin.
2. **Levenberg–Marquardt** from the best ``STARTS`` distinct starting points (the lowest misfit wins):
   ``mujoco.minimize.least_squares``, chosen because it
   takes a *vectorised* residual, so each finite-difference Jacobian is one batch of n laps on all cores
   (scipy's would run them one by one), and it keeps box bounds. Finite-difference step: 1 % (sensor
   readings are integers, so much smaller steps see steps, not slopes).
3. **Noise** (one batch): the misfit at the solution with ``NOISE_SEEDS`` other twin noise seeds; its largest
   change is how much noise alone moves the misfit. At the grip limit a lap is chaotic, so the noise moves its
   traces as much as a parameter does. The fit is also repeated with ``REFITS`` other seeds (one stacked
   least-squares problem, so each Jacobian is one batch), warm-started at the solution; the estimate is the
   mean of the 1 + ``REFITS`` fits and their spread is how far noise alone moves it. Only where step 4's scan
   leaves some parameter that could be identified: otherwise the estimate is the fit itself.
4. **What the run says about each parameter** (:mod:`tuner.align.uncertainty`): a profile scan over the search
   range gives the *consistent set*, every value that fits as well as the best fit given that noise; a
   parameter is identified only where that set is narrow and inside the range, and only then gets a 95 %
   interval (the hull of the set and the local interval from the refits and the Jacobian). Otherwise the
   result says so and gives the set ("fits as well anywhere in [a, b]"). Where the scan finds a point that fits
   far better than the fit's solution (the fit stopped in the wrong basin), steps 2–4 run again from it
   (``RESTARTS`` times at most); a parameter none of whose scanned values fits as well gets its whole range.
5. **Wrong basin**: a fit whose traces differ from the run's by more than ``NOISE_FACTOR`` times what two twin
   runs differ by is not the run, and nothing in it is called identified.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from typing import Sequence

import numpy as np
from mujoco import minimize

from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapResult
from twin.model.identifiability import unresolved
from twin.model.space import ChangeCost
from twin.telemetry.jsonl import Telemetry
from tuner.align.lap_time import PHYSICAL_RANGE, align_lap_time
from tuner.align.uncertainty import MORE_SEEDS, SCAN_SEEDS, FittedParameter, fitted_parameters, profile_scan
from tuner.search.space import TunerError

GRID = 5  # grid points per parameter (7 for one or two parameters: GRID_SMALL)
GRID_SMALL = 7
STARTS = 3  # Levenberg–Marquardt runs, from the best distinct starting points
RESTARTS = 1  # fits again from a better point the profile scan found (the first fit stopped in the wrong basin)
# the residual is noisy at the scale of sensor readings and seeds: a step below 0.01 % is noise, and a damping
# that adapts by ×4 (not 10^0.1) stops it from spending a lap on every tiny rejected step
LM_OPTIONS = {"xtol": 1e-4, "gtol": 1e-6, "mu_factor": 4.0}
TRACE_RANGE = 1.5  # default search range of parameters without one of their own: ÷1.5 to ×1.5
FD_STEP = 0.01
WHEEL_SCALE = 10.0  # [rad/s] per unit residual
LAP_SCALE = 0.02  # [s] per unit residual
FAIL_PENALTY_S = 5.0
MAX_WHEEL_ERROR = 0.2  # a fit whose wheel speeds are further off than this fraction of their size is not the run
MAX_LAP_ERROR = 0.01  # nor one whose lap time is further off than this
NOISE_FACTOR = 3.0  # nor one further off than this many times two twin runs differ by noise alone
MIN_NOISE_RMS = 0.2  # [rad/s] below this, noise is as small as encoder resolution makes no difference
NOISE_SEEDS = 6  # other twin seeds at the solution: how much noise alone moves the misfit
REFITS = 3  # the fit repeated with this many other twin seeds: how much noise alone moves the estimate


@dataclasses.dataclass(frozen=True)
class TraceAlignment:
    parameters: tuple[FittedParameter, ...]
    rms_wheel_radps: float  # remaining wheel-speed mismatch
    simulated_lap_time_s: float | None
    measured_lap_time_s: float | None
    iterations: int
    laps: int
    correlation: list[list[float]]
    best_lap: LapResult | None = None  # the twin's lap at the fitted values, with its trace


def odometry(t: np.ndarray, wl: np.ndarray, wr: np.ndarray, radius: float) -> np.ndarray:
    """Distance the encoders say the robot has driven [m], trapezoid rule; made strictly increasing so it can
    index a trace (a robot at rest or reversing holds its distance)."""
    v = radius * (wl + wr) / 2
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    return np.maximum.accumulate(s) + 1e-9 * np.arange(len(s))


def wheel_residuals(lap: LapResult, tel: Telemetry, radius: float, s_tel: np.ndarray | None = None) -> np.ndarray:
    """The twin's left then right wheel speeds minus the run's, compared at equal odometric distance [rad/s]. A lap
    that ended before its first tick (e.g. a failed calibration) counts as standing still."""
    tr = lap.trace
    if tr is None or len(tr.time_s) < 2:
        return -np.concatenate([tel.wl, tel.wr])
    s_tel = odometry(tel.t, tel.wl, tel.wr, radius) if s_tel is None else s_tel
    wl, wr = tr.column("wheel_left_radps"), tr.column("wheel_right_radps")
    s_sim = odometry(tr.time_s, wl, wr, radius)
    return np.concatenate([np.interp(s_tel, s_sim, wl) - tel.wl, np.interp(s_tel, s_sim, wr) - tel.wr])


class _Residual:
    def __init__(self, twin, tel: Telemetry, addresses, nominal, seed, nthread):
        self.twin, self.tel, self.addresses, self.nominal = twin, tel, addresses, nominal
        self.seed, self.nthread, self.laps = seed, nthread, 0
        self.known: dict[tuple[tuple[float, ...], int], np.ndarray] = {}  # (ratios, seed): that lap's residuals
        self.lap_time = tel.lap_time_s
        self.weight = 1.0 / math.sqrt(len(tel.t))
        self.radius = twin.info.wheel_radius
        self.s_tel = odometry(tel.t, tel.wl, tel.wr, self.radius)
        self.range = [(twin.space.parameter(a).lower, twin.space.parameter(a).upper) for a in addresses]

    def laps_for(self, X: np.ndarray, seeds: Sequence[int] | None = None):
        # a ratio on the search bound times the nominal value can round a hair outside the model space's range
        vs = [{a: float(np.clip(v * n, *r)) for a, v, n, r in zip(self.addresses, col, self.nominal, self.range)}
              for col in X.T]
        self.laps += len(vs)
        return run_laps(self.twin, vs, seed=list(seeds) if seeds is not None else self.seed, nthread=self.nthread)

    def __call__(self, X: np.ndarray, seeds: Sequence[int] | None = None) -> np.ndarray:
        """Residuals (m, k) for k points, given as the columns of X (n, k): ratios to the nominal values; one noise
        seed for all, or one per point. A point asked again on the same seed is answered from ``known``, not raced
        again: a lap is a deterministic function of the twin, its values and its seed, whatever batch it is raced
        in (closed_loop.run_laps), so the fit is bit for bit the one that races every point (the fit asks again for
        its solution, for the refits' start on the noise seeds and for the scan's point at it: 6–15 % of its laps)."""
        X = X.reshape(len(self.addresses), -1)
        per_point = list(seeds) if seeds is not None else [self.seed] * X.shape[1]
        keys = [(tuple(float(v) for v in col), int(s)) for col, s in zip(X.T, per_point)]
        new = list(dict.fromkeys(k for k in keys if k not in self.known))  # in order, each once
        if new:
            laps = self.laps_for(np.array([k[0] for k in new]).T, [k[1] for k in new])
            self.known.update(zip(new, self.residuals_of(laps).T))
        return np.array([self.known[k] for k in keys]).T

    def residuals_of(self, laps: Sequence[LapResult]) -> np.ndarray:
        """(m, k): each lap's residual column."""
        out = []
        for r in laps:
            res = wheel_residuals(r, self.tel, self.radius, self.s_tel) / WHEEL_SCALE * self.weight
            if self.lap_time is not None:
                lt = r.lap_time_s if r.completed else r.simulated_s + FAIL_PENALTY_S
                res = np.append(res, (lt - self.lap_time) / LAP_SCALE)
            out.append(res)
        return np.array(out).T


def align_telemetry(twin: DigitalTwin, tel: Telemetry, addresses: Sequence[str],
                    bounds: dict[str, tuple[float, float]] | None = None, seed: int = 0, max_iter: int = 30,
                    nthread: int = 0, start: dict[str, float] | None = None) -> TraceAlignment:
    """Fit ``addresses`` to a recorded run (see the module docstring). ``start``: values worth trying besides the
    grid (e.g. what another fit found); the twin's own values and the lap-time alignments are always tried."""
    addresses = list(addresses)
    if not addresses or len(set(addresses)) != len(addresses):
        raise TunerError(f"trace alignment: give each parameter once, got {', '.join(addresses) or 'none'}")
    nominal, lo, hi = [], [], []
    for a in addresses:
        p = twin.space.parameter(a)
        if p.cost is ChangeCost.REBUILD or p.integer:
            raise TunerError(f"{a}: alignment searches parameters that can differ between the laps of one batch")
        if why := unresolved(twin.space.values, a):
            raise TunerError(why)
        v = twin.space.get(a)
        if v <= 0:
            raise TunerError(f"{a}: trace alignment searches positive parameters (ratios to the current value)")
        b = (bounds or {}).get(a) or ((p.lower, p.upper) if a in PHYSICAL_RANGE else
                                      (max(p.lower, v / TRACE_RANGE), min(p.upper, v * TRACE_RANGE)))
        if not (math.isfinite(b[0]) and math.isfinite(b[1]) and 0 < b[0] < b[1]):
            raise TunerError(f"{a}: bounds [{b[0]:g}, {b[1]:g}] are inverted, empty or not positive")
        p.check(f"{a} lower bound", b[0])
        p.check(f"{a} upper bound", b[1])
        nominal.append(v)
        lo.append(b[0] / v)
        hi.append(b[1] / v)
    nominal, lo, hi = np.array(nominal), np.array(lo), np.array(hi)
    twin.model()  # the wheel radius for odometry comes from the built robot
    f = _Residual(twin, tel, addresses, nominal, seed, nthread)

    # 1. coarse grid, the twin's own values and any start values: one batch
    axes = [np.geomspace(l, h, GRID_SMALL if len(addresses) <= 2 else GRID) for l, h in zip(lo, hi)]
    extra = [np.clip(np.ones(len(addresses)), lo, hi)]
    if start:
        extra.append(np.clip([start.get(a, v) / v for a, v in zip(addresses, nominal)], lo, hi))
    if tel.lap_time_s is not None:  # each parameter alone explaining the lap time: a start near a real basin
        for i, a in enumerate(addresses):
            # one noise seed: these are starts for the fit of the whole run, which weighs the noise itself
            # (uncertainty.py). With the lap-time alignment's 3 (its median) the fit of R_M and K on the oval started
            # elsewhere on their ridge (rho -1) and stopped at R_M 9.47 for 10 (rms 0.28 rad/s, against 0.20 from here)
            r = align_lap_time(twin, tel.lap_time_s, a, bounds=(lo[i] * nominal[i], hi[i] * nominal[i]), seed=seed,
                               nthread=nthread, noise_seeds=1, interval=False)  # a start, not an answer
            f.laps += r.laps
            for sol in r.solutions:
                p = np.ones(len(addresses))
                p[i] = sol.value / nominal[i]
                extra.append(np.clip(p, lo, hi))
    points = np.column_stack([np.array(list(itertools.product(*axes))).T, *extra])
    r = f(points)
    # 2. Levenberg–Marquardt, Jacobians as batches, from the best STARTS distinct starting points (the misfit is
    # rugged near the grip limit: a local method finds the basin it starts in); the lowest misfit wins
    order = np.argsort(np.sum(r * r, axis=0))
    starts: list[np.ndarray] = []
    for j in order:
        if all(np.max(np.abs(np.log(points[:, j] / s0))) > 0.05 for s0 in starts):
            starts.append(points[:, j])
        if len(starts) == STARTS:
            break
    for _ in range(1 + RESTARTS):
        runs = [minimize.least_squares(s0, f, bounds=[lo, hi], eps=FD_STEP, max_iter=max_iter, verbose=0, **LM_OPTIONS)
                for s0 in starts]
        finals = f(np.column_stack([x for x, _ in runs]))
        x, log = runs[int(np.argmin(np.sum(finals * finals, axis=0)))]
        # the Jacobian at the solution: one batch
        steps = np.where(x + FD_STEP * x <= hi, FD_STEP * x, -FD_STEP * x)
        R = f(np.column_stack([x, x[:, None] + np.diag(steps)]))
        r0 = R[:, 0]
        J = (R[:, 1:] - r0[:, None]) / steps
        sse = float(r0 @ r0)
        # 3. other noise seeds at the solution (one batch): how much noise alone moves the misfit
        noise_seeds = [seed + 1 + j for j in range(NOISE_SEEDS)]
        Rn = f(np.tile(x[:, None], NOISE_SEEDS), seeds=noise_seeds)
        noise_sse = np.sum(Rn * Rn, axis=0)
        noise_spread = float(np.max(np.abs(noise_sse - sse)))
        # 4. each parameter's consistent set (profile scan over SCAN_SEEDS twin seeds, and its edges) and verdicts,
        # see tuner.align.uncertainty
        scan = profile_scan(lambda X, seeds: np.sum(f(X, seeds=seeds) ** 2, axis=0), x, lo, hi, J,
                            np.concatenate([[sse], noise_sse]), noise_spread,
                            [seed + j for j in range(SCAN_SEEDS)],
                            [seed + j for j in range(SCAN_SEEDS, SCAN_SEEDS + MORE_SEEDS)])
        if scan.solution_fits:
            break
        # the scan found a point fitting far better than the fit's solution: the fit stopped in the wrong basin, so
        # it starts again from there (and from its solution)
        starts = [scan.best_point, x]
    profiles, floor = scan.profiles, scan.floor
    # the refits only matter for an interval: skipped when the scan leaves nothing that could be identified
    pinned = any(p.pinned(x[i], floor) for i, p in enumerate(profiles))
    estimates = np.vstack([x, _refits(f, x, lo, hi, seed, max_iter)]) if pinned else x[None, :]  # (1 + REFITS, n)
    fitted, corr = fitted_parameters(addresses, nominal, x, J, r0, estimates, noise_spread, profiles, floor)
    best = f.laps_for(x[:, None])[0]
    k = 2 * len(tel.t)
    rms = float(np.sqrt(np.mean((r0[:k] / f.weight * WHEEL_SCALE) ** 2)))
    # how far two laps of the twin at the solution differ when only the noise seed does
    twin_rms = float(np.median(np.sqrt(np.mean(((Rn[:k] - r0[:k, None]) / f.weight * WHEEL_SCALE) ** 2, axis=0))))
    misfit = _does_not_reproduce(best, tel, rms, twin_rms)
    if misfit:  # 5. a wrong basin: nothing it found is identified, whatever the local curvature says
        fitted = [dataclasses.replace(p, identifiable=False, ci95=None, note=(
            f"{misfit}: not identified (the fit itself fails); near it, fits as well anywhere in "
            f"[{p.consistent[0]:.4g}, {p.consistent[1]:.4g}]")) for p in fitted]
    return TraceAlignment(tuple(fitted), rms, best.lap_time_s if best.completed else None, tel.lap_time_s, len(log),
                          f.laps, corr, best)


def _refits(f: _Residual, x: np.ndarray, lo: np.ndarray, hi: np.ndarray, seed: int, max_iter: int) -> np.ndarray:
    """The fit again with REFITS other twin noise seeds, started at ``x``: one stacked least-squares problem whose
    blocks are independent, so each Jacobian is one batch of REFITS × n + 1 laps. Returns (REFITS, n) estimates."""
    n = len(x)
    seeds = [seed + 1 + j for j in range(REFITS)]

    def stacked(X: np.ndarray) -> np.ndarray:
        X = X.reshape(REFITS * n, -1)
        k = X.shape[1]
        cols = np.column_stack([X[j * n:(j + 1) * n, c] for c in range(k) for j in range(REFITS)])
        R = f(cols, seeds=[s for _ in range(k) for s in seeds])  # (m, k × REFITS), problem j of point c at c·REFITS + j
        return np.vstack([R[:, j::REFITS] for j in range(REFITS)])

    xs, _ = minimize.least_squares(np.tile(x, REFITS), stacked, bounds=[np.tile(lo, REFITS), np.tile(hi, REFITS)],
                                   eps=FD_STEP, max_iter=max_iter, verbose=0, **LM_OPTIONS)
    return xs.reshape(REFITS, n)


def _does_not_reproduce(lap: LapResult, tel: Telemetry, rms: float, twin_rms: float) -> str | None:
    """Why the fitted lap is not the run (None when it is): wheel speeds off by more than MAX_WHEEL_ERROR of their
    typical size, or by more than NOISE_FACTOR times what the noise seed alone changes in the twin (then the twin at
    these values does not behave like the robot: a wrong basin where the traces happen to be smooth), or a lap time
    off by more than MAX_LAP_ERROR."""
    typical = float(np.mean(np.abs(np.concatenate([tel.wl, tel.wr])))) or 1.0
    if rms > MAX_WHEEL_ERROR * typical:
        return f"the fitted lap's wheel speeds are {rms:.1f} rad/s rms off the run's (typical speed {typical:.1f} rad/s)"
    if rms > NOISE_FACTOR * max(twin_rms, MIN_NOISE_RMS):
        return (f"the run differs from the fitted twin by {rms:.2f} rad/s rms, while two runs of the twin there differ by "
                f"{twin_rms:.2f}")
    if tel.lap_time_s is not None:
        if not lap.completed:
            return f"the fitted lap does not complete ({lap.failure}) where the robot's did"
        if abs(lap.lap_time_s - tel.lap_time_s) > MAX_LAP_ERROR * tel.lap_time_s:
            return f"the fitted lap takes {lap.lap_time_s:.3f} s against the run's {tel.lap_time_s:.3f} s"
    return None
