"""Closed loop (§3.5–3.6): default lap, failures as results, determinism, batch = serial, calibration, CLI."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import types

import numpy as np
import pytest

from mjcf.track import builtin
from mjcf.world import MOTORS
from twin.core import native as core
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.errors import TwinError
from twin.core.lap import COL, LapJudge, LapLimits
from twin.run import main
from twin.viz.viewer import check_recording


@pytest.fixture(scope="module")
def twin():
    return DigitalTwin()


@pytest.fixture(scope="module")
def default_lap(twin):
    return run_laps(twin, [{}], seed=0)[0]


@pytest.mark.quick
def test_default_gains_complete_the_default_lap(default_lap, twin):
    r = default_lap
    assert r.completed and r.failure is None
    assert r.distance_m == pytest.approx(twin.track.length_m)
    # 7.18 m at v_max = 0.6 m/s: no faster than v_max allows, and not much slower (it slows only in bends)
    assert twin.track.length_m / 0.6 < r.lap_time_s < 1.25 * twin.track.length_m / 0.6
    assert r.max_cross_track_m < 0.02  # the sensor bar is ±33 mm: the line stays well inside it
    assert 0 < r.mean_cross_track_m < r.max_cross_track_m
    assert energy_lower_bound_j(twin.track.length_m, r.lap_time_s) * 0.97 < r.energy_j
    assert r.energy_j < 1.3 * energy_lower_bound_j(twin.track.length_m, r.lap_time_s)


def energy_lower_bound_j(distance_m: float, lap_time_s: float) -> float:
    """Hand calculation from the datasheet (Pololu #2369: 6 V, 0.67 A at stall, 720 rpm and 40 mA no-load, 29.86:1,
    16 mm wheels) and the gearmotor model (motors.datasheet, half of the no-load friction dry): R = U/I_stall,
    K = (U − R·I_0)/ω_nl. At a steady motor speed ω a motor draws at least the current its own friction takes,
    I(ω) = I_0·(s + (1 − s)·ω/ω_nl) with s = 0.5 (any load adds current), at V = R·I + K·ω, so P ≥ (R·I + K·ω)·I,
    convex in ω: over a lap (Jensen) both motors draw at least 2·P(ω̄)·t, ω̄ the mean motor speed that covers the
    distance; turning (one wheel faster), speeding up and slip only add. 0.97: the contact patch of a crowned
    tyre rolls on a slightly smaller radius; 1.3: room for the bends (turning at ±ω) and the launch."""
    U, I_stall, I_0, gear, rpm, R_wheel, s = 6.0, 0.67, 0.040, 29.86, 720.0, 0.016, 0.5
    R = U / I_stall
    w_nl = rpm * 2 * np.pi / 60 * gear
    K = (U - R * I_0) / w_nl
    w_mean = distance_m / lap_time_s / R_wheel * gear
    current = I_0 * (s + (1 - s) * w_mean / w_nl)
    return 2 * (R * current + K * w_mean) * current * lap_time_s


@pytest.mark.quick
def test_trace_is_consistent_with_eqs_10_and_11(default_lap, twin):
    tr = default_lap.trace
    p = twin.control_params()
    v_target = np.maximum(0.0, p.v_max - p.k_b * np.abs(tr.column("e_rad")))
    v = tr.column("v_mps")
    # Eq. 10, raised no faster than the ramp: v_k = min(v_max − K_B|e_k|, v_k−1 + a·Δt)
    ramp = np.concatenate([[p.accel_max * p.dt_s], v[:-1] + p.accel_max * p.dt_s])
    assert np.allclose(v, np.minimum(v_target, ramp), rtol=0, atol=1e-12)
    assert np.mean(v == v_target) > 0.9  # mostly Eq. 10 itself
    e = tr.column("e_rad")
    omega = p.k_p * e + p.k_d * np.diff(np.concatenate([[e[0]], e])) / p.dt_s  # K_I = 0 by default
    assert np.allclose(tr.column("omega_radps"), omega, rtol=1e-9, atol=1e-9)
    assert np.all(np.abs(tr.column("u_left_v")) <= 6.0) and np.all(np.abs(tr.column("u_right_v")) <= 6.0)
    assert np.allclose(np.diff(tr.time_s), p.dt_s)  # one record per control tick


@pytest.mark.quick
def test_calibration_comes_from_the_in_place_turn(twin, default_lap):
    r = default_lap
    # every sensor crossed the line and the ground: min ≈ white board (≈ 200 µs), max ≈ tape (≈ 2400 µs)
    assert all(150 < lo < 260 for lo in r.calibration_min_us)
    assert all(hi > 2200 for hi in r.calibration_max_us)
    # a turn too small to bring the outer sensors over the line leaves them uncalibrated: a failed lap
    small = run_laps(twin, [{"control.cal_sweep": 0.15}], keep_traces=False)[0]
    assert not small.completed and small.failure == "calibration"
    assert small.calibration_max_us[0] - small.calibration_min_us[0] < 300


@pytest.mark.quick
def test_leaving_the_track_is_a_result(twin):
    blind, lost = run_laps(twin, [{"control.kp": 0.0, "control.kd": 0.0}, {"control.kp": 0.0, "control.kd": 0.0}],
                           keep_traces=False, limits=LapLimits(max_line_lost_s=1000.0))[0], None
    assert not blind.completed and blind.failure == "off_track" and blind.lap_time_s is None
    # it drove straight on from the start (0.3 m before the first bend) until 10 cm off the line
    assert 0.3 < blind.distance_m < 1.0 and blind.max_cross_track_m > 0.1
    lost = run_laps(twin, [{"control.kp": 0.0, "control.kd": 0.0}], keep_traces=False)[0]
    assert lost.failure == "line_lost" and lost.simulated_s < blind.simulated_s


@pytest.mark.quick
def test_same_seed_is_bit_identical_and_seed_matters(twin, default_lap):
    again = run_laps(twin, [{}], seed=0, nthread=1)[0]
    assert np.array_equal(again.trace.records, default_lap.trace.records)
    assert again.lap_time_s == default_lap.lap_time_s
    other = run_laps(twin, [{}], seed=1)[0]
    assert not np.array_equal(other.trace.raw_us[:100], default_lap.trace.raw_us[:100])


@pytest.mark.quick
def test_batched_laps_equal_laps_run_one_by_one(twin):
    variants = [{"control.v_max": 0.8, "control.kp": 25.0}, {"motion.mu": 0.4}, {"control.kd": 0.5, "sensor.noise": 0.05}]
    together = run_laps(twin, variants, seed=3, nthread=2)
    for v, batched in zip(variants, together):
        alone = run_laps(twin, [v], seed=3, nthread=1)[0]
        assert np.array_equal(alone.trace.records, batched.trace.records), v
        assert alone.summary() == batched.summary()
    assert twin.space.get("motion.mu") == 0.9  # variants do not leak into the twin


@pytest.mark.quick
def test_a_lap_does_not_depend_on_the_turns_of_the_laps_beside_it(twin):
    """Laps whose calibration turns differ in length (physics step, sweep) share a batch: each turns exactly as long
    as it would alone (extra idle ticks would draw sensor noise and shift its lap)."""
    variants = [{"motion.timestep": 0.0025}, {"control.cal_sweep": 2.0}, {"motion.timestep": 0.0005}]
    together = run_laps(twin, variants, seed=3, keep_traces=False, reuse_calibration=False)
    for v, batched in zip(variants, together):
        alone = run_laps(twin, [v], seed=3, keep_traces=False, reuse_calibration=False)[0]
        assert alone.summary() == batched.summary(), v


@pytest.mark.quick
def test_variants_never_write_to_the_twin():
    """A variant is derived from a mapping of values: the twin's values and model fields are never touched,
    not even for the duration of the batch (another thread may read them)."""
    t = DigitalTwin()
    model = t.model()
    fields = {f: getattr(model, f).copy() for f in ("geom_friction", "actuator_gainprm", "actuator_biasprm",
                                                  "actuator_dynprm", "actuator_gear", "actuator_user", "dof_frictionloss")}
    before = dict(t.space.values)
    t.space.values = types.MappingProxyType(before)  # any write to the twin's values raises
    mixed = run_laps(t, [{"motion.mu": 0.4, "motor.R_M": 10.0, "motor.friction": 2e-4, "control.kp": 20.0,
                          "sensor.noise": 0.05}, {}],
                     keep_traces=False)
    assert mixed[0].parameters["motor.R_M"] == 10.0 and mixed[1].parameters["motor.R_M"] == before["motor.R_M"]
    assert mixed[0].lap_time_s != mixed[1].lap_time_s
    for name, value in fields.items():
        assert np.array_equal(getattr(model, name), value), name
    assert t.rebuilds == 1


@pytest.mark.quick
@pytest.mark.parametrize("change, needle", [
    ({"cad.L": 0.05}, "cad.L: rebuilds the robot or track"),
    ({"motor.L_M": 0.0}, "motor.L_M: switching between zero and non-zero"),
    ({"control.kp": -1.0}, "control.kp:"),
])
def test_a_variant_that_cannot_share_the_batch_is_one_line(twin, change, needle):
    with pytest.raises(TwinError) as e:
        run_laps(twin, [{}, change])
    assert needle in str(e.value) and "\n" not in str(e.value)


@pytest.mark.quick
def test_sensor_count_is_a_model_parameter():
    t = DigitalTwin()
    t.update({"sensor.count": 6, "sensor.pitch": 0.012})
    r = run_laps(t, [{}], keep_traces=True)[0]
    assert r.completed and len(r.calibration_min_us) == 6 and r.trace.raw_us.shape[1] == 6


# --- the lap judge on a synthetic run: exact answers
def synthetic(track, speed, t):
    rec = np.zeros((len(t), core.RECORD_WORDS))
    rec[:, COL["time_s"]] = t
    rec[:, 1:3] = track.point_at(speed * t)
    rec[:, COL["line_seen"]] = 1
    rec[:, COL["energy_j"]] = 2.0 * t  # 2 W
    rec[:, COL["progress_m"]], rec[:, COL["offset_m"]] = track.locate(rec[:, 1:3])
    rec[:, COL["offset_abs_sum_m"]] = np.cumsum(np.abs(rec[:, COL["offset_m"]]))
    rec[:, COL["offset_abs_max_m"]] = np.maximum.accumulate(np.abs(rec[:, COL["offset_m"]]))
    return rec


@pytest.mark.quick
def test_judge_interpolates_the_crossing():
    track = builtin("circle")
    t = np.arange(0, 4.0, 0.005)
    rec = synthetic(track, 1.0, t)
    judge = LapJudge(track, LapLimits())
    for k in range(0, len(t), 37):  # uneven chunks
        judge.feed(rec[k : k + 37])
    r = judge.result(8, [0] * 8, [0] * 8, {})
    assert r.completed
    assert r.lap_time_s == pytest.approx(track.length_m, abs=1e-6)  # 1 m/s around a 2π·0.5 m circle
    assert r.energy_j == pytest.approx(2.0 * track.length_m, abs=1e-5)
    assert r.max_cross_track_m < 1e-6


@pytest.mark.quick
def test_judge_times_a_lost_line():
    track = builtin("oval")
    t = np.arange(0, 3.0, 0.005)
    rec = synthetic(track, 0.5, t)
    rec[t >= 1.0, COL["line_seen"]] = 0
    judge = LapJudge(track, LapLimits(max_line_lost_s=0.5))
    judge.feed(rec)
    r = judge.result(8, [0] * 8, [0] * 8, {})
    assert r.failure == "line_lost"
    assert 0.5 - 1e-9 <= r.simulated_s - 0.995 <= 0.505 + 1e-9  # last seen at 0.995 s; judged to the tick


# --- command line
DEFAULT_TRACK_LENGTH_M = 2.7 + math.pi * (0.5 + 0.25 + 0.15 + 0.15 + 0.3 + 0.4) / 2 + math.pi * (0.2 + 0.35)
"""By hand from mjcf.track's segments of the default track: 2.7 m of straights, six quarter arcs and two half arcs."""


