"""Motion model: Eqs. 1–3 against MuJoCo's contact dynamics, and tyre friction that governs slip."""

import mujoco
import numpy as np
import pytest

from mjcf.world import AXLE_SITE, CASTER_MU, MOTORS
from twin.core.digital_twin import DigitalTwin

pytestmark = pytest.mark.quick  # the whole module is in the quick tier (tests/test_tiers.py)


@pytest.fixture
def twin():
    """A twin of its own per test: tests set motion.mu on it (the robot and texture come from the disk cache)."""
    return DigitalTwin(track="circle")


def run(twin, voltages, seconds, after):
    """Step with constant voltages; per step after ``after`` seconds: (v, v_eq1, ω, ω_eq2, v_sideways).

    v is the axle midpoint's velocity along the heading, v_sideways across it (Eq. 3: zero)."""
    model = twin.model()
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("start").id)
    data.ctrl[[model.actuator(n).id for n in MOTORS]] = voltages
    info = twin.info
    site = model.site(AXLE_SITE).id
    dofs = [model.jnt_dofadr[model.joint(j).id] for j in info.wheel_joints]
    rows = []
    vel = np.zeros(6)
    for _ in range(int(seconds / model.opt.timestep)):
        mujoco.mj_step(model, data)
        if data.time < after:
            continue
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_SITE, site, vel, 0)
        heading = data.site_xmat[site].reshape(3, 3)[:, 0]
        tl, tr = (data.qvel[d] * s for d, s in zip(dofs, info.wheel_directions))
        R, L = info.wheel_radius, info.half_track
        left = data.site_xmat[site].reshape(3, 3)[:, 1]
        rows.append((vel[3:] @ heading, R * (tr + tl) / 2, vel[2], R * (tr - tl) / (2 * L), vel[3:] @ left))
    return np.array(rows)


@pytest.mark.parametrize("caster_mu", [0.0, CASTER_MU])  # the default free caster, and a plastic ball's resistance
@pytest.mark.parametrize("mu", [0.9, 1.5])  # the product's default grip, and a grippy tyre
@pytest.mark.parametrize("voltages", [(3.0, 3.0), (2.0, 4.0), (4.0, 1.5), (-2.0, 2.0)])
def test_eqs_1_to_3_hold_without_slip_within_2_percent(twin, voltages, mu, caster_mu):
    twin.set("motion.mu", mu)
    twin.set("motion.caster_mu", caster_mu)
    rows = run(twin, voltages, seconds=2.0, after=1.0)
    v, v_eq, w, w_eq, v_side = rows.T
    assert np.max(np.abs(v_side)) <= 0.02 * max(np.abs(v_eq).max(), 0.05)  # Eq. 3: no sideways motion
    scale_v = max(np.abs(v_eq).max(), 1e-3)
    # within 2 % of the wheels' rim speed (a spin in place has v_eq near 0): the tyres creep under the caster's
    # rolling resistance in MuJoCo's soft contacts: 1.1-1.5 % at CASTER_MU, 0.1 % with a free caster
    rim = max(np.abs(v_eq).max(), twin.info.half_track * np.abs(w_eq).max())
    assert np.max(np.abs(v - v_eq)) <= 0.02 * rim
    if abs(voltages[0] - voltages[1]) > 0:
        assert np.max(np.abs(w - w_eq)) <= 0.02 * np.abs(w_eq).max()
    else:
        assert np.max(np.abs(w)) < 1e-3 and np.abs(v - v_eq).max() <= 0.02 * scale_v


def slip_after_step(twin, mu):
    """Peak wheel slip in the first 0.3 s after a 1.5 V step: a launch of ~0.5 g, within reach of μ >= 0.5.

    (At 6 V the stall force is ~2 g and the tyres spin at any realistic μ, as a real 3pi+ would.)"""
    twin.set("motion.mu", mu)
    rows = run(twin, (1.5, 1.5), seconds=0.3, after=0.0)
    v, v_eq = rows[:, 0], rows[:, 1]
    return float(np.max(v_eq - v))  # wheel surface speed ahead of the chassis, [m/s]


