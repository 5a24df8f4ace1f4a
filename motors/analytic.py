"""Closed-form solution of Eqs. 6–7 for a voltage step: the reference the simulation is tested against.

State x = (i, ω_m): current in [A] and motor-shaft speed in [rad/s]. With a constant voltage U the
system is linear, x' = A x + B U, and its solution is exact:

    x(t) = x_ss + exp(A t) (x_0 − x_ss),    x_ss = −A⁻¹ B U,

with exp(A t) of the 2×2 matrix written out through its eigenvalues (Sylvester's formula), so no
numerical integration is involved. With L_M = 0 the current is algebraic and the speed is first order.
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
      motor: constants of Eqs. 6–7.
      voltage: step voltage U in [V].
      t: times in [s], shape (n,).
      load_inertia: inertia on the wheel side (wheel about its axle) in [kg·m²].
      load_damping: viscous damping on the wheel side in [N·m·s/rad].

    Returns:
      (current in [A], wheel speed θ̇ = ω_m / G in [rad/s]), each of shape (n,).
    """
    G = motor.gear
    J = motor.J_rotor + load_inertia / G**2  # everything referred to the motor shaft
    b = motor.b_M + load_damping / G**2
    R, K, L = motor.R_M, motor.K, motor.L_M
    t = np.asarray(t, dtype=float)
    omega_ss = K * voltage / (K * K + R * b)
    i_ss = (voltage - K * omega_ss) / R
    if L == 0.0:
        tau = J * R / (K * K + R * b)
        omega = omega_ss * (1.0 - np.exp(-t / tau))
        return (voltage - K * omega) / R, omega / G
    A = np.array([[-R / L, -K / L], [K / J, -b / J]])
    x0_minus_ss = np.array([-i_ss, -omega_ss])
    x = np.array([i_ss, omega_ss]) + _expm2(A, t) @ x0_minus_ss
    return x[:, 0], x[:, 1] / G
