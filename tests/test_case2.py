"""Case 2 of the paper across the realistic range: a robot slower than its twin, explained.

With robust gains (what ``python -m tuner --robust`` answers today on the default track: the ``robust_gains``
fixture; they are inputs here, the expected values come from the hidden parameters each test sets), a robot whose tyres lost up to a third of
their grip still finishes, and the twin finds out why from its lap time or its telemetry.
"""

from __future__ import annotations


import numpy as np
import pytest

from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.telemetry.jsonl import lap_lines, read_telemetry, telemetry_header, write_telemetry
from tuner.align.lap_time import align_lap_time
from tuner.align.trace import align_telemetry
from tuner.align.diagnose import diagnose
from tuner.studies.coverage import coverage, pass_rule, run_study

ROBOT_SEED = 7  # the robot's noise is not the twin's (seed 0)


@pytest.fixture(scope="module")
def robust_twin(robust_gains):
    t = DigitalTwin()
    t.update(robust_gains)
    return t


def record(twin: DigitalTwin, hidden: dict, path) -> str:
    lap = run_laps(twin, [hidden], seed=ROBOT_SEED)[0]
    assert lap.completed, lap.failure  # the robot finishes, only slower
    return write_telemetry(str(path), lap_lines(lap, telemetry_header(twin, "default", ROBOT_SEED), 2))


@pytest.mark.parametrize("mu", [0.6, 0.7])
def test_lap_time_alignment_recovers_grip_on_another_seed(robust_twin, mu):
    measured = run_laps(robust_twin, [{"motion.mu": mu}], seed=ROBOT_SEED)[0]
    assert measured.completed
    r = align_lap_time(robust_twin, measured.lap_time_s)
    assert r.explained and r.value == pytest.approx(mu, rel=0.01)  # docs/models.md: within 1 % (measured 0.05-0.8 %)
    best = r.solutions[0]
    # the values consistent with the lap hold the hidden one; the 95 % interval, where one is given, misses one robot
    # in twenty, so whether it holds a single robot's value is not asserted here: the coverage studies below count
    # it over 40 robots (on 2026-11-28 this robot's at μ 0.7 was 0.6871–0.6998, with the consistent set 0.685–0.709)
    assert best.consistent[0] <= mu <= best.consistent[1]
    assert r.simulated_lap_time_s == pytest.approx(measured.lap_time_s, rel=0.005)


