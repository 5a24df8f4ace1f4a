"""The profile scan of a trace alignment (tuner.align.uncertainty.profile_scan) on misfits written down by hand, so
the expected sets follow from the formulas, not from a run of the twin."""

from __future__ import annotations

import numpy as np
import pytest

from tuner.align.uncertainty import noise_floor, profile_scan

pytestmark = pytest.mark.quick

LO, HI = np.array([0.2, 0.5]), np.array([2.0, 1.5])


def _scan(misfit, x):
    J = np.eye(2)  # each residual sees one parameter: the others stay where they are along a profile
    at = misfit(x[:, None], [0])
    return profile_scan(lambda X, seeds: misfit(X, seeds), x, LO, HI, J, np.concatenate([at, at]), 0.0, [0], [1])


def test_a_bowl_gives_each_parameter_the_set_below_the_floor_around_the_solution():
    """Misfit 1 + 100 (a − 1)² + 100 (b − 1)²: the floor is 1 + 2 · 0.05 = 1.1, so each set is 1 ± √(0.1/100)."""
    def bowl(X, seeds):
        return 1.0 + 100 * (X[0] - 1) ** 2 + 100 * (X[1] - 1) ** 2

    scan = _scan(bowl, np.array([1.0, 1.0]))
    assert scan.solution_fits and scan.floor == pytest.approx(noise_floor(1.0, 0.0)) == pytest.approx(1.1)
    half = np.sqrt(0.1 / 100)
    for p in scan.profiles:
        # the reported ends are the outer ends of the bisection's last brackets: at or beyond the edge, by < a step
        assert p.inner[0] >= 1 - half - 1e-9 and p.inner[1] <= 1 + half + 1e-9
        assert 1 - 2 * half < p.consistent[0] <= 1 - half and 1 + half <= p.consistent[1] < 1 + 2 * half
        assert not any(p.reaches)


def test_a_far_better_point_on_one_axis_is_reported_and_the_other_parameter_gets_its_whole_range():
    """The solution (1, 1) sits in a shallow basin (misfit 1); along a, at a = 0.4, lies one 100 times better. No
    value of b at a = 1 fits as well as that, so b's set is its whole range (nothing is known of it), and the scan
    names the better point so that the fit can start again from there."""
    def two_basins(X, seeds):
        a, b = X[0], X[1]
        return np.where(np.abs(a - 0.4) < 0.1, 0.01, 1.0) + (b - 1) ** 2

    scan = _scan(two_basins, np.array([1.0, 1.0]))
    assert not scan.solution_fits
    assert abs(scan.best_point[0] - 0.4) < 0.1 and scan.best_point[1] == pytest.approx(1.0)
    a, b = scan.profiles
    assert b.consistent == (LO[1], HI[1]) and b.reaches == (True, True)
    assert LO[0] < a.inner[0] <= a.inner[1] < 0.5  # a's set: the better basin only