def test_lowering_tyre_mu_makes_the_wheels_slip(twin):
    grippy, medium, slippery = (slip_after_step(twin, mu) for mu in (1.0, 0.2, 0.05))
    assert grippy < 0.06  # a 5 cm/s transient while the chassis pitches at launch, independent of μ
    assert slip_after_step(twin, 2.0) == pytest.approx(grippy, rel=1e-6)  # no more grip to gain
    assert grippy < medium < slippery and slippery > 4 * grippy


def test_tyre_friction_governs_not_the_floor(twin):
    twin.set("motion.mu", 0.05)
    twin.set("motion.floor_mu", 2.0)  # MuJoCo's default "max of the two" would hide the tyre's μ
    try:
        assert slip_after_step(twin, 0.05) > 0.1
    finally:
        twin.set("motion.floor_mu", 0.6)


@pytest.mark.parametrize("caster_mu", [CASTER_MU / 2, CASTER_MU])
def test_a_coast_down_slows_at_the_casters_rolling_resistance(caster_mu):
    """The robot rolling at 0.5 m/s with its motors cut (no torque, no friction of their own) slows only by its
    ball caster's rolling resistance F = mu_c N_c (mjcf.world.CASTER_MU), at a constant rate from the closed form of
    the robot's balance: horizontally m_eff a = mu_c N_c, with m_eff = m + sum(I_wheel + J_rotor G^2)/R^2; the
    moments about the wheels' contact line, m g d - x_c N_c = -a (m h + 2 I_wheel / R) (the centre of mass d ahead of
    the axle and h above the floor, the caster's contact x_c ahead). So a = mu_c m g d / (x_c m_eff - mu_c (m h +
    2 I_wheel / R)). Masses and places from the model; within 1 % (MuJoCo's soft contacts: measured 0.06 %)."""
    twin = DigitalTwin(track="oval")
    twin.set("motion.caster_mu", caster_mu)
    model, info = twin.model(), twin.info
    wheels = [model.joint(j).id for j in info.wheel_joints]
    dofs = [model.jnt_dofadr[j] for j in wheels]
    motors = [model.actuator(n).id for n in MOTORS]
    model.actuator_gainprm[motors] = 0.0
    model.actuator_biasprm[motors] = 0.0
    model.actuator_damping[motors] = 0.0
    model.dof_frictionloss[dofs] = 0.0
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("start").id)
    mujoco.mj_forward(model, data)
    root = model.body(info.root_body).id
    R, v0, g = info.wheel_radius, 0.5, 9.81
    heading = data.xmat[root].reshape(3, 3)[:, 0]
    data.qvel[:3] = v0 * heading
    for d, s in zip(dofs, info.wheel_directions):
        data.qvel[d] = s * v0 / R
    # the closed form's inputs: masses, inertias and places from the model
    m = float(model.body_subtreemass[root])
    axle = data.site(AXLE_SITE).xpos
    com = data.subtree_com[root] - axle
    d = float(com @ heading)
    h = float(data.subtree_com[root][2])
    caster = data.geom(info.caster_geoms[0])
    x_c = float((caster.xpos - axle) @ heading)
    wheel_bodies = [model.jnt_bodyid[j] for j in wheels]
    i_wheel = float(np.mean([model.body_inertia[b].max() for b in wheel_bodies]))  # about its axle (the largest)
    motor = twin.motor()
    j_reflected = motor.J_rotor * motor.gear ** 2
    m_eff = m + 2 * (i_wheel + j_reflected) / R ** 2
    expected = caster_mu * m * g * d / (x_c * m_eff - caster_mu * (m * h + 2 * i_wheel / R))
    site = model.site(AXLE_SITE).id
    vel, speeds = np.zeros(6), []
    for _ in range(int(0.8 / model.opt.timestep)):
        mujoco.mj_step(model, data)
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_SITE, site, vel, 0)
        speeds.append(vel[3:] @ heading)
    t = np.arange(1, len(speeds) + 1) * model.opt.timestep
    keep = t > 0.1  # past the contacts' settling
    slope = -np.polyfit(t[keep], np.array(speeds)[keep], 1)[0]
    assert slope == pytest.approx(expected, rel=0.01), (slope, expected, d, h, x_c, m, m_eff)
    assert np.array(speeds)[-1] > 0.1  # still rolling: the rate was measured in motion
