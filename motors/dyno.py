"""A gearmotor on a test bench in MuJoCo: its datasheet's four points measured as a datasheet measures them.

One wheel on the motor's output, free in the air or held back by a constant load torque; the no-load point is the
steady state at the rated voltage, the stall point is where the torque-speed and torque-current lines through two
loaded points reach zero speed (a datasheet's stall torque is such an extrapolation too). Used by tests/test_motors.py
and benchmarks/bench_motors.py, at the product's 1 ms step.
"""

from __future__ import annotations

import mujoco
import numpy as np

from motors.actuator import add_gearmotor, current
from motors.constants import MotorConstants

STEP_S = 1e-3  # [s] the product's physics step (motion.timestep)


def wheel_in_free_air(motor: MotorConstants, timestep: float = STEP_S, direction: float = 1.0) -> mujoco.MjModel:
    """A 5 g, 16 mm wheel on the motor's output shaft, nothing else."""
    spec = mujoco.MjSpec()
    spec.option.timestep = timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST  # as mjcf.world
    body = spec.worldbody.add_body(name="wheel")
    body.add_joint(name="axle", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1])
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.016, 0.0035, 0], mass=0.005)
    add_gearmotor(spec, "motor", "axle", motor, direction=direction)
    return spec.compile()


def steady(model: mujoco.MjModel, volts: float, load: float = 0.0, seconds: float = 2.0) -> tuple[float, float]:
    """(wheel speed [rad/s], current [A]) after ``seconds`` at ``volts`` against a load torque ``load`` [N·m]."""
    data = mujoco.MjData(model)
    data.ctrl[0] = volts
    sign = np.sign(model.actuator_gear[0, 0])
    data.qfrc_applied[0] = -sign * load  # opposes the way the voltage turns the wheel
    for _ in range(int(round(seconds / model.opt.timestep))):
        mujoco.mj_step(model, data)
    return float(sign * data.qvel[0]), current(model, data, 0)


def measured_points(model: mujoco.MjModel, volts: float, stall_guess: float) -> dict[str, float]:
    """The four datasheet points measured in MuJoCo: free at ``volts`` [V]; the stall point through loads of 30 % and
    60 % of ``stall_guess`` [N·m]. Keys: no_load_speed [rad/s], no_load_current [A], stall_torque [N·m],
    stall_current [A]."""
    speed0, amps0 = steady(model, volts)
    (w1, i1), (w2, i2) = steady(model, volts, 0.3 * stall_guess), steady(model, volts, 0.6 * stall_guess)
    t1, t2 = 0.3 * stall_guess, 0.6 * stall_guess
    stall = t1 + (t2 - t1) * w1 / (w1 - w2)
    return {"no_load_speed": speed0, "no_load_current": amps0, "stall_torque": stall,
            "stall_current": i1 + (i2 - i1) * w1 / (w1 - w2)}
