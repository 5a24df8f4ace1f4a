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
3. **Uncertainty**: at the grip limit a lap is chaotic, so the noise moves its traces as much as a parameter
   does. The fit is repeated with ``REFITS`` other twin noise seeds (one stacked least-squares problem, so each
   Jacobian is one batch), warm-started at the solution; the estimate is the mean of the 1 + ``REFITS`` fits and
   its spread is how far noise alone moves it. The robot's run is one more noise realisation, so the 95 %
   interval is mean ± t₀.₉₇₅,ₖ₋₁·√((1 + 1/k)σ²_noise + σ²_J) (k = 1 + REFITS), with σ_J from s²(JᵀJ)⁻¹ and s²
   inflated by (1 + ρ₁)/(1 − ρ₁) for residuals correlated in time (ρ₁: their lag-1 autocorrelation).
4. **Profile** (one batch, with ``NOISE_SEEDS`` other seeds at the solution): each parameter moved ``PIN`` either way and to each bound, the others at the
   solution. It is **pinned** only if the misfit rises, on each side, by more than noise alone moves it (the
   spread of the other seeds' misfits); a parameter that fits about as well up to a bound (μ above the grip
   the robot needs) or within ±``PIN`` is reported as not identifiable, with those numbers as the evidence.
   "Identified" needs both: pinned, and a 95 % interval narrower than ±``IDENTIFIABLE_REL``.
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
from twin.model.space import ChangeCost
from twin.telemetry.jsonl import Telemetry
from tuner.align.lap_time import PHYSICAL_RANGE, align_lap_time
from tuner.search.space import TunerError

GRID = 5  # grid points per parameter (7 for one or two parameters: GRID_SMALL)
GRID_SMALL = 7
STARTS = 3  # Levenberg–Marquardt runs, from the best distinct starting points
# the residual is noisy at the scale of sensor readings and seeds: a step below 0.01 % is noise, and a damping
# that adapts by ×4 (not 10^0.1) stops it from spending a lap on every tiny rejected step
LM_OPTIONS = {"xtol": 1e-4, "gtol": 1e-6, "mu_factor": 4.0}
TRACE_RANGE = 1.5  # default search range of parameters without one of their own: ÷1.5 to ×1.5
FD_STEP = 0.01
WHEEL_SCALE = 10.0  # [rad/s] per unit residual
LAP_SCALE = 0.02  # [s] per unit residual
FAIL_PENALTY_S = 5.0
IDENTIFIABLE_REL = 0.25
PROFILE_TOLERANCE = 0.05  # relative increase of the squared residual: below it, "fits about as well"
MAX_WHEEL_ERROR = 0.2  # a fit whose wheel speeds are further off than this fraction of their size is not the run
MAX_LAP_ERROR = 0.01  # nor one whose lap time is further off than this
NOISE_FACTOR = 3.0  # nor one further off than this many times two twin runs differ by noise alone
MIN_NOISE_RMS = 0.2  # [rad/s] below this, noise is as small as encoder resolution makes no difference
NOISE_SEEDS = 6  # other twin seeds at the solution: how much noise alone moves the misfit
REFITS = 3  # the fit repeated with this many other twin seeds: how much noise alone moves the estimate
PIN = 0.25  # profile step, as a fraction of the value
PIN_MARGIN = 2.0  # pinned: the misfit rises by more than this many times what another noise seed alone changes
T_975 = {2: 12.71, 3: 4.303, 4: 3.182, 5: 2.776, 6: 2.571, 7: 2.447, 8: 2.365, 9: 2.306, 10: 2.262}  # t(0.975, K − 1)


@dataclasses.dataclass(frozen=True)
class FittedParameter:
    address: str
    value: float
    stderr: float
    ci95: tuple[float, float]
    identifiable: bool
    note: str


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
        self.lap_time = tel.lap_time_s
        self.weight = 1.0 / math.sqrt(len(tel.t))
        self.radius = twin.info.wheel_radius
        self.s_tel = odometry(tel.t, tel.wl, tel.wr, self.radius)

    def laps_for(self, X: np.ndarray, seeds: Sequence[int] | None = None):
        vs = [{a: float(v * n) for a, v, n in zip(self.addresses, col, self.nominal)} for col in X.T]
        self.laps += len(vs)
        return run_laps(self.twin, vs, seed=list(seeds) if seeds is not None else self.seed, nthread=self.nthread)

    def __call__(self, X: np.ndarray, seeds: Sequence[int] | None = None) -> np.ndarray:
        """Residuals (m, k) for k points, given as the columns of X (n, k): ratios to the nominal values; one noise
        seed for all, or one per point."""
        X = X.reshape(len(self.addresses), -1)
        out = []
        for r in self.laps_for(X, seeds):
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
            r = align_lap_time(twin, tel.lap_time_s, a, bounds=(lo[i] * nominal[i], hi[i] * nominal[i]), seed=seed,
                               nthread=nthread)
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
    runs = [minimize.least_squares(s0, f, bounds=[lo, hi], eps=FD_STEP, max_iter=max_iter, verbose=0, **LM_OPTIONS) for s0 in starts]
    finals = f(np.column_stack([x for x, _ in runs]))
    x, log = runs[int(np.argmin(np.sum(finals * finals, axis=0)))]
    # 3. the Jacobian at the solution: one batch
    steps = np.where(x + FD_STEP * x <= hi, FD_STEP * x, -FD_STEP * x)
    R = f(np.column_stack([x, x[:, None] + np.diag(steps)]))
    r0 = R[:, 0]
    J = (R[:, 1:] - r0[:, None]) / steps
    m, n = len(r0), len(x)
    sse = float(r0 @ r0)
    # 3.-4. other noise seeds at the solution, and the profile (±PIN, bounds), in one batch
    moved = []
    for i in range(n):
        for b in (lo[i], max(lo[i], x[i] * (1 - PIN)), min(hi[i], x[i] * (1 + PIN)), hi[i]):
            p = x.copy()
            p[i] = b
            moved.append(p)
    noise_seeds = [seed + 1 + j for j in range(NOISE_SEEDS)]
    both = f(np.column_stack([np.tile(x[:, None], NOISE_SEEDS), np.array(moved).T]),
             seeds=noise_seeds + [seed] * len(moved))
    Rn, P = both[:, :NOISE_SEEDS], both[:, NOISE_SEEDS:]
    noise_sse = np.sum(Rn * Rn, axis=0)
    noise_spread = float(np.max(np.abs(noise_sse - sse)))  # how much noise alone moves the misfit
    profile = np.sum(P * P, axis=0).reshape(n, 4)  # lower bound, −PIN, +PIN, upper bound
    estimates = np.vstack([x, _refits(f, x, lo, hi, seed, max_iter)])  # (1 + REFITS, n)
    fitted, corr = _uncertainty(addresses, nominal, x, lo, hi, J, r0, estimates, sse, noise_spread, profile)
    best = f.laps_for(x[:, None])[0]
    k = 2 * len(tel.t)
    rms = float(np.sqrt(np.mean((r0[:k] / f.weight * WHEEL_SCALE) ** 2)))
    # how far two laps of the twin at the solution differ when only the noise seed does
    twin_rms = float(np.median(np.sqrt(np.mean(((Rn[:k] - r0[:k, None]) / f.weight * WHEEL_SCALE) ** 2, axis=0))))
    misfit = _does_not_reproduce(best, tel, rms, twin_rms)
    if misfit:  # a wrong basin: nothing it found is identified, whatever the local curvature says
        fitted = [dataclasses.replace(p, identifiable=False, note=f"{misfit}: not identified (the fit itself fails)")
                  for p in fitted]
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


