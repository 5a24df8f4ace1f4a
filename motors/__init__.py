"""DC gearmotor partial model (paper Eqs. 6–7, with a lossy gearbox).

    U = L_M di/dt + R_M i + K θ̇_m                            (6)  electrical, at the motor shaft
    τ_wheel = G·η·(K i − τ0 sign θ̇) − G² b_M θ̇ − G² J θ̈       (7)  at the wheel, θ̇ = θ̇_m / G

fitted to a datasheet's four figures (:mod:`motors.datasheet`). In simulation the model is a MuJoCo 4 general
actuator plus the wheel joint's dry friction (see :mod:`motors.actuator` for why not the native ``dcmotor``);
:mod:`motors.analytic` holds the closed forms it is tested against.
"""

from motors.constants import MotorConstants, MotorError
from motors.datasheet import POLOLU_MP_6V_30_1, Datasheet

__all__ = ["MotorConstants", "MotorError", "Datasheet", "POLOLU_MP_6V_30_1"]
