"""The twin's failure model, which the forecast rests on (tuner.history.twin_edge): how often its laps fail at a value
of the wearing parameter, against laps on noise seeds the race never drew (an independent Monte Carlo of the same
question)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binomtest

from tuner.history.twin_edge import twin_edge
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapLimits

# held fixed on purpose (test_history's and test_act's gains, not the tuner's answer today): aggressive gains whose
# failures begin below μ ≈ 0.73 and come and go below that (a wrong-way band)
from reference_gains import PLAIN_HELD as PLAIN
LIMITS = LapLimits(timeout_s=30.0)
LAPS = 40


@pytest.fixture(scope="module")
def race():
    twin = DigitalTwin()
    edge = twin_edge(twin, PLAIN, "motion.mu", 1.0, 0.4, -1.0, 0, LIMITS, 5)
    assert edge.failure is not None
    return twin, edge


@pytest.mark.parametrize("z", [0.0, 1.28, 2.05, 3.0])
def test_the_twins_failure_model_says_how_often_laps_fail_at_the_onset(race, z):
    """The failure model (a normal CDF of the edge's onset, fitted to the race's laps) against 40 laps on seeds the
    race never drew, at the value where it says half the laps fail and where it says 10 %, 2 % and 0.1 % do (z edge
    widths towards the unworn side): the count of failed laps is what a binomial of the model's probability gives
    (two-sided p-value at least 1 %). Fitted past the onset (these gains fail 80 % of their laps at μ 0.70 and 42 % at
    0.62), the same race put its edge, where half the laps fail, at μ 0.676, where 80 % do; with the same five seeds
    at every value it learnt five seeds' thresholds (issue 35). Below the onset failures come and go, which the model
    does not describe and a first failure does not need."""
    twin, edge = race
    f = edge.failure
    mu = f.threshold + z * f.width  # grip fails below the edge: +z is towards the unworn side
    laps = run_laps(twin, [{**PLAIN, "motion.mu": mu}] * LAPS, seed=list(range(9000, 9000 + LAPS)), limits=LIMITS,
                    keep_traces=False)
    failed = sum(not lap.completed for lap in laps)
    p = float(np.clip(f.p_fail(mu), 1e-4, 1 - 1e-4))
    assert binomtest(failed, LAPS, p).pvalue >= 0.01, (mu, failed, p, f)
