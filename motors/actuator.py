"""Eqs. 6–7 as MuJoCo 4's native ``dcmotor`` actuator, with voltage as the control input.

Mapping (MuJoCo XML reference, actuator/dcmotor): ``resistance`` = R_M, ``motorconst`` = (K, K),
``inductance`` = (L_M, 0) which adds the current as the actuator's activation, ``gear`` = ±G,
``armature`` = J_rotor and ``damping`` = b_M (both reflected through gear², as a gearbox does).
After compilation the constants live in model fields, so a changed R_M, K, b_M or J_rotor is a field
edit (:func:`write_fields`), which a ``mujoco.batch`` can hold per simulation. Switching L_M between
zero and non-zero changes the model's activation count and needs a rebuild.
"""

from __future__ import annotations

import mujoco
import numpy as np

from motors.constants import MotorConstants, MotorError


def add_dcmotor(
    spec: mujoco.MjSpec,
    name: str,
    joint: str,
    motor: MotorConstants,
    direction: float = 1.0,
    max_voltage: float | None = None,
) -> mujoco.MjsActuator:
    """Add a voltage-driven DC gearmotor on a hinge joint.

    Args:
      spec: the spec to add to.
      name: actuator name.
      joint: name of the hinge joint the gearbox output drives.
      motor: constants of Eqs. 6–7.
      direction: +1 or −1, so that a positive voltage turns the joint the way the caller wants.
      max_voltage: if given, the control (voltage) is clamped to ±max_voltage in [V].
    """
    if direction not in (1.0, -1.0, 1, -1):
        raise MotorError(f"actuator {name}: direction must be +1 or -1, got {direction!r}")
    act = spec.add_actuator(name=name, target=joint, trntype=mujoco.mjtTrn.mjTRN_JOINT)
    act.set_to_dcmotor(motorconst=[motor.K, motor.K], resistance=motor.R_M, inductance=[motor.L_M, 0.0])
    act.gear[0] = direction * motor.gear
    act.armature = motor.J_rotor
    act.damping[0] = motor.b_M
    if max_voltage is not None:
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = [-max_voltage, max_voltage]
    return act


def write_fields(model: mujoco.MjModel, actuator_ids: list[int], motor: MotorConstants) -> None:
    """Write ``motor`` into compiled dcmotor actuators, keeping each one's gear sign."""
    for i in actuator_ids:
        if model.actuator_gaintype[i] != mujoco.mjtGain.mjGAIN_DCMOTOR:
            raise MotorError(f"actuator {i} is not a dcmotor")
        has_current = model.actuator_actnum[i] > 0
        if has_current != (motor.L_M > 0):
            raise MotorError(
                "motor.L_M: switching between zero and non-zero inductance changes the model structure; rebuild it"
            )
        model.actuator_gainprm[i, 0] = motor.R_M
        model.actuator_gainprm[i, 1] = motor.K
        if has_current:
            model.actuator_dynprm[i, 0] = motor.L_M / motor.R_M
        model.actuator_gear[i, 0] = np.sign(model.actuator_gear[i, 0]) * motor.gear
        model.actuator_armature[i] = motor.J_rotor
        model.actuator_damping[i] = motor.b_M


def read_fields(model: mujoco.MjModel, actuator_id: int) -> MotorConstants:
    """The constants a compiled dcmotor actuator holds."""
    i = actuator_id
    R = float(model.actuator_gainprm[i, 0])
    L = float(model.actuator_dynprm[i, 0]) * R if model.actuator_actnum[i] > 0 else 0.0
    return MotorConstants(
        R_M=R,
        L_M=L,
        K=float(model.actuator_gainprm[i, 1]),
        b_M=float(model.actuator_damping[i]),
        J_rotor=float(model.actuator_armature[i]),
        gear=float(abs(model.actuator_gear[i, 0])),
    )
