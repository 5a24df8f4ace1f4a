"""Prognostics (tuner.prognostics): the failure model against the normal CDF; the Monte Carlo's remaining life
against a hand calculation; bit-identical results for a seed whatever order the evidence comes in; and the
filter's intervals covering the truth at their stated rate over many synthetic lives drawn from the filter's own
model (simulation-based calibration: exact only when truths come from the model, which is what this checks)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import norm

from tuner.prognostics import (FailureModel, FilterSettings, Measurement, Outcome, estimate, life_sentence,
                               measurement_sigma, remaining_life)
from tuner.prognostics.particle_filter import SCALE_PRIOR, DegradationState


@pytest.mark.quick
def test_the_failure_model_is_the_normal_cdf_and_a_certain_wear_fails_on_the_lap_a_hand_counts():
    fm = FailureModel(0.7, 0.01, -1.0)
    v = np.array([0.65, 0.7, 0.72])
    assert fm.p_fail(v) == pytest.approx(norm.cdf((0.7 - v) / 0.01))  # below the threshold: likely to fail
    assert FailureModel(0.7, 0.01, 1.0).p_fail(v) == pytest.approx(norm.cdf((v - 0.7) / 0.01))
    # every future the same: μ = 1.0 now, −0.01 per lap, no walk; fails below 0.905 (edge 1e-6): 1 − 0.01k < 0.905
    # first at k = 10 (0.90); the service limit 0.95 is reached at k = 5
    state = DegradationState(0, np.full(64, 1.0), np.full(64, -0.01), np.ones(64), np.zeros(64), [])
    life = remaining_life(state, FailureModel(0.905, 1e-6, -1.0), q=0.0, seed=3, service_limit=0.95)
    assert set(life.laps) == {10.0} and life.quantile(0.05) == life.quantile(0.95) == 10
    assert life.service_median() == 5 and life.within(9) == 0.0 and life.within(10) == 1.0
    assert life_sentence(life) == "the gains in force stop finishing in about 10 laps (90 % between 10 and 10)"
    rising = DegradationState(0, np.full(8, 1.0), np.full(8, 0.01), np.ones(8), np.zeros(8), [])
    never = remaining_life(rising, FailureModel(0.905, 1e-6, -1.0), q=0.0, horizon=50)
    assert never.quantiles()["50"] is None and "not expected to stop finishing within 50 laps" in life_sentence(never)


@pytest.mark.quick
def test_an_alignments_interval_is_a_uniform_spread():
    assert measurement_sigma(0.8, (0.78, 0.81)) == pytest.approx(0.03 / math.sqrt(12))
    assert measurement_sigma(0.8, None) == pytest.approx(0.8 * 2e-3)


def test_the_same_evidence_and_seed_give_the_same_particles_whatever_their_order():
    ms = [Measurement(k - 1, k, 0.9 - 0.004 * k, 0.004) for k in (3, 9, 14, 20)]
    outs = [Outcome(k, k >= 17) for k in range(21)]
    fm = FailureModel(0.8, 0.01, -1.0)
    st = FilterSettings(span=1.0, particles=2000)
    a = estimate(ms, outs, 20, st, fm, seed=7)
    b = estimate(ms[::-1], outs[::-1], 20, st, fm, seed=7)
    assert a.value.tobytes() == b.value.tobytes() and a.rate.tobytes() == b.rate.tobytes() and a.band == b.band
    c = estimate(ms, outs, 20, st, fm, seed=8)
    assert c.value.tobytes() != a.value.tobytes()  # the seed is the only source of chance
    # laps 17-20 failed at μ ≈ 0.83, above the twin's edge (0.8): this robot's edge lies higher than the twin's (the
    # shift, 0 a priori, moves up), while the well measured value stays near the straight line's
    assert np.median(a.shift) > 0.005 and np.median(c.shift) > 0.005
    assert abs(np.median(a.value) - 0.82) < 0.01


def _synthetic_life(i: int, st: FilterSettings, horizon: int):
    """A life drawn from the filter's own model: value, rate with its walk q, the alignments' noise scale; four
    alignments in laps 0-30, then the truth continued to the horizon; the threshold 0.02-0.15 below lap 30's value."""
    g = np.random.default_rng(1000 + i)
    scale = math.exp(g.uniform(*map(math.log, SCALE_PRIOR)))
    sigma = g.uniform(0.002, 0.01)
    v, r = g.uniform(0.7, 1.0), g.standard_normal() * st.rate_prior * st.span
    measured = {int(x) for x in g.choice(np.arange(31), 4, replace=False)}
    ms, path = [], []
    for lap in range(31 + horizon):
        if lap:
            v, r = v + r, r + st.q * g.standard_normal()
        path.append((v, r))
        if lap in measured:
            ms.append(Measurement(lap, lap, v + scale * sigma * g.standard_normal(), sigma))
    return ms, path, path[30][0] - g.uniform(0.02, 0.15)


def test_the_stated_intervals_cover_the_truth_at_their_stated_rate():
    """400 synthetic lives (deterministic seeds). The rate's 90 % interval at lap 30 must cover the true rate in
    85.5-94.5 % of them: 0.9 ± 3 binomial standard deviations (√(0.9·0.1/400) = 1.5 %), a false alarm about 0.3 %
    of the time for a calibrated filter. The remaining life's 90 % interval (whole laps, ends included, so it
    covers at least its rate) must cover the true first failed lap in 85.5-98 %."""
    st, horizon, n = FilterSettings(span=1.0), 300, 400
    rate_in = life_in = 0
    for i in range(n):
        ms, path, threshold = _synthetic_life(i, st, horizon)
        state = estimate(ms, (), 30, st, None, seed=i)
        lo, hi = np.quantile(state.rate, [0.05, 0.95])
        rate_in += lo <= path[30][1] <= hi
        life = remaining_life(state, FailureModel(threshold, 1e-4, -1.0), st.q, seed=i, horizon=horizon)
        truth = next((k for k in range(1, horizon + 1) if path[30 + k][0] < threshold), math.inf)
        life_in += life.quantile(0.05) <= truth <= life.quantile(0.95)
    assert 0.855 <= rate_in / n <= 0.945, rate_in / n
    assert 0.855 <= life_in / n <= 0.98, life_in / n
