"""The gearmotor (:class:`motors.constants.MotorConstants`) as a MuJoCo 4 general actuator, voltage the control.

MuJoCo's own ``dcmotor`` cannot hold a gearbox efficiency: it collapses ``motorconst=[Kt, Ke]`` into one
K = √(Kt·Ke) (same gain, same forces), so its torque-speed line and its current cannot both be right once η < 1
(its R could absorb η, R' = R/η, but then its current, and so the lap's energy, is η·i). The motor is therefore
the general actuator that the electrical and mechanical equations reduce to with the current algebraic:

    actuator: gear ±G (its length velocity is the motor shaft's speed ω_m), gaintype fixed, biastype affine,
        force at the motor shaft  η·K·i = η·K/R_M · v − η·K²/R_M · ω_m      (gainprm[0], biasprm[2])
        armature J_rotor, damping b_M (MuJoCo reflects both through gear², as a gearbox does)
    wheel joint: frictionloss += G·η·τ0, MuJoCo's dry friction, solved with the constraints (stable at 1 ms;
        ``DRY_FRICTION_SOLREF``)

so the wheel gets G·η·(K·i − τ0·sign Ω) − G²·b_M·Ω − G²·J_rotor·Ω̇, exactly. v is the winding voltage: with
L_M > 0 it is the control lagged by L_M/R_M (dyntype filterexact, actearly, so the lag is all there is: ≈ 56 µs, which
a 1 ms step cannot resolve; the current's true lag also feeds back the back-EMF, which this does not), with
L_M = 0 the control itself; switching between the two changes the model's state and needs a rebuild.

The constants are model fields, so a changed motor is a field edit (:func:`write_fields`); ``actuator_user`` holds
what the forces cannot give back: (R_M, the joint's own dry friction before the motor's), read by
:func:`read_fields` and by the C loop's energy (``lf_motor_power``: u·i with i = (v − K·ω_m)/R_M).
"""

from __future__ import annotations

import mujoco
import numpy as np

from motors.constants import MotorConstants, MotorError

USER_R_M, USER_JOINT_FRICTION, NUSER = 0, 1, 2  # actuator_user slots
# [s, -] the wheel joint's dry friction as stiff as a 1 ms step allows (MuJoCo's floor: 2 steps). MuJoCo's friction is
# soft: a wheel held at its stall torque creeps where the friction's force falls short of G·η·τ0, at 1 % of the no-load
# speed with MuJoCo's default 20 ms, 0.1 % with this
DRY_FRICTION_SOLREF = (0.002, 1.0)