def electrical_energy_j(twin: DigitalTwin, trace, t_end: float) -> float:
    """∫ U·I dt over [0, t_end] for both motors, from a lap's trace and Eq. 6 alone (not the C loop's integral).
    The firmware writes each duty once per control tick and it holds until the next; the current settles
    within L/R = 0.5 mH / 8.96 Ω = 56 µs ≪ Δt = 5 ms, so I = (U − K·ω_m)/R, with ω_m the motor speed (the
    wheel's times the actuator's signed gear), averaged over the tick. U is the duty (the trace's commanded voltage
    over the nominal supply) times the supply under that load (twin.model.power, its own closed form, tested by
    hand in tests/test_power.py). A motor feeding power back (U·I < 0) draws none from the battery."""
    model, t = twin.model(), trace.time_s
    R, K = twin.space.get("motor.R_M"), twin.space.get("motor.K")
    power = twin.power()
    dt = np.clip(t_end - t[:-1], 0.0, np.diff(t))  # whole ticks, and the part of the last one before t_end
    duty, emf = [], []
    for motor, u, w in zip(MOTORS, ("u_left_v", "u_right_v"), ("wheel_left_radps", "wheel_right_radps")):
        w_m = model.actuator(motor).gear[0] * trace.column(w)
        duty.append(trace.column(u)[:-1] / power.nominal_v)
        emf.append(K * (w_m[:-1] + w_m[1:]) / 2)
    bus = np.array([power.bus_voltage(d, e, (R, R))[0] for d, e in zip(zip(*duty), zip(*emf))])
    total = 0.0
    for d, e in zip(duty, emf):
        U = d * bus
        total += float(np.sum(np.maximum(U * (U - e) / R, 0.0) * dt))
    return total


