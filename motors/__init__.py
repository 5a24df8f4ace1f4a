"""DC motor partial model (paper Eqs. 6–7).

    U = L_M di/dt + R_M i + K θ̇_m          (6)  electrical, at the motor shaft
    J θ̈_m + b_M θ̇_m = K i                  (7)  mechanical, at the motor shaft

The wheel turns at θ̇ = θ̇_m / G through a gearbox of ratio G. In simulation the model is MuJoCo 4's
native ``dcmotor`` actuator (see :mod:`motors.actuator`); :mod:`motors.analytic` is the closed-form
reference it is tested against.
"""

from motors.constants import MotorConstants, MotorError
from motors.datasheet import POLOLU_MP_6V_30_1, Datasheet

__all__ = ["MotorConstants", "MotorError", "Datasheet", "POLOLU_MP_6V_30_1"]
