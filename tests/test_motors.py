"""The gearmotor model: datasheet fit, MuJoCo's actuator against the closed forms, and every catalogue motor in
MuJoCo at its datasheet's four points."""

import dataclasses
import math

import mujoco
import numpy as np
import pytest

from motors import POLOLU_MP_6V_30_1, Datasheet, MotorConstants, MotorError
from motors.actuator import current, read_fields, write_fields
from motors.analytic import free_air_step
from motors.datasheet import RPM
from motors.dyno import measured_points, steady, wheel_in_free_air

pytestmark = pytest.mark.quick  # the whole module is in the quick tier (tests/test_tiers.py)

STEP = 1e-3  # [s] the product's physics step (motion.timestep)


@pytest.mark.parametrize("dry_share", [0.0, 0.5, 1.0])
def test_datasheet_fit_reproduces_all_four_figures_exactly(dry_share):
    ds = dataclasses.replace(POLOLU_MP_6V_30_1, dry_share=dry_share)
    m = ds.constants()
    assert m.R_M == pytest.approx(6.0 / 0.67, rel=1e-12)
    assert m.stall_torque_wheel(6.0) == pytest.approx(ds.stall_torque, rel=1e-12)
    assert m.stall_current(6.0) == pytest.approx(0.67, rel=1e-12)
    assert m.no_load_speed_wheel(6.0) == pytest.approx(720 * RPM, rel=1e-12)
    assert m.no_load_current(6.0) == pytest.approx(0.040, rel=1e-12)
    # by hand: K = (6 − 8.955·0.04)/(29.86·75.40) = 2.506e-3 N·m/A, K·I_0 = 1.0024e-4 N·m
    assert m.K == pytest.approx(2.506e-3, rel=1e-3)
    assert m.friction == pytest.approx(dry_share * 1.0024e-4, rel=1e-3)
    # η = 0.03236 / (29.86·(2.506e-3·0.67 − τ0)): 0.6455 all viscous, 0.6654 half, 0.6865 all dry
    assert m.efficiency == pytest.approx({0.0: 0.6455, 0.5: 0.6654, 1.0: 0.6865}[dry_share], rel=1e-3)
    # b_M = η·(1 − s)·K·I_0/ω_0, ω_0 = 29.86·75.40 rad/s: 2.874e-8, 1.481e-8, 0
    assert m.b_M == pytest.approx({0.0: 2.874e-8, 0.5: 1.481e-8, 1.0: 0.0}[dry_share], rel=2e-3, abs=1e-15)


def test_reverse_voltage_mirrors_the_motor_and_the_dead_band_holds_it():
    m = dataclasses.replace(POLOLU_MP_6V_30_1, dry_share=1.0).constants()
    assert m.no_load_speed_wheel(-6.0) == pytest.approx(-720 * RPM, rel=1e-12)
    assert m.stall_torque_wheel(-6.0) == pytest.approx(-POLOLU_MP_6V_30_1.stall_torque, rel=1e-12)
    u_0 = 0.040 * 6.0 / 0.67  # R·I_0 [V]: all of the no-load friction dry, the motor breaks away only above it
    assert m.no_load_speed_wheel(0.99 * u_0) == 0.0 and m.no_load_speed_wheel(-0.99 * u_0) == 0.0
    assert m.no_load_speed_wheel(1.01 * u_0) > 0.0 > m.no_load_speed_wheel(-1.01 * u_0)


@pytest.mark.parametrize("volts", [0.15, 0.3, 1.0, -1.0])
def test_low_voltage_in_mujoco_matches_the_closed_form_with_dry_friction(volts):
    """Near the dead band the dry friction decides: MuJoCo's frictionloss against the closed-form steady state, within
    1 % and 0.1 % of the no-load speed (MuJoCo's friction is soft: a held wheel creeps). The default motor's dead
    band is R·τ0/K = 8.955 Ω · 0.5 · 0.04 A = 0.179 V: 0.15 V stays put, above it the speed is the closed form's."""
    motor = POLOLU_MP_6V_30_1.constants()
    model = wheel_in_free_air(motor, STEP)
    data = mujoco.MjData(model)
    data.ctrl[0] = volts
    for _ in range(3000):
        mujoco.mj_step(model, data)
    expected = motor.no_load_speed_wheel(volts)
    assert abs(data.qvel[0] - expected) <= 0.01 * abs(expected) + 1e-3 * 720 * RPM
    assert (expected == 0.0) == (volts == 0.15)


