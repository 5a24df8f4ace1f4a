"""Motion model: Eqs. 1–3 against MuJoCo's contact dynamics, and tyre friction that governs slip."""

import mujoco
import numpy as np
import pytest

from mjcf.world import AXLE_SITE, MOTORS
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


@pytest.mark.parametrize("mu", [0.9, 1.5])  # the product's default grip, and a grippy tyre
@pytest.mark.parametrize("voltages", [(3.0, 3.0), (2.0, 4.0), (4.0, 1.5), (-2.0, 2.0)])
def test_eqs_1_to_3_hold_without_slip_within_2_percent(twin, voltages, mu):
    twin.set("motion.mu", mu)
    rows = run(twin, voltages, seconds=2.0, after=1.0)
    v, v_eq, w, w_eq, v_side = rows.T
    assert np.max(np.abs(v_side)) <= 0.02 * max(np.abs(v_eq).max(), 0.05)  # Eq. 3: no sideways motion
    scale_v = max(np.abs(v_eq).max(), 1e-3)
    assert np.max(np.abs(v - v_eq)) <= 0.02 * max(np.abs(v_eq).max(), 0.02 * 0.5) + 1e-4
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
