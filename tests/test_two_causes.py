"""Two causes at once (tuner.prognostics.plane, tuner.history.two_causes): the plane's models against hand
numbers; the joint filter's remaining life covering the truth at its stated rate over synthetic lives drawn from the
filter's own model (simulation-based calibration); and a stand-in robot whose grip and battery wear together along
drifts the benchmark does not use, forecast from its laps alone."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import norm

from tuner.prognostics import (FailureModel, FilterSettings, LapObservation, ObservationModel, Outcome, estimate,
                               remaining_life)
from tuner.prognostics.particle_filter import SCALE_PRIOR
from tuner.prognostics.plane import PlaneFailure, PlaneObservation

U = np.linspace(0.5, 1.0, 11)  # the first cause's values along each row
ROWS = np.array([4.0, 5.0, 6.0, 7.0])  # the second cause's


def _cubic(w):
    return 0.1 * (6.0 - w) ** 3 - 0.05 * (6.0 - w) ** 2


def _plane(second=_cubic, offset_w=-0.3e-3):
    """A plane whose lap time is 7 + 2·(1 − u) + ``second``(w) and line offset 4 mm + 3 mm·(1 − u) + ``offset_w``·(6 −
    w), scatter 0.01 s and 0.05 mm (uncorrelated), the scatter doubling from the first row to the last."""
    models = []
    for k, w in enumerate(ROWS):
        means = np.stack([7 + 2 * (1 - U) + second(w), 4e-3 + 3e-3 * (1 - U) + offset_w * (6 - w)], axis=1)
        cov = np.diag([0.01 ** 2, 0.05e-3 ** 2]) * (1 + k / (len(ROWS) - 1))
        models.append((float(w), ObservationModel(("lap_time_s", "line_offset_m"), U, means,
                                                  np.repeat(cov[None], len(U), axis=0))))
    return PlaneObservation.of(models[::-1])  # any order of rows


@pytest.mark.quick
def test_the_plane_reads_its_rows_on_a_cubic_across_them_and_a_line_beyond():
    """Means that are a cubic in the second cause come back exactly between rows (a line between the nearest two
    was 0.03 s of lap time off on the twin's battery rows), and beyond the outer rows on the line through them;
    the covariance on a line between rows, held beyond; the failure edge and its probability likewise; the
    nearest values and how far one lap pins each cause against hand numbers."""
    plane = _plane()
    x = np.array([[0.8, 4.3], [0.65, 5.5], [0.9, 6.9], [0.7, 7.5], [0.7, 3.0]])
    want_t = 7 + 2 * (1 - x[:, 0]) + np.array([_cubic(4.3), _cubic(5.5), _cubic(6.9),
                                               _cubic(7.0) + 0.5 * (_cubic(7.0) - _cubic(6.0)),
                                               _cubic(4.0) - 1.0 * (_cubic(5.0) - _cubic(4.0))])
    assert plane.mean(x)[:, 0] == pytest.approx(want_t, abs=1e-12)
    assert plane.mean(x)[:, 1] == pytest.approx(4e-3 + 3e-3 * (1 - x[:, 0]) - 0.3e-3 * (6 - x[:, 1]), abs=1e-15)
    grow = np.array([1 + 0.3 / 3, 1 + 1.5 / 3, 1 + 2.9 / 3, 2.0, 1.0])  # the scatter's factor along the rows
    assert plane.covariance(x)[:, 0, 0] == pytest.approx(0.01 ** 2 * grow, rel=1e-12)
    failure = PlaneFailure.of([(float(w), FailureModel(0.6 + 0.02 * (6 - w) ** 2, 0.01, -1.0)) for w in ROWS], -1.0)
    assert failure.threshold(np.array([4.5, 6.5])) == pytest.approx([0.6 + 0.02 * 1.5 ** 2, 0.6 + 0.02 * 0.25])
    edge = 0.6 + 0.02 * 0.5 ** 2
    assert failure.p_fail(np.array([[edge + 0.01, 5.5], [edge - 0.02, 5.5]])) == pytest.approx(
        [norm.cdf(-1.0), norm.cdf(2.0)])
    assert failure.p_fail(np.array([[edge, 5.5]]), shift=np.array([0.01])) == pytest.approx([norm.cdf(1.0)])
    assert list(failure.direction) == [-1.0, -1.0]
    # the edge's width is held beyond the outer rows (as the scatter is), its threshold goes on along the line
    widening = PlaneFailure.of([(float(w), FailureModel(0.6 + 0.02 * (6 - w) ** 2, 0.01 * (w - 3), -1.0))
                                for w in ROWS], -1.0)
    below = 0.6 + 0.02 * 4 - (0.02 * 1 - 0.02 * 4)  # the line through rows 4 and 5, at 3
    with np.errstate(over="raise", invalid="raise"):
        assert widening.p_fail(np.array([[below + 0.01, 3.0], [0.5, -1e4], [0.5, 1e4]]))[0] == pytest.approx(
            norm.cdf(-1.0))
    # with the second cause's own edge (4.2 V, width 0.1 V): a lap fails as either fails it, independently. At
    # 5.5 V the battery alone never fails (Φ(−13)); at 4.2 V half its laps do, and grip at its own edge there
    # (0.6 + 0.02·1.8²) fails half: 1 − ½·½; at 4.1 V with grip far from its edge, the battery's Φ(1)
    both = PlaneFailure.of([(float(w), FailureModel(0.6 + 0.02 * (6 - w) ** 2, 0.01, -1.0)) for w in ROWS], -1.0,
                           FailureModel(4.2, 0.1, -1.0))
    assert both.p_fail(np.array([[edge + 0.01, 5.5], [0.6 + 0.02 * 1.8 ** 2, 4.2], [0.95, 4.1]])) == pytest.approx(
        [norm.cdf(-1.0), 0.75, norm.cdf(1.0)], abs=1e-9)
    # a lap right on the plane at (0.75, 5.2) is found there (within the grid's step), and one lap pins u to
    # 1/√(Jᵀ Σ⁻¹ J)'s diagonal: lap time moves 2 s per unit of u and −(0.3·(6 − w)² − 0.1·(6 − w)) per unit of w
    u0, w0 = 0.75, 5.2
    found, d2 = plane.nearest(tuple(plane.mean(np.array([[u0, w0]]))[0]), (np.array([0.5, 4.0]), np.array([1.0, 7.0])),
                              points=201)
    assert found == pytest.approx([u0, w0], abs=0.02) and d2 < 0.5
    jac = np.array([[-2.0, -(0.3 * (6 - w0) ** 2 - 0.1 * (6 - w0))], [-3e-3, 0.3e-3]])
    info = jac.T @ np.linalg.inv(plane.covariance(np.array([[u0, w0]]))[0]) @ jac
    assert plane.pins(np.array([u0, w0])) == pytest.approx(np.sqrt(np.diag(np.linalg.inv(info))), rel=1e-3)
    assert plane.reads((9.0, 4e-3)) and not plane.reads((30.0, 4e-3))
    with pytest.raises(ValueError):
        PlaneObservation(np.array([5.0]), (plane.models[0],))


@pytest.mark.quick
def test_rows_whose_laps_slow_towards_an_edge_that_moves_are_read_at_the_same_distance_from_it():
    """Each row's lap time the same steep curve of the distance to its own failure edge, 7 + 0.02/(u − e(w)), the
    edge e(w) = 0.6 + 0.02·(6 − w)² moving with the second cause: the plane given the rows' edges reads between
    and beyond the rows (where the edge goes straight on, as the failure model's) the curve at its own edge's
    distance (within the rows' piecewise-linear sampling, 2001 points: 1e-4 s); the same rows read at the same u
    are far off (on the twin's battery rows: 5 lap scatters)."""
    def edge(w):
        return 0.6 + 0.02 * (6.0 - w) ** 2

    def row(w):
        u = edge(w) + np.linspace(0.03, 0.6, 2001)  # each row raced from near its edge
        means = np.stack([7 + 0.02 / (u - edge(w)), 4e-3 + 0 * u], axis=1)
        return float(w), ObservationModel(("lap_time_s", "line_offset_m"), u, means,
                                          np.repeat(np.diag([0.01 ** 2, 0.05e-3 ** 2])[None], len(u), axis=0))

    rows = [row(w) for w in ROWS]
    aligned, plain = PlaneObservation.of(rows[::-1], [edge(w) for w in ROWS[::-1]]), PlaneObservation.of(rows)
    x = np.array([[0.8, 4.5], [0.68, 5.5], [0.75, 6.6], [0.9, 7.2]])
    at = edge(x[:, 1])
    at[3] = edge(7.0) + 0.2 * (edge(7.0) - edge(6.0))  # beyond the outer rows the edge goes straight on
    want = 7 + 0.02 / (x[:, 0] - at)
    assert aligned.mean(x)[:, 0] == pytest.approx(want, abs=1e-4)
    assert np.abs(plain.mean(x)[:, 0] - want).max() > 0.01
    with pytest.raises(ValueError):
        PlaneObservation(aligned.rows, aligned.models, np.array([0.6]))


def _two_worn_parts(i: int, st: FilterSettings, plane: PlaneObservation, horizon: int):
    """Two parts' life from the joint filter's own model (each straight or speeding up, half the time each), read
    lap by lap through ``plane`` with the robot's own noise scale; laps 0-30 seen."""
    g = np.random.default_rng(9000 + i)
    scale = math.exp(g.uniform(*map(math.log, SCALE_PRIOR)))
    (lo, hi), spans = np.array(st.value_range).T, st.spans
    v = g.uniform(lo, hi)
    r = -np.abs(g.standard_normal(2)) * st.rate_prior * spans
    a = np.where(g.random(2) < 0.5, -np.abs(g.standard_normal(2)) * st.accel_prior * spans, 0.0)
    obs, path = [], []
    for lap in range(31 + horizon):
        if lap:
            v, r = v + r, np.minimum(r + a + st.q * g.standard_normal(2), 0.0)
        path.append(v)
        if lap <= 30:
            chol = np.linalg.cholesky(plane.covariance(v[None])[0])
            obs.append(LapObservation(lap, tuple(float(y) for y in plane.mean(v[None])[0]
                                                 + scale * chol @ g.standard_normal(2))))
    return obs, path


def test_both_causes_at_once_give_a_remaining_life_that_covers_the_truth_at_its_stated_rate():
    """120 synthetic lives of two parts wearing together, each from the joint filter's own model, read lap by lap
    through a plane with a sharp edge (the first cause fails below 0.6 + 0.02·(6 − w)², the second's way). The
    remaining life's 90 % interval must cover the true first failed lap in at least 0.9 − 3 binomial standard
    deviations (√(0.9·0.1/120) = 2.7 %: 81.8 %), a false alarm about 0.1 % of the time for a calibrated filter,
    and at most 98 % (whole laps, ends included)."""
    plane = _plane()
    failure = PlaneFailure.of([(float(w), FailureModel(0.6 + 0.02 * (6 - w) ** 2, 1e-4, -1.0)) for w in ROWS], -1.0)
    st = FilterSettings(span=(0.3, 2.0), value_range=((0.75, 1.0), (5.0, 6.5)), renewal=0.0, rate_prior=0.02,
                        one_way=(-1.0, -1.0), particles=2000)
    horizon, n, life_in = 300, 120, 0
    for i in range(n):
        obs, path = _two_worn_parts(i, st, plane, horizon)
        state = estimate((), (), 30, st, failure, seed=i, observations=obs, model=plane)
        life = remaining_life(state, failure, st.q, seed=i, horizon=horizon)
        truth = next((k for k in range(1, horizon + 1) if failure.p_fail(path[30 + k][None])[0] > 0.5), math.inf)
        life_in += life.quantile(0.05) <= truth <= life.quantile(0.95)
    assert 0.818 <= life_in / n <= 0.98, life_in / n


def test_a_robot_whose_grip_and_battery_wear_together_is_forecast_from_both_and_the_order_does_not_matter():
    """Grip and the battery wearing together along drifts the benchmark does not use (0.95 → 0.5 and 6.1 → 4.0 V
    over 50 laps, the robot starting above the twin's own voltage), read from every lap's time and the line's offset
    and side, no alignment: neither alone explains the laps at half of the life, so ``history`` forecasts both at
    once, and its 90 % interval holds the lap the robot first fails on; the same laps in another order give the
    same forecast bit for bit. One scenario, deterministic seeds: a calibrated interval misses one in ten, which
    would show here as a failure to look into, not to re-seed away."""
    from stand_in import robot_laps
    from tuner.history.report import causes_note, soonest
    from tuner.history.twin_edge import FEATURES
    from tuner.history.two_causes import forecasts_of, joint_address
    from twin.core.digital_twin import DigitalTwin

    from reference_gains import PLAIN_HELD as plain

    twin = DigitalTwin()
    twin.model()
    laps = robot_laps(twin, plain, ["motion.mu=0.95:0.5@50", "motor.supply_voltage=6.1:4.0@50"], 56, 900)
    first_failed = next((k for k, r in enumerate(laps) if not r["completed"]), None)
    assert first_failed is not None and 30 < first_failed < 56, first_failed  # decidable: seen within the run
    now = first_failed // 2
    causes = ["motion.mu", "motor.supply_voltage"]
    fs = forecasts_of(twin, plain, [], laps[:now + 1], causes, now)
    both = fs[joint_address(("motion.mu", "motor.supply_voltage"))]
    assert all(fs[a].laps_to_failure is None for a in causes) and soonest(fs.values()) is both
    assert "wearing together" in both.statement and "together too" in causes_note(fs, [])
    assert set(both.causes) == set(causes) and both.evidence["features"] == list(FEATURES)
    lo, hi = both.interval
    assert lo <= first_failed - now <= (hi if hi is not None else math.inf), (both.statement, first_failed)
    shuffled = [laps[k] for k in np.random.default_rng(5).permutation(now + 1)]
    assert forecasts_of(twin, plain, [], shuffled, causes, now)[both.address] == both
    # the plane it read (cached) against the twin raced mid-way between rows, away from its edge (3 edge widths
    # on): RMS within 1 lap scatter, none beyond 3. Not the two gaps next to where the gains fail on the battery
    # alone: there grip's edge jumps (0.54 at that row, 0.31 0.03 V above it) and the plane is 15 scatters off.
    # Measured RMS 0.48 and 0.65, max 1.6 and 2.2; the same check on 7 rows read at the same u: max 6.0 and 5.2;
    # 4 rows evenly read at the same u: 9.5 at 5.14 V (read at the edge's distance: 2.6, but 15 at 4.4 V on the
    # benchmark's gains)
    from tuner.history.forecast import LAP_TIMEOUT_S
    from tuner.history.twin_edge import twin_edge
    from tuner.history.two_causes import race_plane
    from twin.core.lap import LapLimits

    limits = LapLimits(timeout_s=LAP_TIMEOUT_S)
    raced_plane = race_plane(twin, plain, tuple(causes), 0, limits)
    plane, (start, end) = raced_plane.observation, raced_plane.raced
    direction = raced_plane.failure.directions[0]
    rows = plane.rows
    for w in ((rows[2] + rows[3]) / 2, (rows[4] + rows[5]) / 2):
        raced = twin_edge(twin, {**plain, "motor.supply_voltage": float(w)}, "motion.mu", start, end, direction, 0,
                          limits)
        u = raced.observation.values[raced.observation.values >= raced.failure.threshold + 3 * raced.failure.width]
        x = np.stack([u, np.full_like(u, w)], axis=1)
        off = (plane.mean(x) - raced.observation.mean(u)) / np.sqrt(np.diagonal(plane.covariance(x), axis1=1, axis2=2))
        assert len(u) >= 5 and np.sqrt(np.mean(off ** 2)) <= 1.0 and np.abs(off).max() <= 3.0, (w, off)
    # where the gains fail on the battery alone they fail whatever the grip (here the calibration turn, too slow
    # below 4.0 V, leaves a sensor short of the line): the plane says so from the battery's own edge, its rows
    # there left out of grip's (fitted on five seeds a value, that row's grip edge is noise: 0.54 to 0.78 over four
    # draws of the twin's races on the benchmark's gains; on these, a lap at the twin's own grip 2 widths past the
    # battery's edge failed 26 % of the time). Against the twin raced 2 of the edge's widths either side of it at two
    # grips, 16 seeds of its own each: each count inside the binomial's two-sided 99 % (a false alarm 4 % of seedings
    # at most, these seeds fixed)
    from scipy.stats import binom

    from tuner.history.two_causes import SECOND_ALONE
    from twin.core.closed_loop import run_laps

    failure = raced_plane.failure
    assert all(failure.second.p_fail(w) < SECOND_ALONE for w in failure.rows)
    points = [(mu, failure.second.threshold + k * failure.second.width) for mu in (float(twin.space.get("motion.mu")),
                                                                               0.6) for k in (-2.0, 2.0)]
    edge_laps = run_laps(twin, [{**plain, "motion.mu": mu, "motor.supply_voltage": w} for mu, w in points
                                for _ in range(16)], seed=list(range(70_000, 70_000 + 16 * len(points))),
                         limits=limits, keep_traces=False)
    for i, (mu, w) in enumerate(points):
        failed = sum(not r.completed for r in edge_laps[16 * i:16 * (i + 1)])
        p = float(failure.p_fail(np.array([[mu, w]]))[0])
        assert binom.cdf(failed, 16, p) > 0.005 and binom.sf(failed - 1, 16, p) > 0.005, (mu, w, failed, p)


def test_both_causes_at_once_are_followed_as_the_exact_posterior_follows_them():
    """Grip wearing straight (0.95, −0.004 a lap) and the battery ever faster (6.2 V, −0.01 V a lap, −4·10⁻⁴ a lap²),
    read lap by lap through the plane (its scatter 1.5 times the twin's), every lap finished; the gains fail at the
    plane's edge (width 0.01), first at lap 75. At laps 15 and 30 the joint filter (three seeds; no rate walk, no
    renewal) against the exact posterior of its own model (tests/exact_posterior.py over the plane: each of the
    four combinations of the parts' shapes sampled on its own, the likelihood tempered in the first rounds): the
    remaining life's 10 %, 50 % and 90 % quantiles, the seeds' mean, within 10 % and a lap of the exact's, each
    cause's median value within a quarter of the exact's 90 % band, and the share of futures in which a part speeds
    up within 0.1 (the seeds' mean: one seed alone strays further, the spread bench_forecast reports). Measured
    2026-12-03: exact 38, 70, 94 laps at lap 15 and 21, 26, 36 at lap 30 (10 000 draws a shape; 20 000 gave the
    same but 22 for 21); the filter 38.3, 69.3, 95 and 22, 26.3, 33.3; speeding up 0.39 and 0.93 exact, 0.38 and
    0.94 the filter (its seeds 0.27-0.54 at lap 15). A joint filter whose parts never speed up fails it at lap 15
    (its 10 % quantile 62.7 laps against 38; measured by patching the filter)."""
    from exact_posterior import assert_life_near, exact_posterior, filter_on_seeds

    plane = _plane()
    failure = PlaneFailure.of([(float(w), FailureModel(0.6 + 0.02 * (6 - w) ** 2, 0.01, -1.0)) for w in ROWS], -1.0)
    st = FilterSettings(span=(0.3, 2.0), value_range=((0.75, 1.0), (5.0, 6.5)), renewal=0.0, rate_walk=0.0,
                        rate_prior=0.02, one_way=(-1.0, -1.0))
    g = np.random.default_rng(5)
    v, r, a = np.array([0.95, 6.2]), np.array([-0.004, -0.01]), np.array([0.0, -4e-4])
    obs = []
    for lap in range(31):
        if lap:
            v, r = v + r, r + a
        chol = np.linalg.cholesky(plane.covariance(v[None])[0])
        obs.append(LapObservation(lap, tuple(float(y) for y in plane.mean(v[None])[0]
                                             + 1.5 * chol @ g.standard_normal(2))))
    outs = [Outcome(k, False) for k in range(31)]
    for now in (15, 30):
        exact = exact_posterior((), outs, now, st, failure, draws=10_000, seed=1, observations=obs, model=plane,
                                horizon=300)
        assert min(exact.effective) > 2000  # the importance sampler found the posterior
        runs = filter_on_seeds((), outs, now, st, failure, observations=obs, model=plane, horizon=300)
        assert_life_near(exact, [life for _, life in runs], now)
        medians = [[state.quantiles(dim=j)[1] for j in range(2)] for state, _ in runs]
        shares = [float(np.mean(state.speeding_up)) for state, _ in runs]
        for j, median in enumerate(np.mean(medians, axis=0)):
            low, mid, high = exact.value[3 * j:3 * j + 3]
            assert abs(median - mid) <= 0.25 * (high - low), (now, j, medians, exact.value)
        assert abs(np.mean(shares) - exact.speeding_up) < 0.1, (now, shares, exact.speeding_up)