@pytest.mark.parametrize("inductance", [0.5e-3, 0.0])
def test_free_air_voltage_step_matches_closed_form_within_1_percent(inductance):
    motor = POLOLU_MP_6V_30_1.constants().replace(L_M=inductance)
    dt = 2e-5  # resolve the electrical time constant L/R = 56 µs
    model = wheel_in_free_air(motor, dt)
    data = mujoco.MjData(model)
    data.ctrl[0] = 6.0
    n = int(0.3 / dt)
    t, speed, amps = np.empty(n), np.empty(n), np.empty(n)
    for k in range(n):
        mujoco.mj_step(model, data)
        t[k], speed[k], amps[k] = data.time, data.qvel[0], current(model, data, 0)
    wheel_inertia = model.body_inertia[1, 2]
    i_ref, w_ref = free_air_step(motor, 6.0, t, load_inertia=wheel_inertia)
    assert np.max(np.abs(speed - w_ref)) < 0.01 * w_ref[-1]
    assert np.max(np.abs(amps - i_ref)) < 0.01 * np.max(np.abs(i_ref))
    assert speed[-1] == pytest.approx(motor.no_load_speed_wheel(6.0), rel=1e-6)  # steady state exact
    assert amps[-1] == pytest.approx(motor.no_load_current(6.0), rel=1e-4)


def test_closed_form_starts_at_rest_and_reaches_steady_state():
    motor = POLOLU_MP_6V_30_1.constants()
    i, w = free_air_step(motor, 6.0, np.array([0.0, 5.0]))
    assert i[0] == pytest.approx(0.0, abs=1e-12) and w[0] == pytest.approx(0.0, abs=1e-12)
    assert w[1] == pytest.approx(motor.no_load_speed_wheel(6.0), rel=1e-9)
    assert i[1] == pytest.approx(0.040, rel=1e-9)


def test_field_edit_changes_the_running_motor_without_rebuild():
    base = POLOLU_MP_6V_30_1.constants()
    model = wheel_in_free_air(base, STEP)
    changed = base.replace(R_M=2 * base.R_M, b_M=1e-7, J_rotor=5 * base.J_rotor, efficiency=0.5,
                           friction=2 * base.friction)
    write_fields(model, [0], changed)
    back = read_fields(model, 0)
    for field in ("R_M", "L_M", "K", "b_M", "J_rotor", "gear", "efficiency", "friction"):
        assert getattr(back, field) == pytest.approx(getattr(changed, field), rel=1e-12), field
    data = mujoco.MjData(model)
    data.ctrl[0] = 6.0
    for _ in range(3000):
        mujoco.mj_step(model, data)
    assert data.qvel[0] == pytest.approx(changed.no_load_speed_wheel(6.0), rel=1e-6)
    assert current(model, data, 0) == pytest.approx(changed.no_load_current(6.0), rel=1e-4)


def test_switching_inductance_on_needs_a_rebuild():
    model = wheel_in_free_air(POLOLU_MP_6V_30_1.constants().replace(L_M=0.0), STEP)
    with pytest.raises(MotorError, match="L_M"):
        write_fields(model, [0], POLOLU_MP_6V_30_1.constants())


@pytest.mark.parametrize("field,value", [("R_M", 0.0), ("K", -1.0), ("gear", math.nan), ("b_M", -1e-9),
                                         ("efficiency", 0.0), ("efficiency", 1.01), ("friction", -1e-6)])
def test_bad_constants_are_refused_by_name(field, value):
    with pytest.raises(MotorError, match=f"motor.{field}"):
        POLOLU_MP_6V_30_1.constants().replace(**{field: value})


def test_inconsistent_datasheet_is_refused():
    with pytest.raises(MotorError, match="no ideal DC motor"):
        Datasheet(6.0, 1.0, 0.1, 100.0, 0.01, 30.0, 0.0, 0.0)
    with pytest.raises(MotorError, match="no-load current"):
        Datasheet(6.0, 0.01, 0.1, 100.0, 0.2, 30.0, 0.0, 0.0)
    with pytest.raises(MotorError, match="datasheet.no_load_current"):
        Datasheet(6.0, 0.01, 0.1, 100.0, None, 30.0, 0.0, 0.0).constants()


# --- the catalogue ---------------------------------------------------------------------------------------------

