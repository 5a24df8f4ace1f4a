"""The field's metrics over a prognostics benchmark's robots (tests/prognostic_metrics.py) against a hand
calculation of Saxena et al.'s (2010) definitions on two made-up robots, and its readiness on made-up times."""

from __future__ import annotations

import pytest

from prognostic_metrics import covered, metrics, ready_within_a_lap

pytestmark = pytest.mark.quick


def forecast(now, true_rul, median, lo, hi, at_point=True):
    return {"now": now, "true_rul": true_rul, "median": median, "lo": lo, "hi": hi, "numbered": median is not None,
            "at_point": at_point, "wall_s": 1.0}


def test_the_metrics_are_the_definitions_worked_by_hand():
    """Robot A fails at lap 40; forecast at laps 10, 20, 30 (true 30, 20, 10 laps left): medians 40, 22, 9, 90 %
    intervals 20–35 (holds 30), 18–25 (holds 20), 10–open (holds 10). Robot B fails at lap 20; at 10 (true 10):
    median 15, 12–18 (misses 10); at 15 (true 5): median 5, 4–6 (holds).

    Coverage: 4 of 5; widths 15, 7, 6, 2 (the open one has none): median 6.5, one open-ended. α-λ (α 0.2, nearest half
    of the life): A at lap 20, |22 − 20| = 2 ≤ 4: met; B at lap 10, |15 − 10| = 5 > 2: not: 1 of 2. Relative
    accuracy there: 1 − 2/20 = 0.9 and 1 − 5/10 = 0.5: median 0.7. Horizon (within ±0.2 of the whole life, 8 laps
    for A, 4 for B): A's errors 10, 2, 1: within from lap 20, (40 − 20)/40 = 0.5; B's 5, 0: within from lap 15,
    (20 − 15)/20 = 0.25: median 0.375."""
    a = {"first_failed_lap": 40, "forecasts": [forecast(10, 30, 40, 20, 35), forecast(20, 20, 22, 18, 25),
                                               forecast(30, 10, 9, 10, None)]}
    b = {"first_failed_lap": 20, "forecasts": [forecast(10, 10, 15, 12, 18), forecast(15, 5, 5, 4, 6)]}
    m = metrics([a, b])
    assert m["forecasts"] == 5 and m["without_a_number"] == 0 and m["coverage_90"] == 0.8
    assert m["median_width_laps"] == 6.5 and m["open_ended"] == 1
    assert m["alpha_lambda_met"] == 0.5 and m["relative_accuracy_median"] == pytest.approx(0.7)
    assert m["prognostic_horizon_median"] == pytest.approx(0.375)
    assert covered(forecast(1, 10, 10, None, None)) and not covered(forecast(1, 10, 10, 11, None))


def test_the_twins_draws_are_counted_over_robot_and_draw():
    """Two robots forecast at half of life on the twin's default draw and one more (``--race-seeds 1``): A (true
    10 laps) 10 (8–12) and 13 (11–15); B (true 20) 20 (15–25) and 30 (26–34). α-λ (±0.2): 10 yes, 13 no (3 > 2),
    20 yes, 30 no: 2 of 4; covered: yes, no (10 < 11), yes, no: 2 of 4; the medians' spread over the true life:
    3/10 and 10/20, median 0.4, max 0.5."""
    def drawn(true, *fs):
        return {"first_failed_lap": 2 * true, "forecasts": [],
                "race_seeds_at_half": {"now": true, "true_rul": true, "forecasts": [
                    {"median": m, "lo": lo, "hi": hi} for m, lo, hi in fs]}}

    m = metrics([drawn(10, (10, 8, 12), (13, 11, 15)), drawn(20, (20, 15, 25), (30, 26, 34))])
    assert m["alpha_lambda_met_per_race_seed"] == 0.5 and m["coverage_90_at_half_per_race_seed"] == 0.5
    assert m["race_seed_spread_median"] == pytest.approx(0.4) and m["race_seed_spread_max"] == pytest.approx(0.5)


def test_readiness_is_the_lateness_after_asking_against_one_lap():
    """Laps of 7, 7 and 8 s: a lap is 7 s (the median). Races written at 10 and 20 s (one cause each), then 150 s
    (both at once). The first forecast, asked when 8 laps are in (56 s), its races done at 20 s, 1.5 s to compute:
    1.5 s late, within a lap. The first of both at once at lap 17, asked when it is in (18 · 7 = 126 s), its races
    done at 150 s, 2 s to compute: 26 s late, not within a lap."""
    r = ready_within_a_lap([10.0, 20.0, 150.0], [7.0, 7.0, 8.0], {"now": 8, "wall_s": 1.5},
                           {"now": 17, "wall_s": 2.0}, 8, 2)
    assert r["lap_s"] == 7.0
    assert r["first"] == {"asked_s": 56.0, "races_done_s": 20.0, "wall_s": 1.5, "late_s": 1.5, "within_a_lap": True}
    assert r["first_joint"] == {"now": 17, "asked_s": 126.0, "races_done_s": 150.0, "wall_s": 2.0, "late_s": 26.0,
                                "within_a_lap": False}
    # the same with each part raced again on more seeds last (at 160 and 170 s): the rows of both at once are the
    # third race from the end; the first forecast on the later races, at lap 19, asked when it is in (20 · 7 = 140 s),
    # 3 s to compute: 33 s late
    r = ready_within_a_lap([10.0, 20.0, 150.0, 160.0, 170.0], [7.0, 7.0, 8.0], {"now": 8, "wall_s": 1.5},
                           {"now": 17, "wall_s": 2.0}, 8, 2, {"now": 19, "wall_s": 3.0}, 2)
    assert r["first_joint"]["races_done_s"] == 150.0 and r["first_joint"]["late_s"] == 26.0
    assert r["first_later"] == {"now": 19, "asked_s": 140.0, "races_done_s": 170.0, "wall_s": 3.0, "late_s": 33.0,
                                "within_a_lap": False}
    assert ready_within_a_lap([10.0], [7.0], {"now": 8, "wall_s": 1.0}, None, 8, 2) == {"lap_s": 7.0}  # one race
    assert ready_within_a_lap([], [7.0], None, None, 8, 2) is None
