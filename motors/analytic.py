"""Closed forms of the gearmotor model: the references the MuJoCo actuator is tested against.

Datasheet points (steady state, :class:`motors.constants.MotorConstants`): no-load speed and current, stall torque
(where the torque-speed line reaches zero speed) and stall current.

Voltage step from rest, with everything referred to the motor shaft (J = J_rotor + J_load/G², b = b_M + b_load/G²)
and the winding voltage v lagging the applied U by τ_e = L_M/R_M (:mod:`motors.actuator`):

    τ_e v' = U − v,    J ω' = η·K/R·(v − K·ω) − η·τ0 − b·ω,    i = (v − K·ω)/R

Once the rotor turns forward the dry friction is a constant torque, so the system is linear with a constant input,
x' = A x + c, and its solution x(t) = x_ss + exp(A t)(x_0 − x_ss) is exact, with exp(A t) of the 2×2 matrix written
out through its eigenvalues (Sylvester's formula); no numerical integration is involved. With L_M = 0, v = U and
the speed is first order. Valid while the motor's torque exceeds its friction from the first instant (U/R > τ0/K,
the no-load current: every motor at its rated voltage).
"""

from __future__ import annotations

import numpy as np

from motors.constants import MotorConstants


def _expm2(A: np.ndarray, t: np.ndarray) -> np.ndarray:
    """exp(A t) for a real 2×2 matrix A and times t of shape (n,); returns (n, 2, 2)."""
    tr, det = np.trace(A), np.linalg.det(A)
    disc = complex(tr * tr / 4.0 - det) ** 0.5
    l1, l2 = tr / 2.0 + disc, tr / 2.0 - disc
    t = np.asarray(t, dtype=float)[:, None, None]
    eye = np.eye(2)
    if abs(l1 - l2) < 1e-9 * max(1.0, abs(l1)):  # repeated eigenvalue
        lam = l1.real
        return np.exp(lam * t) * ((1.0 - lam * t) * eye + t * A)
    e1, e2 = np.exp(l1 * t), np.exp(l2 * t)
    out = (l1 * e2 - l2 * e1) / (l1 - l2) * eye + (e1 - e2) / (l1 - l2) * A
    return out.real


def free_air_step(
    motor: MotorConstants,
    voltage: float,
    t: np.ndarray,
    load_inertia: float = 0.0,
    load_damping: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Current and wheel speed after a voltage step at t = 0 from rest.

    Args:
      motor: the motor's constants.
      voltage: step voltage U in [V], above the no-load current's R·I_0 (the rotor breaks away at once).
      t: times in [s], shape (n,).
      load_inertia: inertia on the wheel side (wheel about its axle) in [kg·m²].
      load_damping: viscous damping on the wheel side in [N·m·s/rad].

    Returns:
      (current in [A], wheel speed θ̇ = ω_m / G in [rad/s]), each of shape (n,).
    """
    G, eta = motor.gear, motor.efficiency
    J = motor.J_rotor + load_inertia / G**2  # everything referred to the motor shaft
    b = motor.b_M + load_damping / G**2
    R, K, tau_e = motor.R_M, motor.K, motor.electrical_time_constant_s
    drive = eta * K / R  # [N·m/V] motor torque per winding volt
    slope = eta * K * K / R + b  # [N·m·s/rad] torque lost per motor-shaft speed
    t = np.asarray(t, dtype=float)
    omega_ss = (drive * voltage - eta * motor.friction) / slope
    if tau_e == 0.0:
        omega = omega_ss * (1.0 - np.exp(-t * slope / J))
        return (voltage - K * omega) / R, omega / G
    A = np.array([[-1.0 / tau_e, 0.0], [drive / J, -slope / J]])
    x_ss = np.array([voltage, omega_ss])
    x = x_ss + _expm2(A, t) @ (np.zeros(2) - x_ss)
    v, omega = x[:, 0], x[:, 1]
    return (v - K * omega) / R, omega / G
