"""The forecast against a robot whose wear is hidden from it: a stand-in robot (the twin with its own noise seeds)
whose tyre grip wears along a drift the benchmark does not use (accelerating, 0.95 → 0.6 over 70 laps), lap times
aligned two laps at a time as live does, and ``history``'s forecast at half of the life: its 90 % interval must
hold the lap the robot first failed on. One scenario, deterministic seeds: a calibrated 90 % interval misses it
one time in ten, which would show here as a failure to look into, not to re-seed away."""

from __future__ import annotations

import numpy as np

from tuner.align.lap_time import align_lap_time
from tuner.history import forecast_failure
from tuner.history.forecast import alone_explains, misfit_limit
from tuner.history.twin_edge import FEATURES
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapLimits
from twin.link.emulator import Drift

from stand_in import robot_laps

# held fixed on purpose, not the tuner's answer today (the plain_gains fixture): the scenario (its seeds, its drift)
# is built on where these gains fail, below μ ≈ 0.75, and a calibrated interval may miss one scenario in ten, so
# the scenario must not move when the tuner does; the test asserts its premise (the first failure within the run)
from reference_gains import PLAIN_HELD as PLAIN
LAPS, EVERY = 70, 5  # laps run; an alignment on laps k-1, k every EVERY laps
ROBOTS, COVERED = 8, 12  # robots read lap by lap, and how many of their 2·ROBOTS intervals must hold the truth


def test_the_stated_interval_holds_the_hidden_drifts_first_failure():
    twin = DigitalTwin()
    twin.model()
    drift = Drift.parse("motion.mu=0.95:0.6@70:accelerating", twin)
    laps = run_laps(twin, [{**PLAIN, "motion.mu": drift.at(k)} for k in range(LAPS)], seed=[500 + k for k in range(LAPS)],
                    keep_traces=False)
    first_failed = next(k for k, lap in enumerate(laps) if not lap.completed)
    assert 20 < first_failed < 65  # a scenario where it can be decided: enough life before, seen within the run
    now = first_failed // 2
    aligned = twin.clone()
    for name, value in PLAIN.items():
        aligned.set(name, value)
    alignments = []
    for k in range(EVERY, now + 1, EVERY):
        measured = (laps[k - 1].lap_time_s + laps[k].lap_time_s) / 2
        r = align_lap_time(aligned, measured, "motion.mu", seed=0, limits=LapLimits(timeout_s=2 * measured))
        alignments.append({"first_lap": k - 1, "lap": k, "address": "motion.mu", "explained": r.explained,
                           "value": r.value, "interval": list(r.consistent) if r.consistent else None})
    seen = [{"n": k, "completed": lap.completed, "gains": PLAIN} for k, lap in enumerate(laps[:now + 1])]
    f = forecast_failure(twin, PLAIN, alignments, seen, "motion.mu", now_lap=now)
    assert f.interval is not None, (f.statement, alignments)
    lo, hi = f.interval
    truth = first_failed - now
    assert lo <= truth <= (hi if hi is not None else float("inf")), (f.statement, truth, alignments)


def test_read_lap_by_lap_the_stated_interval_holds_hidden_drifts_first_failures_and_the_order_does_not_matter():
    """Grip wearing along a drift the benchmark does not use (linear, 0.92 → 0.62 over 60 laps) on ROBOTS robots of
    their own noise seeds, read from every lap's time and the line's offset and side, no alignment at all: at a
    third and at two thirds of each one's life the stated 90 % interval holds its first failed lap at least
    COVERED times of 2·ROBOTS (binomial: a calibrated interval fails this 1.7 % of the time, and one covering 85 %
    7.9 %; one robot alone, as this test was until the line's side was read, misses one time in ten: seeds 700
    onwards did at two thirds, 13 laps left against 14–32); the same laps in another order give the same forecast
    bit for bit."""
    twin = DigitalTwin()
    twin.model()
    covered, said = 0, []
    for r in range(ROBOTS):
        laps = robot_laps(twin, PLAIN, ["motion.mu=0.92:0.62@60"], 60, 700 + 1000 * r)
        first_failed = next((k for k, lap in enumerate(laps) if not lap["completed"]), None)
        assert first_failed is not None and 25 < first_failed < 60, first_failed  # decidable: seen within the run
        for now in (first_failed // 3, 2 * first_failed // 3):
            f = forecast_failure(twin, PLAIN, [], laps[:now + 1], "motion.mu", now_lap=now)
            assert f.interval is not None and f.evidence["features"] == list(FEATURES), f.statement
            lo, hi = f.interval
            covered += lo <= first_failed - now <= (hi if hi is not None else float("inf"))
            said.append((r, now, first_failed - now, f.statement))
    assert covered >= COVERED, said
    shuffled = [laps[k] for k in np.random.default_rng(3).permutation(now + 1)]
    assert forecast_failure(twin, PLAIN, [], shuffled, "motion.mu", now_lap=now) == f


def test_two_causes_at_once_grip_alone_does_not_explain_and_the_battery_that_does_forecasts_the_failure():
    """Grip and the battery wearing together (0.9 → 0.7 and 6.0 → 3.8 V over 40 laps; the robot fails when its
    calibration turn falls short, below ≈ 4 V, as the slowing robot never needs the grip it loses): the laps get
    slower while the line stays nearer the array's centre, which wear of grip alone does not give: no number for
    grip, and the note says so. A flat battery alone reads the laps within their scatter (the grip's share is small beside it), and
    its forecast at lap 23 holds the lap the robot first fails on."""
    from tuner.history.report import causes_note, soonest

    twin = DigitalTwin()
    twin.model()
    laps = robot_laps(twin, PLAIN, ["motion.mu=0.9:0.7@40", "motor.supply_voltage=6.0:3.8@40"], 40, 800)
    first_failed = next((k for k, r in enumerate(laps) if not r["completed"]), None)
    assert first_failed is not None and first_failed > 28, first_failed  # decidable: seen within the run, late
    now = 23
    fs = {a: forecast_failure(twin, PLAIN, [], laps[:now + 1], a, now_lap=now)
          for a in ("motion.mu", "motor.supply_voltage")}
    grip, battery = fs["motion.mu"], fs["motor.supply_voltage"]
    assert grip.laps_to_failure is None and grip.interval is None and "alone does not explain" in grip.statement
    assert grip.misfit > 3 * misfit_limit(len(FEATURES)) and alone_explains(battery), (grip.misfit, battery.misfit)
    assert "only motor.supply_voltage alone explains" in causes_note(fs, []) and soonest(fs.values()) is battery
    lo, hi = battery.interval
    assert lo <= first_failed - now <= (hi if hi is not None else float("inf")), (battery.statement, first_failed)
