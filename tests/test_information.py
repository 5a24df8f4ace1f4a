"""The Cramér–Rao bound on a remaining life (tuner.prognostics.information) against a hand calculation (a straight
line read with a constant error: ordinary least squares' prediction variance) and against Monte Carlo (a curved
path read with noise, refitted many times: the crossing's spread)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tuner.prognostics.information import crossing, remaining_life_bound, within_alpha

pytestmark = pytest.mark.quick


def test_a_straight_line_read_with_one_error_gives_least_squares_prediction_spread_at_its_crossing():
    """v = 1 − 0.01·t read at laps 0–30 to 0.01 each crosses 0.6 at lap 40: 10 laps after lap 30; the crossing
    T = (0.6 − v₀)/r has sd σ·√(1/n + (T − t̄)²/Sxx)/|r| = √(1/31 + 25²/2480) = 0.5332 laps (n = 31, t̄ = 15,
    Sxx = n(n² − 1)/12 = 2480)."""
    t = np.arange(31)
    remaining, sd = remaining_life_bound(1 - 0.01 * t, np.full(31, 0.01), 0.6, 30, degree=1)
    assert remaining == pytest.approx(10.0, abs=1e-9)
    assert sd == pytest.approx(math.sqrt(1 / 31 + 625 / 2480), rel=1e-9)


def test_a_curved_path_refitted_from_noisy_laps_spreads_its_crossing_as_the_bound_says():
    """v = 0.9 − 0.4·(t/70)² (the benchmark's accelerating wear) read at laps 0–30 with errors growing from 0.002 to
    0.004, refitted by weighted least squares 4000 times: the crossing of 0.62 spreads within 5 % of the bound
    (the bound is the delta method's, exact as the noise shrinks; 4000 draws: ±1.1 % sampling error)."""
    t = np.arange(31)
    path, sd = 0.9 - 0.4 * (t / 70) ** 2, np.linspace(0.002, 0.004, 31)
    remaining, bound = remaining_life_bound(path, sd, 0.62, 30)
    assert remaining == pytest.approx(70 * math.sqrt(0.28 / 0.4) - 30, rel=1e-9)
    g = np.random.default_rng(1)
    lives = []
    for _ in range(4000):
        noisy = path + sd * g.standard_normal(31)
        theta = np.polynomial.polynomial.polyfit(t, noisy, 2, w=1 / sd)
        lives.append(crossing(theta, 0.62, 30) - 30)
    assert np.std(lives) == pytest.approx(bound, rel=0.05)


def test_crossings_and_the_chance_to_be_within_alpha_against_hand_numbers():
    assert crossing(np.array([1.0, -0.1]), 0.5, 2.0) == pytest.approx(5.0)
    assert crossing(np.array([1.0, -0.1]), 0.5, 6.0) == math.inf  # crossed before
    assert crossing(np.array([1.0, 0.0, 0.01]), 0.5, 0.0) == math.inf  # never reaches it
    assert remaining_life_bound(np.ones(5), np.ones(5), 0.5, 4, degree=1) == (math.inf, math.inf)
    assert within_alpha(30.0, 6.0, 0.2) == pytest.approx(0.682689, abs=1e-6)  # ±1 sd
    assert within_alpha(30.0, math.inf, 0.2) == 0.0
    with pytest.raises(ValueError):
        remaining_life_bound(np.ones(2), np.ones(2), 0.5, 1, degree=2)
    with pytest.raises(ValueError):  # two laps that say something, three coefficients
        remaining_life_bound(np.ones(4), np.array([1.0, math.inf, 1.0, math.inf]), 0.5, 3, degree=2)
    # a lap that says nothing counts for nothing: the same bound as without it
    t = np.arange(6.0)
    with_silent = remaining_life_bound(1 - 0.1 * t, np.array([0.1, 0.1, math.inf, 0.1, 0.1, 0.1]), 0.2, 5, 1)
    assert with_silent[1] == pytest.approx(0.1 * math.sqrt(1 / 5 + (8 - 2.6) ** 2 / 17.2) / 0.1, rel=1e-9)
