"""The motor driver's supply (twin.model.power): the closed forms by hand, the C loop against its reference every
physics step, and the 3pi's regulator against what its user's guide says it does."""

import math

import mujoco
import numpy as np
import pytest

from mjcf.world import MOTORS, START_KEY
from twin.core import native as core
from twin.core.closed_loop import run_laps, setup, start_phase
from twin.core.digital_twin import DigitalTwin
from twin.errors import TwinError
from twin.model.control import RUN
from twin.model.power import Power
from twin.model.robots import THREE_PI, use_robot

R_M = 6.0 / 0.67  # [Ω] the default motor's winding (stall current 0.67 A at 6 V)


@pytest.mark.quick
def test_the_battery_sags_by_hand():
    """Both motors held (no back-EMF) at full duty on 6 V behind 0.12 Ω: v = 6/(1 + 0.12·2/8.955) = 5.8434 V by hand;
    a motor turning faster than its duty's share would feed the battery: it is left out (a one-motor circuit)."""
    p = Power(battery_v=6.0, source_ohm=0.12)
    v, terminal = p.bus_voltage((1.0, 1.0), (0.0, 0.0), (R_M, R_M))
    assert v == pytest.approx(5.8434, abs=1e-4) and terminal == v
    # one motor at half duty with back-EMF 4 V would return current (0.5·(0.5·v − 4) < 0): only the other draws,
    # v = 6/(1 + 0.12/8.955) = 5.9207 V
    v, _ = p.bus_voltage((1.0, 0.5), (0.0, 4.0), (R_M, R_M))
    assert v == pytest.approx(5.9207, abs=1e-4)
    assert Power(battery_v=6.0, source_ohm=0.0).bus_voltage((1.0, 1.0), (0.0, 0.0), (R_M, R_M)) == (6.0, 6.0)


@pytest.mark.quick
def test_the_regulator_holds_its_voltage_until_its_input_falls_below_its_minimum():
    """The 3pi: 9.25 V out while the battery's terminal voltage t stays ≥ 3.5 V. Both 3pi motors held at full duty
    draw P = 2·9.25²/17.13 = 9.99 W; from 4.8 V behind 0.12 Ω, t = (4.8 + √(4.8² − 4·0.12·9.99))/2 = 4.536 V by hand;
    from 3.8 V behind 0.5 Ω the discriminant 3.8² − 4·0.5·9.99 < 0: no terminal voltage gives that power, it shuts off."""
    r = 9.25 / 0.54
    p = Power(battery_v=4.8, source_ohm=0.12, regulator_v=9.25, regulator_min_input_v=3.5)
    v, terminal = p.bus_voltage((1.0, 1.0), (0.0, 0.0), (r, r))
    assert v == 9.25 and terminal == pytest.approx(4.536, abs=1e-3)
    weak = Power(battery_v=3.8, source_ohm=0.5, regulator_v=9.25, regulator_min_input_v=3.5)
    assert weak.bus_voltage((1.0, 1.0), (0.0, 0.0), (r, r))[0] == 0.0
    assert weak.bus_voltage((0.0, 0.0), (0.0, 0.0), (r, r)) == (9.25, 3.8)  # at rest it runs
    assert not Power(battery_v=3.4, regulator_v=9.25, regulator_min_input_v=3.5).starts()


@pytest.mark.parametrize("field,value,address", [("source_ohm", -0.1, "power.source_resistance"),
                                                 ("battery_v", math.nan, "motor.supply_voltage"),
                                                 ("regulator_min_input_v", 10.0, "power.regulator_min_input")])
def test_bad_power_is_refused_naming_its_address(field, value, address):
    values = dict(battery_v=4.8, source_ohm=0.12, regulator_v=9.25, regulator_min_input_v=3.5)
    values[field] = value
    with pytest.raises(TwinError, match=address.replace(".", r"\.")):
        Power(**values)