def add_gearmotor(
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
      joint: name of the hinge joint the gearbox output drives (its own frictionloss is kept, the motor's added).
      motor: the motor's constants.
      direction: +1 or −1, so that a positive voltage turns the joint the way the caller wants.
      max_voltage: if given, the control (voltage) is clamped to ±max_voltage in [V].
    """
    if direction not in (1.0, -1.0, 1, -1):
        raise MotorError(f"actuator {name}: direction must be +1 or -1, got {direction!r}")
    hinge = spec.joint(joint)
    if hinge is None:
        raise MotorError(f"actuator {name}: no joint {joint!r} in the spec")
    act = spec.add_actuator(name=name, target=joint, trntype=mujoco.mjtTrn.mjTRN_JOINT)
    act.gaintype = mujoco.mjtGain.mjGAIN_FIXED
    act.biastype = mujoco.mjtBias.mjBIAS_AFFINE
    if motor.L_M > 0:
        act.dyntype = mujoco.mjtDyn.mjDYN_FILTEREXACT
        act.actearly = True
    act.gear[0] = direction * motor.gear
    act.userdata = [motor.R_M, float(hinge.frictionloss)]
    _set(act.gainprm, act.biasprm, act.dynprm, motor)
    act.armature = motor.J_rotor
    act.damping[0] = motor.b_M
    hinge.frictionloss = float(hinge.frictionloss) + _dry_friction(motor)
    hinge.solref_friction = list(DRY_FRICTION_SOLREF)
    if max_voltage is not None:
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = [-max_voltage, max_voltage]
    return act


def _dry_friction(motor: MotorConstants) -> float:
    """The motor's friction τ0 as the wheel feels it through the gearbox [N·m]."""
    return motor.gear * motor.efficiency * motor.friction


def _set(gainprm, biasprm, dynprm, motor: MotorConstants) -> None:
    gainprm[0] = motor.efficiency * motor.K / motor.R_M
    biasprm[0] = biasprm[1] = 0.0
    biasprm[2] = -motor.efficiency * motor.K**2 / motor.R_M
    dynprm[0] = motor.L_M / motor.R_M


def _check(model: mujoco.MjModel, i: int) -> None:
    if (model.actuator_gaintype[i] != mujoco.mjtGain.mjGAIN_FIXED
            or model.actuator_biastype[i] != mujoco.mjtBias.mjBIAS_AFFINE or model.nuser_actuator < NUSER):
        raise MotorError(f"actuator {i} is not a gearmotor of motors.actuator")


def write_fields(model: mujoco.MjModel, actuator_ids: list[int], motor: MotorConstants) -> None:
    """Write ``motor`` into compiled gearmotor actuators (and their joints' dry friction), keeping each gear's sign."""
    for i in actuator_ids:
        _check(model, i)
        if (model.actuator_actnum[i] > 0) != (motor.L_M > 0):
            raise MotorError(
                "motor.L_M: switching between zero and non-zero inductance changes the model structure; rebuild it"
            )
        _set(model.actuator_gainprm[i], model.actuator_biasprm[i], model.actuator_dynprm[i], motor)
        model.actuator_user[i, USER_R_M] = motor.R_M
        model.actuator_gear[i, 0] = np.sign(model.actuator_gear[i, 0]) * motor.gear
        model.actuator_armature[i] = motor.J_rotor
        model.actuator_damping[i] = motor.b_M
        dof = model.jnt_dofadr[model.actuator_trnid[i, 0]]
        model.dof_frictionloss[dof] = model.actuator_user[i, USER_JOINT_FRICTION] + _dry_friction(motor)


def read_fields(model: mujoco.MjModel, actuator_id: int) -> MotorConstants:
    """The constants a compiled gearmotor actuator holds."""
    i = actuator_id
    _check(model, i)
    R = float(model.actuator_user[i, USER_R_M])
    gain, slope = float(model.actuator_gainprm[i, 0]), float(model.actuator_biasprm[i, 2])
    K = -slope / gain
    eta = gain * R / K
    eta = 1.0 if 1.0 < eta < 1.0 + 1e-9 else eta  # η = 1 read back through two divisions
    G = float(abs(model.actuator_gear[i, 0]))
    dof = model.jnt_dofadr[model.actuator_trnid[i, 0]]
    dry = float(model.dof_frictionloss[dof]) - float(model.actuator_user[i, USER_JOINT_FRICTION])
    return MotorConstants(
        R_M=R,
        L_M=float(model.actuator_dynprm[i, 0]) * R if model.actuator_actnum[i] > 0 else 0.0,
        K=K,
        b_M=float(model.actuator_damping[i]),
        J_rotor=float(model.actuator_armature[i]),
        gear=G,
        efficiency=eta,
        friction=dry / (G * eta),
    )


def current(model: mujoco.MjModel, data: mujoco.MjData, actuator_id: int) -> float:
    """The winding current i = (v − K·ω_m)/R_M in [A] (the C loop's ``lf_motor_power`` divides by the same)."""
    i = actuator_id
    if model.actuator_actnum[i] > 0:
        v = float(data.act[model.actuator_actadr[i]])
    else:
        v = float(data.ctrl[i])
        if model.actuator_ctrllimited[i]:
            v = float(np.clip(v, *model.actuator_ctrlrange[i]))
    K = -model.actuator_biasprm[i, 2] / model.actuator_gainprm[i, 0]
    return (v - K * float(data.actuator_velocity[i])) / float(model.actuator_user[i, USER_R_M])