def test_the_refined_scan_finds_a_value_inside_a_narrow_steep_band():
    """Default gains: the lap is 1–7 % slower than nominal only in a narrow band of μ just above where it fails.
    The band is located here with a sweep, not written down."""
    twin = DigitalTwin()
    mus = np.geomspace(0.15, 0.5, 28)
    laps = run_laps(twin, [{"motion.mu": float(m)} for m in mus], seed=0, keep_traces=False)
    nominal = run_laps(twin, [{}], seed=0)[0].lap_time_s
    band = [(m, r.lap_time_s) for m, r in zip(mus, laps) if r.completed and 1.01 < r.lap_time_s / nominal < 1.07]
    assert band, "no steep band on this track"
    hidden, measured = band[len(band) // 2]
    r = align_lap_time(twin, measured, bounds=(0.15, 2.0))
    assert r.explained
    assert any(s.consistent[0] * 0.98 <= hidden <= s.consistent[1] * 1.02 for s in r.solutions), (hidden, r.solutions)


def test_telemetry_recovers_grip_and_battery_with_intervals_that_cover_them(robust_twin, tmp_path):
    """A robot that lost 28 % of its grip on a battery at 5.9 V: both found, within 5 %, inside their intervals.
    (With the caster's drag the robust gains slow the robot so much on a weaker battery that grip hardly moves the
    lap below ≈ 5.8 V; there the fit can stop on the grip–battery ridge, the case below.)"""
    hidden = {"motion.mu": 0.65, "motor.supply_voltage": 5.9}
    tel = read_telemetry(record(robust_twin, hidden, tmp_path / "run.jsonl"))
    r = align_telemetry(robust_twin, tel, ["motion.mu", "motor.supply_voltage"])
    for p in r.parameters:
        assert p.identifiable, p.note
        assert p.value == pytest.approx(hidden[p.address], rel=0.05)
        assert p.ci95[0] <= hidden[p.address] <= p.ci95[1], (p.address, p.ci95)


def test_a_fit_stopped_on_the_ridge_says_so_and_states_no_interval_that_misses(robust_twin, tmp_path):
    """Grip 0.7 on a 5.8 V battery: the fit may stop on the ridge where less grip and more volts trade off (it did
    on 2026-11-26, at μ 0.88, 5.73 V, and said the fit fails); whatever it finds, every interval it states holds
    the hidden value."""
    hidden = {"motion.mu": 0.7, "motor.supply_voltage": 5.8}
    tel = read_telemetry(record(robust_twin, hidden, tmp_path / "run.jsonl"))
    r = align_telemetry(robust_twin, tel, ["motion.mu", "motor.supply_voltage"])
    for p in r.parameters:
        assert p.ci95 is None or p.ci95[0] <= hidden[p.address] <= p.ci95[1], (p.address, p.ci95, p.note)
        assert p.identifiable or p.ci95 is None


def test_a_parameter_the_run_cannot_pin_is_named_with_the_evidence(robust_twin, tmp_path):
    """Grippy tyres on a tired battery: the robot never needs all its grip, so any μ above what it needs fits as
    well; the battery is pinned (the suite's check of a fit that names one parameter not identifiable beside one it
    pins)."""
    hidden = {"motion.mu": 1.2, "motor.supply_voltage": 4.9}
    tel = read_telemetry(record(robust_twin, hidden, tmp_path / "run.jsonl"))
    mu, volts = align_telemetry(robust_twin, tel, ["motion.mu", "motor.supply_voltage"]).parameters
    assert not mu.identifiable and "not identifiable" in mu.note and "misfit" in mu.note
    assert volts.identifiable and volts.value == pytest.approx(4.9, rel=0.05)


ADDRESSES = ("motion.mu", "motor.supply_voltage", "motor.R_M")


def test_lap_time_and_diagnosis_intervals_cover_hidden_values_across_the_documented_ranges(plain_gains):
    """Coverage study (tuner.studies.coverage) of the 95 % intervals that align --measured-lap-time and diagnose
    state (the consistent set where the lap time does not pin the value): 24 robots on the oval with the gains tune
    answers today, each with its own noise seed (1000 on; the twin's laps use 0–38), hiding μ, the battery voltage or
    the winding resistance drawn across its documented range; align and diagnose in turn. Pass: at least 21 of 24
    covered. A 95 % procedure passes with probability 0.970; one of 80 % with 0.264, of 70 % with 0.042
    (pass_rule, binomial): fewer false alarms than 27 of 30 (0.939) for less power against 80 % (was 0.123), to keep
    the suite within its budget; the benchmark measures coverage on more robots (benchmarks/bench_case_studies.py:
    30 per procedure, with Wilson intervals). Measured 2026-12-03: 22 of 24, 17 of them by a 95 % interval; both
    misses diagnose's, as with 30: R_M 9.139 against [9.144, 9.245], just outside, and μ 0.436 against the
    consistent set [0.440, 0.464] near the grip limit, where no interval is given; 293 s of CPU in two worker
    processes beside another test (359 s for 30 robots in the suite run earlier that day)."""
    trials = run_study("oval", plain_gains, ("lap_time", "diagnose"), 12, ADDRESSES, 36).trials
    rule = pass_rule(24, 21)
    assert rule.pass_if_claimed > 0.96 and rule.pass_if[0.8] < 0.27 and rule.pass_if[0.7] < 0.05  # as said above
    covered, n = coverage(trials)
    assert n == 24 and covered >= rule.least, [t for t in trials if not t.covered]
    assert sum(t.kind == "ci95" for t in trials) >= 8, "too few intervals were tested: the study tested sets"


def test_telemetry_intervals_cover_hidden_values_across_the_documented_ranges(plain_gains):
    """The same study for align --telemetry (its 95 % interval where the run pins the value, else the consistent
    set): 16 robots. Pass: at least 14 of 16: a 95 % procedure passes with probability 0.957, one of 80 % with 0.352,
    of 70 % with 0.099 (pass_rule): this one guards against an interval that is badly off; the benchmark measures
    how close to 95 % it is. Measured 2026-12-02: 15 of 16, 12 of them by a 95 % interval; the miss: μ 0.421, where
    the fit itself fails and says so (wheel speeds 61 rad/s rms off), and the set it gives near its solution,
    [0.160, 0.332], lies wholly below the hidden value; 276 s of CPU, 160 s in two worker processes."""
    trials = run_study("oval", plain_gains, ("telemetry",), 16, ADDRESSES, 37).trials
    rule = pass_rule(16, 14)
    assert rule.pass_if_claimed > 0.95 and rule.pass_if[0.7] < 0.1
    covered, n = coverage(trials)
    assert n == 16 and covered >= rule.least, [t for t in trials if not t.covered]
    assert sum(t.kind == "ci95" for t in trials) >= 6, "too few intervals were tested"


def test_diagnosis_ranks_a_tired_battery_first_from_the_lap_time():
    twin = DigitalTwin(track="oval")
    measured = run_laps(twin.clone({"motor.supply_voltage": 5.0}), [{}], seed=ROBOT_SEED)[0].lap_time_s
    report = diagnose(twin, measured, seed=0)
    best = report.candidates[0]
    assert best.address == "motor.supply_voltage" and best.value == pytest.approx(5.0, rel=0.05) and best.plausible
    grip = next(c for c in report.candidates if c.address == "motion.mu")  # (the default gains never slip)
    assert not grip.explained and "align --param motion.mu --bounds motion.mu=LO,HI" in grip.message  # no --bounds here


def test_diagnosis_ranks_dirty_tyres_first_from_the_traces(robust_twin, tmp_path):
    tel = read_telemetry(record(robust_twin, {"motion.mu": 0.6}, tmp_path / "run.jsonl"))
    report = diagnose(robust_twin, None, ["motion.mu", "motor.supply_voltage", "motor.R_M"], tel=tel, joint=False)
    best = report.candidates[0]
    assert best.address == "motion.mu" and best.value == pytest.approx(0.6, rel=0.05)
    others = [d.trace_rms_radps for d in report.candidates[1:] if d.explained]
    assert all(best.trace_rms_radps < o for o in others)