@pytest.mark.quick
def test_each_physics_step_drives_the_sagging_supply_the_reference_gives():
    """The C loop's lf_bus_voltage against Power.bus_voltage, every step of a line-following start, with a 1 Ω
    source (eight times the default, so the sag is large): to 1e-12 V."""
    twin = DigitalTwin()
    model = twin.model()
    core.install_callback()
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(START_KEY).id)
    params = twin.control_params()
    power = Power(battery_v=twin.physics().supply_voltage, source_ohm=1.0)
    sim = setup(data.userdata, model, twin, params, twin.sensor_model(), 3, power=power)
    for i in range(params.count):
        sim.fw.cal_min[i], sim.fw.cal_max[i] = 200, 2300
    start_phase(sim, RUN)
    motors = [model.actuator(n).id for n in MOTORS]
    dofs = [model.jnt_dofadr[model.actuator_trnid[a, 0]] for a in motors]
    motor = twin.motor()
    sags = []
    for _ in range(400):
        # the back-EMF the step's control sees: K·ω_m, ω_m = gear·qvel at the step's start
        emf = [motor.K * model.actuator_gear[a, 0] * data.qvel[d] for a, d in zip(motors, dofs)]
        duty_now, duty_next, pending = list(sim.duty_now), list(sim.duty_next), sim.pending
        apply_s, t = sim.apply_time_s, data.time
        mujoco.mj_step(model, data)
        if pending and apply_s < t + model.opt.timestep:  # a blend in this step (lf_drive)
            share = max(0.0, (apply_s - t) / model.opt.timestep)
            duty = [share * a + (1 - share) * b for a, b in zip(duty_now, duty_next)]
        else:
            duty = duty_now
        v, _ = power.bus_voltage(duty, emf, (motor.R_M, motor.R_M))
        np.testing.assert_allclose([data.ctrl[a] for a in motors], [d * v for d in duty], rtol=0, atol=1e-12)
        sags.append(power.battery_v - v)
    assert max(sags) > 0.1  # the test can tell a sagging supply from a stiff one
    assert sim.terminal_min_v == pytest.approx(power.battery_v - max(sags), abs=1e-12)


@pytest.fixture(scope="module")
def three_pi():
    twin = DigitalTwin()
    use_robot(twin, THREE_PI)
    return twin


def test_the_3pi_laps_alike_on_a_full_and_a_tired_pack(three_pi):
    """Pololu 3pi Robot User's Guide §5.b: "the motors will run the same speed as the batteries drop from 5.5 down to
    3.5 V": the same lap at 5.5 V and at 4.0 V (four NiMH cells at the end of their discharge), bit for bit; with no
    regulator (the default robot) a 4.8 V battery laps slower than a 5.5 V one (at 4.0 V its timed calibration turn falls
    short: the motors' dead band takes a larger share of 15 % duty)."""
    full, tired = run_laps(three_pi, [{"motor.supply_voltage": 5.5}, {"motor.supply_voltage": 4.0}], keep_traces=False)
    assert full.completed and tired.completed and full.lap_time_s == tired.lap_time_s
    twin = DigitalTwin()
    plain_full, plain_tired = run_laps(twin, [{"motor.supply_voltage": 5.5}, {"motor.supply_voltage": 4.8}],
                                       keep_traces=False)
    assert plain_tired.lap_time_s > plain_full.lap_time_s + 1.0


def test_the_3pi_shuts_off_below_its_regulators_input(three_pi):
    """"Instead of gradually running out of power like most robots, the 3pi will operate at maximum performance
    until it suddenly shuts off" (ibid.): below 3.5 V it does not start; a pack that sags below it under load (3.7 V
    behind 1 Ω) shuts off on the way, and each lap says so."""
    dead, sagging = run_laps(three_pi, [{"motor.supply_voltage": 3.4},
                                        {"motor.supply_voltage": 3.7, "power.source_resistance": 1.0}],
                             keep_traces=False)
    assert dead.failure == "power" and dead.simulated_s == 0.0 and "power.regulator_min_input" in dead.detail
    assert sagging.failure == "power" and "shut off" in sagging.detail and "3.5 V" in sagging.detail