@pytest.mark.quick
def test_cli_lap_json_gains_and_recording(tmp_path, capsys):
    gains = tmp_path / "gains.json"
    gains.write_text(json.dumps({"gains": {"control.v_max": 0.7, "kp": 18}}))
    rrd = tmp_path / "run.rrd"
    assert main(["lap", "--gains", str(gains), "--set", "control.kd=0.35", "--json", "--save", str(rrd)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["completed"] and out["failure"] is None and out["seed"] == 0
    assert out["parameters"]["control.v_max"] == 0.7 and out["parameters"]["control.kp"] == 18
    assert out["parameters"]["control.kd"] == 0.35
    # the same lap through the library: the command adds nothing and loses nothing
    twin = DigitalTwin()
    twin.update({"control.v_max": 0.7, "control.kp": 18.0, "control.kd": 0.35})
    lap = run_laps(twin, [{}], seed=0)[0]
    assert (out["lap_time_s"], out["energy_j"]) == (lap.lap_time_s, lap.energy_j)
    assert (out["max_cross_track_m"], out["mean_cross_track_m"]) == (lap.max_cross_track_m, lap.mean_cross_track_m)
    # a completed lap covers the track: its length by hand from the segments
    assert out["distance_m"] == pytest.approx(DEFAULT_TRACK_LENGTH_M, abs=1e-6)
    assert out["track_length_m"] == pytest.approx(DEFAULT_TRACK_LENGTH_M, abs=1e-6)
    # the energy is the electrical energy the motors drew, recomputed from the trace by Eq. 6
    # (to 0.02 J: the trace does not show the duties' arrival after each tick's reads and compute, nor their PWM
    # counts; 0.02 J was the old motor model's 2e-3 of 9 J, and stays the bound now that the lap draws 3.3 J)
    assert out["energy_j"] == pytest.approx(electrical_energy_j(twin, lap.trace, lap.lap_time_s), abs=0.02)
    # the recording holds that lap: rerun's own reader finds the energy series tick by tick
    check_recording(str(rrd))
    assert not list(tmp_path.glob("*.tmp"))
    data = rrd.read_bytes()
    assert b"sensors/calibrated/7" in data and b"track/robot/path" in data
    try:
        from rerun.chunk import RrdReader  # rerun-sdk ≥ 0.41
    except ImportError:
        pytest.skip("reading a recording back needs rerun-sdk ≥ 0.41")
    chunks = [c.to_record_batch() for c in RrdReader(str(rrd)).stream().to_chunks() if c.entity_path == "/energy/motors"]
    recorded = np.concatenate([np.concatenate(b.column("Scalars:scalars").to_pylist()) for b in chunks])
    assert np.array_equal(recorded, lap.trace.column("energy_j"))


@pytest.mark.quick
@pytest.mark.parametrize("args, needle", [
    (["--track", "nowhere"], "unknown track"),
    (["--set", "control.kp=nan"], "control.kp: must be finite"),
    (["--set", "control.kp=-3"], "outside"),
    (["--set", "control.gain=3"], "unknown parameter address"),
])
def test_cli_bad_input_is_one_line_and_exit_2(args, needle, capsys):
    assert main(["lap", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and needle in err[0]


def test_cli_unreadable_track_image_in_a_fresh_process(tmp_path):
    bad = tmp_path / "track.png"
    bad.write_bytes(b"not a png")
    p = subprocess.run([sys.executable, "-m", "twin.run", "lap", "--track", str(bad)], capture_output=True, text=True)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert p.stderr.strip().startswith(f"error: {bad}")


@pytest.mark.quick
def test_c_lap_progress_equals_track_locate():
    """lf_locate (the C loop's incremental search) against Track.locate (k-d tree) along a wandering path."""
    import ctypes

    from twin.core.digital_twin import centre_line_data

    track = builtin("default")
    data = np.ascontiguousarray(centre_line_data(track))
    ptr = data.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
    seg = ctypes.c_int64(-1)
    s_c, off_c = ctypes.c_double(), ctypes.c_double()
    rng = np.random.default_rng(0)
    s = np.arange(0.0, 2 * track.length_m, 0.004)  # two laps, 4 mm per tick
    lateral = 0.04 * np.sin(s / 0.3) + rng.normal(0, 0.002, len(s))
    p = track.point_at(s)
    q = track.point_at(s + 0.001)
    n = (q - p) / np.linalg.norm(q - p, axis=1)[:, None]
    xy = p + lateral[:, None] * np.stack([-n[:, 1], n[:, 0]], axis=1)
    ref_s, ref_off = track.locate(xy)
    for k, (x, y) in enumerate(xy):
        core.lib.lf_locate(ptr, len(track.centre), track.length_m, x, y, ctypes.byref(seg), ctypes.byref(s_c), ctypes.byref(off_c))
        ds = (s_c.value - ref_s[k] + track.length_m / 2) % track.length_m - track.length_m / 2
        assert abs(ds) < 1e-9 and abs(off_c.value - ref_off[k]) < 1e-12, k


@pytest.mark.quick
def test_a_field_changed_on_the_twin_is_simulated_by_the_next_laps():
    """The batch of a twin is reused between calls; a model-field change in between must reach it."""
    t = DigitalTwin()
    first = run_laps(t, [{}], keep_traces=False)[0]
    t.set("motion.mu", 0.2)  # the robot slips in the tight bends: a slower lap (+0.24 s; at 0.18 it no longer finishes)
    slow = run_laps(t, [{}], keep_traces=False)[0]
    assert slow.lap_time_s > first.lap_time_s + 0.1
    assert slow.lap_time_s == run_laps(DigitalTwin(), [{"motion.mu": 0.2}], keep_traces=False)[0].lap_time_s


@pytest.mark.quick
def test_kept_calibration_is_bit_identical_to_a_fresh_one(twin):
    """Laps that differ only in gains reuse one calibration turn; the laps equal those of a fresh twin."""
    variants = [{"control.kp": 18.0}, {"control.kp": 22.0, "control.v_max": 0.7}]
    run_laps(twin, [{}])  # the twin has calibrated already
    kept = run_laps(twin, variants, seed=0)
    fresh = [run_laps(DigitalTwin(), [v], seed=0)[0] for v in variants]
    for a, b in zip(kept, fresh):
        assert np.array_equal(a.trace.records, b.trace.records)
        assert a.calibration_max_us == b.calibration_max_us


@pytest.mark.quick
def test_per_lap_seeds_equal_laps_run_with_one_seed_each(twin):
    together = run_laps(twin, [{}, {"control.kp": 18.0}, {}], seed=[3, 0, 5], keep_traces=False)
    alone = [run_laps(twin, [v], seed=s, keep_traces=False)[0] for v, s in (({}, 3), ({"control.kp": 18.0}, 0), ({}, 5))]
    assert [r.summary() for r in together] == [r.summary() for r in alone]
    assert together[0].lap_time_s != together[2].lap_time_s  # the seeds did differ


@pytest.mark.quick
def test_a_supply_voltage_varied_in_a_batch_is_the_one_simulated():
    """The PWM duty drives the lap's own battery voltage: a 4.8 V variant in a batch equals a twin set to 4.8 V."""
    base = DigitalTwin(track="oval")
    low = DigitalTwin(track="oval")
    low.set("motor.supply_voltage", 4.8)
    batched = run_laps(base, [{}, {"motor.supply_voltage": 4.8}], seed=0)
    alone = run_laps(low, [{}], seed=0)[0]
    assert batched[1].summary() == alone.summary()
    assert batched[1].lap_time_s > batched[0].lap_time_s * 1.1  # 20 % less voltage: clearly slower


RECKLESS = {"control.v_max": 1.2, "control.kb": 1.0, "control.kp": 20.0, "control.ki": 0.0, "control.kd": 0.3}


def test_stopping_decided_laps_changes_no_result(twin):
    """Laps whose decision is close (too fast for their steering at μ 0.605: some seeds finish, others slide and turn
    round) end the tick they are decided with exactly the results of laps stepped to the end of their chunk;
    a deadline stops a lap undecided past it, and one past the lap's end changes nothing."""
    laps = [{**RECKLESS, "motion.mu": 0.605}] * 6  # 2 of 6 finish (0.63 before the caster's drag, 0.6 before the losses)
    stopped = run_laps(twin, laps, seed=list(range(6)), keep_traces=False)
    to_the_end = run_laps(twin, laps, seed=list(range(6)), keep_traces=False, stop_decided=False)
    assert 0 < sum(r.completed for r in stopped) < len(laps)  # the decision is close: the seeds split it
    assert [r.summary() for r in stopped] == [r.summary() for r in to_the_end]  # bit for bit
    done = next(i for i, r in enumerate(stopped) if r.completed)
    t = stopped[done].lap_time_s
    early, late = run_laps(twin, [laps[done]] * 2, seed=done, keep_traces=False, deadline_s=[t / 2, t + 1.0])
    assert early.failure == "stopped" and t / 2 < early.simulated_s < t and not early.completed
    assert late.summary() == stopped[done].summary()


@pytest.mark.parametrize("limits", [LapLimits(), LapLimits(max_cross_track_m=0.01), LapLimits(max_progress_jump_m=0.003),
                                    LapLimits(timeout_s=5.0), LapLimits(min_calibration_range_us=3000.0)],
                         ids=["default", "off_track", "cut_across", "timeout", "calibration"])
def test_laps_judged_in_c_alone_equal_laps_judged_from_their_trace(twin, limits):
    """A lap whose trace is not kept is judged by the C loop alone and runs to its end in one call; its result, what it
    says and the statistics included, is the one Python's judge reaches from the same lap's trace: completed, line
    lost, off the track (either way), timed out, a failed calibration, stopped past a deadline."""
    laps = [{}, {"control.kp": 2.0}, {"motion.mu": 0.2}, {"control.v_max": 1.6}, {**RECKLESS, "motion.mu": 0.6}]
    seeds = list(range(len(laps)))
    alone = run_laps(twin, laps, seed=seeds, keep_traces=False, limits=limits)
    traced = run_laps(twin, laps, seed=seeds, keep_traces=True, limits=limits)
    assert [r.summary() for r in alone] == [r.summary() for r in traced]
    assert all(r.trace is None for r in alone)
    deadline = [3.0] * len(laps)
    assert ([r.summary() for r in run_laps(twin, laps, seed=seeds, keep_traces=False, limits=limits, deadline_s=deadline)]
            == [r.summary() for r in run_laps(twin, laps, seed=seeds, keep_traces=True, limits=limits, deadline_s=deadline)])


def test_the_cases_of_laps_judged_in_c_alone_happen(twin):
    """The equality above covers each way a lap ends, each with its own detail."""
    laps = [{}, {"control.kp": 2.0}, {"motion.mu": 0.2}, {"control.v_max": 1.6}, {**RECKLESS, "motion.mu": 0.6}]
    seeds = list(range(len(laps)))
    said = set()
    for limits in (LapLimits(), LapLimits(max_cross_track_m=0.01), LapLimits(max_progress_jump_m=0.003),
                   LapLimits(timeout_s=5.0), LapLimits(min_calibration_range_us=3000.0)):
        for deadline in (None, [3.0] * len(laps)):
            said |= {(r.failure, r.detail.split(" ")[0]) for r in
                     run_laps(twin, laps, seed=seeds, keep_traces=False, limits=limits, deadline_s=deadline)}
    assert {(None, "lap"), ("line_lost", "line"), ("off_track", "more"), ("off_track", "cut"), ("timeout", "no"),
            ("calibration", "sensor"), ("stopped", "stopped")} <= said, said


def test_a_step_that_does_not_divide_the_control_period_is_refused_with_one_that_does(twin):
    """The error for a physics step that is not a whole fraction of control.dt names one that is: set, it is taken."""
    t = DigitalTwin()
    t.set("motion.timestep", 0.0003)  # 5 ms / 0.3 ms = 16.7 steps
    with pytest.raises(TwinError, match="not a whole number of physics steps") as refused:
        t.control_params()
    suggested = float(str(refused.value).rsplit("e.g. ", 1)[1])
    assert suggested <= 0.0003
    t.set("motion.timestep", suggested)
    assert round(t.control_params().dt_s / suggested) == 17  # 5 ms in 17 whole steps: taken


def test_the_lap_says_which_physics_step_it_ran(capsys):
    """A step set with --set shows in the lap's text, so a user sees that it was taken."""
    assert main(["lap", "--set", "motion.timestep=0.0016666666666666668"]) == 0
    assert "physics step 1.66667 ms" in capsys.readouterr().out