# datasheet figures as the cited sources print them: (no-load rpm, stall torque kg·mm, stall current A)
PRINTED = {
    "pololu-lp-6v-30": (450, 2.9, 0.36), "pololu-lp-6v-100": (130, 7.4, 0.36),  # datasheet Rev 2.0, p. 1
    "pololu-mp-6v-30": (720, 3.3, 0.67), "pololu-mp-6v-50": (420, 5.4, 0.67),  # product pages #2364 (3pi+ guide), #2365
    "pololu-hp-6v-30": (1000, 5.7, 1.6), "pololu-hpcb-6v-75": (430, 11, 1.5),
    # 3pi+ 32U4 User's Guide §5.3, the editions' table: Standard 720 rpm 0.33 kg·cm 0.67 A, Turtle 180 rpm 0.64 kg·cm
    # 0.36 A, Hyper 2100 rpm 0.25 kg·cm 1.5 A
    "3pi+-standard": (720, 3.3, 0.67), "3pi+-turtle": (180, 6.4, 0.36), "3pi+-hyper": (2100, 2.5, 1.5),
}
# maximum output power the sources print [W]: a linear DC motor gives τ_stall·Ω_0/4 at half its no-load speed
PRINTED_MAX_POWER = {"pololu-lp-6v-30": 0.31, "pololu-lp-6v-50": 0.29, "pololu-lp-6v-75": 0.29,
                     "pololu-lp-6v-100": 0.25, "pololu-lp-6v-150": 0.25, "pololu-mp-6v-50": 0.55,
                     "pololu-hpcb-6v-75": 1.3}


def test_catalogue_figures_are_the_datasheets():
    from motors.catalogue import CATALOGUE
    from motors.datasheet import RPM

    for name, (rpm, kg_mm, amps) in PRINTED.items():
        d = CATALOGUE[name]
        assert d.no_load_speed == pytest.approx(rpm * RPM, rel=1e-12)
        assert d.stall_torque == pytest.approx(kg_mm * 9.80665e-3, rel=1e-12)
        assert d.stall_current == amps and d.voltage == 6.0 and d.source


def test_catalogue_max_power_matches_the_printed_column():
    """An independent column: the printed maximum power against τ_stall·Ω_0/4 from the speed and torque, 12 %."""
    from motors.catalogue import CATALOGUE

    for name, watts in PRINTED_MAX_POWER.items():
        d = CATALOGUE[name]
        assert d.stall_torque * d.no_load_speed / 4 == pytest.approx(watts, rel=0.12), name


def test_every_catalogue_motor_fits_the_model_space_and_its_figures():
    from motors.catalogue import CATALOGUE
    from twin.model.partial_models import default_space

    space = default_space()
    for name, d in CATALOGUE.items():
        c = d.constants()
        assert c.stall_torque_wheel(d.voltage) == pytest.approx(d.stall_torque, rel=1e-9), name
        assert c.no_load_speed_wheel(d.voltage) == pytest.approx(d.no_load_speed, rel=1e-9), name
        space.update({"motor.R_M": c.R_M, "motor.K": c.K, "motor.b_M": c.b_M, "motor.gear": c.gear,
                      "motor.efficiency": c.efficiency, "motor.friction": c.friction})


# --- every catalogue motor in MuJoCo, at its datasheet's four points --------------------------------------------

# typed from the sources the catalogue cites: (volts, no-load rpm, no-load A, stall torque N·m, stall A);
# None: not published (the catalogue assumes the family's figure and says so)
KGMM, OZIN = 9.80665e-3, 0.00706155183333
DATASHEET_POINTS = {
    "pololu-mp-6v-30": (6, 720, 0.040, 3.3 * KGMM, 0.67),
    "pololu-lp-6v-30": (6, 450, 0.02, 2.9 * KGMM, 0.36), "pololu-lp-6v-50": (6, 270, 0.02, 4.4 * KGMM, 0.36),
    "pololu-lp-6v-75": (6, 180, 0.02, 6.4 * KGMM, 0.36), "pololu-lp-6v-100": (6, 130, 0.02, 7.4 * KGMM, 0.36),
    "pololu-lp-6v-150": (6, 90, 0.02, 11 * KGMM, 0.36),
    "pololu-mp-6v-50": (6, 420, 0.07, 5.4 * KGMM, 0.67), "pololu-mp-6v-75": (6, 290, 0.07, 7.8 * KGMM, 0.67),
    "pololu-mp-6v-100": (6, 220, 0.07, 9.4 * KGMM, 0.67),
    "pololu-hp-6v-30": (6, 1000, 0.1, 5.7 * KGMM, 1.6), "pololu-hp-6v-50": (6, 590, None, 8.6 * KGMM, 1.6),
    "pololu-hp-6v-100": (6, 310, None, 17 * KGMM, 1.6),
    "pololu-hpcb-6v-30": (6, 1100, 0.15, 4.5 * KGMM, 1.5), "pololu-hpcb-6v-50": (6, 650, 0.15, 7.4 * KGMM, 1.5),
    "pololu-hpcb-6v-75": (6, 430, 0.15, 11 * KGMM, 1.5), "pololu-hpcb-6v-15": (6, 2100, 0.1, 2.5 * KGMM, 1.5),
    "pololu-3pi-30": (9.25, 700, 0.06, 6 * OZIN, 0.54),
    "3pi+-standard": (6, 720, 0.040, 3.3 * KGMM, 0.67), "3pi+-turtle": (6, 180, 0.02, 6.4 * KGMM, 0.36),
    "3pi+-hyper": (6, 2100, 0.1, 2.5 * KGMM, 1.5),
}
HP_FAMILY_NO_LOAD_A = 0.1  # HP 6V 30:1's published figure, the catalogue's rule for HP ratios without one


