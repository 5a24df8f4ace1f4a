"""Alignment to a recorded run: fit parameters so the twin's lap reproduces the robot's telemetry traces.

Residuals, all from the telemetry (:mod:`twin.telemetry`): left and right encoder wheel speeds (per 10 rad/s)
compared at the same *odometric distance* (∫ R(ω_l + ω_r)/2 dt, from the encoders on both sides), so a run that
is a little ahead or behind is not a mismatch everywhere after it; and the lap time (per 20 ms) when the run
has a lap event. Each parameter is searched as a ratio to its current value.

1. **Coarse grid** (one batch of ``GRID``ⁿ laps): where friction does not limit the robot, a trace does not
   change with μ at all, so a local method started there never moves; the grid picks the basin.
2. **Levenberg–Marquardt** from the best grid point: ``mujoco.minimize.least_squares``, chosen because it
   takes a *vectorised* residual, so each finite-difference Jacobian is one batch of n laps on all cores
   (scipy's would run them one by one), and it keeps box bounds. Finite-difference step: 1 % (sensor
   readings are integers, so much smaller steps see steps, not slopes).
3. **Uncertainty** from the Jacobian at the solution: covariance s²(JᵀJ)⁻¹ with s² the residual variance,
   95 % intervals ±1.96σ. Trace residuals are correlated in time, so these intervals are optimistic.
   A parameter whose interval is wider than ±``IDENTIFIABLE_REL`` of its value is not identifiable.
4. **Profile at the bounds** (one batch of 2n laps): the curvature at the solution cannot see a parameter
   that stops mattering on one side (μ above the grip the robot needs). Each parameter is moved to each
   bound with the others at the solution; if the fit gets less than ``PROFILE_TOLERANCE`` worse there, every
   value up to that bound explains the run about as well, and the parameter is reported as not identifiable.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from typing import Sequence

import numpy as np
from mujoco import minimize

from twin.closed_loop import run_laps
from twin.digital_twin import DigitalTwin
from twin.lap import LapResult
from twin.model_space import ChangeCost
from twin.telemetry import Telemetry
from tuner.align import DEFAULT_RANGES
from tuner.space import TunerError

GRID = 5
TRACE_RANGE = 1.5  # default search range of parameters without one of their own: ÷1.5 to ×1.5
FD_STEP = 0.01
WHEEL_SCALE = 10.0  # [rad/s] per unit residual
LAP_SCALE = 0.02  # [s] per unit residual
FAIL_PENALTY_S = 5.0
IDENTIFIABLE_REL = 0.25
PROFILE_TOLERANCE = 0.05  # relative increase of the squared residual: below it, "fits about as well"


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
    """The twin's left then right wheel speeds minus the run's, compared at equal odometric distance [rad/s]."""
    tr = lap.trace
    if tr is None:
        raise TunerError("trace alignment: the lap has no trace")
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

    def laps_for(self, X: np.ndarray):
        vs = [{a: float(v * n) for a, v, n in zip(self.addresses, col, self.nominal)} for col in X.T]
        self.laps += len(vs)
        return run_laps(self.twin, vs, seed=self.seed, nthread=self.nthread)

    def __call__(self, X: np.ndarray) -> np.ndarray:
        """Residuals (m, k) for k points, given as the columns of X (n, k): ratios to the nominal values."""
        X = X.reshape(len(self.addresses), -1)
        out = []
        for r in self.laps_for(X):
            res = wheel_residuals(r, self.tel, self.radius, self.s_tel) / WHEEL_SCALE * self.weight
            if self.lap_time is not None:
                lt = r.lap_time_s if r.completed else r.simulated_s + FAIL_PENALTY_S
                res = np.append(res, (lt - self.lap_time) / LAP_SCALE)
            out.append(res)
        return np.array(out).T


def align_telemetry(twin: DigitalTwin, tel: Telemetry, addresses: Sequence[str],
                    bounds: dict[str, tuple[float, float]] | None = None, seed: int = 0, max_iter: int = 30,
                    nthread: int = 0) -> TraceAlignment:
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
        b = (bounds or {}).get(a) or DEFAULT_RANGES.get(a) or (max(p.lower, v / TRACE_RANGE), min(p.upper, v * TRACE_RANGE))
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

    # 1. coarse grid, one batch
    axes = [np.geomspace(l, h, GRID) for l, h in zip(lo, hi)]
    points = np.array(list(itertools.product(*axes))).T
    r = f(points)
    x0 = points[:, int(np.argmin(np.sum(r * r, axis=0)))]
    # 2. Levenberg–Marquardt, Jacobians as batches
    x, log = minimize.least_squares(x0, f, bounds=[lo, hi], eps=FD_STEP, max_iter=max_iter, verbose=0)
    # 3. uncertainty at the solution: one batch for the Jacobian
    steps = np.where(x + FD_STEP * x <= hi, FD_STEP * x, -FD_STEP * x)
    R = f(np.column_stack([x, x[:, None] + np.diag(steps)]))
    r0 = R[:, 0]
    J = (R[:, 1:] - r0[:, None]) / steps
    m, n = len(r0), len(x)
    s2 = float(r0 @ r0) / max(1, m - n)
    sse = float(r0 @ r0)
    # profile at the bounds: each parameter at each bound, the others at the solution, one batch
    moved = []
    for i in range(n):
        for b in (lo[i], hi[i]):
            p = x.copy()
            p[i] = b
            moved.append(p)
    P = f(np.array(moved).T)
    profile = np.sum(P * P, axis=0).reshape(n, 2)
    # a parameter the residuals do not move is not identifiable; the covariance is of the others
    scale = np.linalg.norm(J, axis=0)
    live = [i for i in range(n) if scale[i] > 1e-6 * max(scale.max(), 1e-300)]
    cov = np.full((n, n), np.nan)
    if live:
        JtJ = J[:, live].T @ J[:, live]
        if np.linalg.cond(JtJ) < 1e12:
            cov[np.ix_(live, live)] = s2 * np.linalg.inv(JtJ)
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr = (cov / np.outer(sd, sd)).tolist()
    fitted = []
    for i, a in enumerate(addresses):
        value = float(x[i] * nominal[i])
        if not np.isfinite(cov[i, i]):
            fitted.append(FittedParameter(a, value, math.inf, (math.nan, math.nan), False,
                                          "the traces do not change with it here: not identifiable from this run"))
            continue
        se = float(sd[i] * nominal[i])
        ci = (value - 1.96 * se, value + 1.96 * se)
        partner = [f"{addresses[j]} (ρ = {corr[i][j]:+.2f})" for j in range(n)
                   if j != i and np.isfinite(corr[i][j]) and abs(corr[i][j]) > 0.9]
        flat = [f"{'lower' if k == 0 else 'upper'} bound {b * nominal[i]:.4g}" for k, b in enumerate((lo[i], hi[i]))
                if profile[i][k] < sse * (1 + PROFILE_TOLERANCE)]
        ok = 1.96 * se <= IDENTIFIABLE_REL * abs(value) and not flat
        if flat:
            note = (f"fits about as well at its {' and '.join(flat)} (< {PROFILE_TOLERANCE * 100:g} % worse): "
                    "not identifiable from this run")
        elif not ok:
            note = f"95 % interval ±{196 * se / abs(value):.0f} %: the traces barely change with it; not identifiable"
        else:
            note = "identified" + (f"; strongly correlated with {', '.join(partner)}" if partner else "")
        fitted.append(FittedParameter(a, value, se, ci, ok, note))
    best = f.laps_for(x[:, None])[0]
    wheel = r0[: 2 * len(tel.t)] / f.weight * WHEEL_SCALE
    return TraceAlignment(tuple(fitted), float(np.sqrt(np.mean(wheel ** 2))),
                          best.lap_time_s if best.completed else None, tel.lap_time_s, len(log), f.laps, corr, best)