def _uncertainty(addresses, nominal, x, lo, hi, J, r0, estimates, sse, noise_spread, profile):
    """Intervals from the refits' spread and the Jacobian, and the profile's verdicts."""
    n, m, k = len(x), len(r0), len(estimates)
    scale = np.linalg.norm(J, axis=0)
    live = [i for i in range(n) if scale[i] > 1e-6 * max(scale.max(), 1e-300)]
    cov = np.full((n, n), np.nan)
    if live:
        JtJ = J[:, live].T @ J[:, live]
        if np.linalg.cond(JtJ) < 1e12:
            # residuals along a trace are correlated in time: m of them carry only about m·(1 − ρ₁)/(1 + ρ₁)
            # independent ones (ρ₁: lag-1 autocorrelation), so s² is inflated by m / that
            rho = float(np.corrcoef(r0[:-1], r0[1:])[0, 1]) if m > 2 and np.std(r0) > 0 else 0.0
            inflation = (1 + max(rho, 0.0)) / max(1 - max(rho, 0.0), 1e-3)
            cov[np.ix_(live, live)] = inflation * sse / max(1, m - n) * np.linalg.inv(JtJ)
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr = (cov / np.outer(sd, sd)).tolist()
    centre = estimates.mean(axis=0)  # the twin's own noise averaged out over its seeds
    noise_sd = estimates.std(axis=0, ddof=1)
    t = T_975.get(k, 1.96)
    floor = sse + PIN_MARGIN * max(noise_spread, PROFILE_TOLERANCE * sse)  # clearly more than noise alone
    fitted = []
    for i, a in enumerate(addresses):
        value = float(centre[i] * nominal[i])
        if not np.isfinite(cov[i, i]):
            fitted.append(FittedParameter(a, value, math.inf, (math.nan, math.nan), False,
                                          "the traces do not change with it here: not identifiable from this run"))
            continue
        # the robot's run is one more noise realisation than the k the estimates average: (1 + 1/k)
        se = float(np.sqrt((1 + 1 / k) * noise_sd[i] ** 2 + sd[i] ** 2) * nominal[i])
        ci = (value - t * se, value + t * se)
        partner = [f"{addresses[j]} (ρ = {corr[i][j]:+.2f})" for j in range(n)
                   if j != i and np.isfinite(corr[i][j]) and abs(corr[i][j]) > 0.9]
        flat = [f"{'lower' if j == 0 else 'upper'} bound {b * nominal[i]:.4g}" for j, b in ((0, lo[i]), (3, hi[i]))
                if profile[i][j] < floor]
        sides = [(profile[i][j], name) for j, name, b in ((1, "−", lo[i]), (2, "+", hi[i])) if abs(b - x[i]) > 1e-12]
        loose = [name for p, name in sides if p < floor]
        pinned = not flat and not loose
        narrow = t * se <= IDENTIFIABLE_REL * abs(value)
        evidence = (f"misfit ×{profile[i][1] / sse:.2f} at −{PIN * 100:g} %, ×{profile[i][2] / sse:.2f} at +{PIN * 100:g} %"
                    f" (another noise seed alone: up to ×{(sse + noise_spread) / sse:.2f})")
        if flat:
            note = f"fits about as well at its {' and '.join(flat)}: not identifiable from this run ({evidence})"
        elif loose:
            note = f"fits about as well {PIN * 100:g} % {' and '.join(loose)}: not identifiable from this run ({evidence})"
        elif not narrow:
            note = f"95 % interval ±{100 * t * se / abs(value):.0f} %: noise moves it too much; not identifiable ({evidence})"
        else:
            note = f"identified ({evidence})" + (f"; strongly correlated with {', '.join(partner)}" if partner else "")
        fitted.append(FittedParameter(a, value, se, ci, pinned and narrow, note))
    return fitted, corr