@pytest.mark.parametrize("name", sorted(DATASHEET_POINTS))
@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_catalogue_motor_in_mujoco_meets_its_datasheet(name, direction):
    """No-load speed and stall torque within 2 %, no-load and stall currents within 10 %, at the 1 ms step."""
    from motors.catalogue import CATALOGUE

    volts, rpm, no_load_a, stall_nm, stall_a = DATASHEET_POINTS[name]
    d = CATALOGUE[name]
    assert d.voltage == volts and d.no_load_current_assumed == (no_load_a is None), name
    model = wheel_in_free_air(d.constants(), STEP, direction)
    got = measured_points(model, volts, stall_nm)
    assert got["no_load_speed"] == pytest.approx(rpm * RPM, rel=0.02)
    assert got["stall_torque"] == pytest.approx(stall_nm, rel=0.02)
    assert got["no_load_current"] == pytest.approx(no_load_a or HP_FAMILY_NO_LOAD_A, rel=0.10)
    assert got["stall_current"] == pytest.approx(stall_a, rel=0.10)


def test_default_motor_held_at_its_stall_torque_stands_and_draws_its_stall_current():
    """Held by its stall torque, it stands (MuJoCo's soft dry friction lets it creep at < 0.2 % of no-load speed)."""
    model = wheel_in_free_air(POLOLU_MP_6V_30_1.constants(), STEP)
    speed, amps = steady(model, 6.0, load=POLOLU_MP_6V_30_1.stall_torque)
    assert abs(speed) < 0.002 * 720 * RPM and amps == pytest.approx(0.67, rel=0.01)


def test_default_motor_no_load_draws_the_datasheets_40_mA():
    """Fails on the old model (one K, viscous b_M as the only loss): 0.263 A and 0.96 W at no-load speed."""
    model = wheel_in_free_air(POLOLU_MP_6V_30_1.constants(), STEP)
    data = mujoco.MjData(model)
    data.ctrl[0] = 6.0
    for _ in range(2000):
        mujoco.mj_step(model, data)
    assert current(model, data, 0) == pytest.approx(0.040, rel=0.02)
    assert 6.0 * current(model, data, 0) < 0.25  # [W]: was 0.96 W, all of it heating a lumped viscous loss


# Pololu Micro Metal Gearmotors datasheet (Rev 2.0, May 2018), performance summary, LP 6V rows "at maximum efficiency":
# (speed RPM, torque kg·mm, current A, output W). A fifth point on each curve, not used by the fit.
MAX_EFFICIENCY_POINTS = {
    "pololu-lp-6v-30": (320, 0.66, 0.11, 0.22), "pololu-lp-6v-50": (200, 1.0, 0.10, 0.20),
    "pololu-lp-6v-75": (140, 1.3, 0.10, 0.19), "pololu-lp-6v-100": (100, 1.7, 0.10, 0.17),
    "pololu-lp-6v-150": (67, 2.6, 0.11, 0.18),
}


@pytest.mark.parametrize("name", sorted(MAX_EFFICIENCY_POINTS))
def test_the_datasheets_maximum_efficiency_point_lies_on_the_models_curve(name):
    """At the printed torque the model (in MuJoCo) turns at the printed speed within 10 % and draws the printed current
    within 15 %: the datasheet's points lie a little off any straight torque-speed line (LP 30:1 turns 8 % slower
    there than the line through its own no-load and stall figures, 347.6 RPM by hand), so this is the model's error
    against the curve, stated, not an exact fit."""
    from motors.catalogue import CATALOGUE

    rpm, kg_mm, amps, watts = MAX_EFFICIENCY_POINTS[name]
    d = CATALOGUE[name]
    speed, current_a = steady(wheel_in_free_air(d.constants(), STEP), d.voltage, load=kg_mm * KGMM)
    assert speed == pytest.approx(rpm * RPM, rel=0.10)
    assert current_a == pytest.approx(amps, rel=0.15)
    assert speed * kg_mm * KGMM == pytest.approx(watts, rel=0.12)  # the printed output power
