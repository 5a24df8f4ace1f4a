"""DC motor model (Eqs. 6–7): datasheet fit, and MuJoCo's dcmotor against the closed-form solution."""

import math

import mujoco
import numpy as np
import pytest

from motors import POLOLU_MP_6V_30_1, Datasheet, MotorConstants, MotorError
from motors.actuator import add_dcmotor, read_fields, write_fields
from motors.analytic import free_air_step
from motors.datasheet import RPM

pytestmark = pytest.mark.quick  # the whole module is in the quick tier (tests/test_tiers.py)


def wheel_in_free_air(motor: MotorConstants, timestep: float) -> mujoco.MjModel:
    spec = mujoco.MjSpec()
    spec.option.timestep = timestep
    body = spec.worldbody.add_body(name="wheel")
    body.add_joint(name="axle", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1])
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.016, 0.0035, 0], mass=0.005)
    add_dcmotor(spec, "motor", "axle", motor)
    return spec.compile()


def test_datasheet_fit_reproduces_stall_torque_and_no_load_speed_exactly():
    ds = POLOLU_MP_6V_30_1
    m = ds.constants()
    assert m.R_M == pytest.approx(6.0 / 0.67, rel=1e-12)
    assert m.stall_torque_wheel(6.0) == pytest.approx(ds.stall_torque, rel=1e-12)
    assert m.no_load_speed_wheel(6.0) == pytest.approx(720 * RPM, rel=1e-12)
    # gearbox losses lumped into b_M raise the model's no-load current above the datasheet's 40 mA
    assert ds.derived_no_load_current() > ds.no_load_current


@pytest.mark.parametrize("inductance", [0.5e-3, 0.0])
def test_free_air_voltage_step_matches_closed_form_within_1_percent(inductance):
    motor = POLOLU_MP_6V_30_1.constants().replace(L_M=inductance)
    dt = 2e-5  # the electrical time constant L/R is 56 µs: resolve it
    model = wheel_in_free_air(motor, dt)
    data = mujoco.MjData(model)
    data.ctrl[0] = 6.0
    n = int(0.3 / dt)
    t, speed, current = np.empty(n), np.empty(n), np.empty(n)
    for k in range(n):
        mujoco.mj_step(model, data)
        t[k], speed[k] = data.time, data.qvel[0]
        # with inductance the current is the actuator's state; without, it is algebraic (force = K i)
        current[k] = data.act[0] if model.na else data.actuator_force[0] / motor.K
    wheel_inertia = model.body_inertia[1, 2]
    i_ref, w_ref = free_air_step(motor, 6.0, t, load_inertia=wheel_inertia)
    assert np.max(np.abs(speed - w_ref)) < 0.01 * w_ref[-1]
    assert np.max(np.abs(current - i_ref)) < 0.01 * np.max(np.abs(i_ref))
    assert speed[-1] == pytest.approx(motor.no_load_speed_wheel(6.0), rel=1e-9)  # steady state exact
    assert current[-1] == pytest.approx(motor.no_load_current(6.0), rel=1e-9)


def test_closed_form_starts_at_rest_and_reaches_steady_state():
    motor = POLOLU_MP_6V_30_1.constants()
    i, w = free_air_step(motor, 6.0, np.array([0.0, 5.0]))
    assert i[0] == pytest.approx(0.0, abs=1e-12) and w[0] == pytest.approx(0.0, abs=1e-12)
    assert w[1] == pytest.approx(motor.no_load_speed_wheel(6.0), rel=1e-9)


def test_field_edit_changes_the_running_motor_without_rebuild():
    base = POLOLU_MP_6V_30_1.constants()
    model = wheel_in_free_air(base, 1e-3)
    changed = base.replace(R_M=2 * base.R_M, b_M=3 * base.b_M, J_rotor=5 * base.J_rotor)
    write_fields(model, [0], changed)
    assert read_fields(model, 0) == changed
    data = mujoco.MjData(model)
    data.ctrl[0] = 6.0
    for _ in range(3000):
        mujoco.mj_step(model, data)
    assert data.qvel[0] == pytest.approx(changed.no_load_speed_wheel(6.0), rel=1e-6)


def test_switching_inductance_on_needs_a_rebuild():
    model = wheel_in_free_air(POLOLU_MP_6V_30_1.constants().replace(L_M=0.0), 1e-3)
    with pytest.raises(MotorError, match="L_M"):
        write_fields(model, [0], POLOLU_MP_6V_30_1.constants())


@pytest.mark.parametrize("field,value", [("R_M", 0.0), ("K", -1.0), ("gear", math.nan), ("b_M", -1e-9)])
def test_bad_constants_are_refused_by_name(field, value):
    with pytest.raises(MotorError, match=f"motor.{field}"):
        POLOLU_MP_6V_30_1.constants().replace(**{field: value})


def test_inconsistent_datasheet_is_refused():
    with pytest.raises(MotorError, match="no ideal DC motor"):
        Datasheet(6.0, 1.0, 0.1, 100.0, 0.01, 30.0, 0.0, 0.0)


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
        space.update({"motor.R_M": c.R_M, "motor.K": c.K, "motor.b_M": c.b_M, "motor.gear": c.gear})
