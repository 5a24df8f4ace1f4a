"""The distribution-free inverse prediction (tuner.align.calibration) that gives a lap-time alignment its 95 %
interval, checked in simulations where the truth is known: lap-to-lap noise skewed like the twin's (gamma, skewness
≈ 1.4: slow laps stretch further than fast ones), each seed's noise shared across values (common random numbers,
as the twin's seeds are), and a robot whose one lap is another draw."""

from __future__ import annotations

import numpy as np
import pytest

from tuner.align.calibration import inverse_interval, seeds_for

pytestmark = pytest.mark.quick


def test_39_laps_hold_one_more_at_95_percent():
    assert seeds_for(0.95) == 39  # (n − 1)/(n + 1) = 38/40
    assert seeds_for(0.9) == 19  # 18/20


def _noise(rng, size):
    return 0.004 * (rng.gamma(2.0, 1.0, size) - 2.0)  # mean 0, skewed towards slow laps


def test_it_covers_the_truth_at_least_95_times_in_100_with_skewed_noise():
    """10 000 robots: coverage at or above 95 % (its slope's own interval widens it a little); a normal-theory
    interval of mean ± 1.96 σ from the same laps covers about 1 point less here (93.9 %)."""
    rng = np.random.default_rng(2018)
    slope, x0, n = -2.0, 1.0, seeds_for(0.95)
    covered = covered_normal = 0
    for _ in range(10000):
        seed_noise = _noise(rng, n)
        at_x0 = 5 + seed_noise
        lo, hi = 0.99, 1.01
        at_lo = 5 + slope * (lo - x0) + seed_noise[:8] + rng.normal(0, 2e-4, 8)
        at_hi = 5 + slope * (hi - x0) + seed_noise[:8] + rng.normal(0, 2e-4, 8)
        truth = x0 + rng.uniform(-0.004, 0.004)
        y0 = 5 + slope * (truth - x0) + _noise(rng, 1)[0]
        r = inverse_interval(x0, at_x0, lo, at_lo, hi, at_hi, y0)
        covered += bool(r.interval and r.interval[0] <= truth <= r.interval[1])
        m, sd = at_x0.mean(), at_x0.std(ddof=1)
        covered_normal += abs(y0 - (m + slope * (truth - x0))) <= 1.96 * sd
    assert 0.945 <= covered / 10000 <= 0.975, covered  # 95 % within 2.3 σ of 10 000 draws (or a little above)
    assert covered_normal / 10000 < covered / 10000 - 0.005, (covered, covered_normal)


def test_a_slope_that_may_be_0_pins_nothing():
    rng = np.random.default_rng(3)
    noise = rng.normal(0, 0.01, 39)
    flat = inverse_interval(1.0, 5 + noise, 0.99, 5 + rng.normal(0, 0.01, 8), 1.01, 5 + rng.normal(0, 0.01, 8), 5.0)
    assert flat.interval is None


def test_bad_designs_are_refused():
    with pytest.raises(ValueError):
        inverse_interval(1.0, [5.0, 5.1], 1.01, [5.0, 5.1], 0.99, [5.0, 5.1], 5.0)  # x_lo > x_hi
