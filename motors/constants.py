"""Constants of the gearmotor model (Eqs. 6–7 with a lossy gearbox), checked on construction."""

from __future__ import annotations

import dataclasses
import math

from lf_common.errors import LineFollowerError


class MotorError(LineFollowerError, ValueError):
    """A motor parameter is missing, not finite or out of range."""


@dataclasses.dataclass(frozen=True)
class MotorConstants:
    """One brushed DC gearmotor, in SI units, all referred to the motor shaft except ``gear`` and ``efficiency``.

    The wheel (gearbox output) turning at Ω gets the torque

        τ = G·η·(K·i − τ0·sign Ω) − G²·b_M·Ω − G²·J_rotor·Ω̇,    i = (U − K·G·Ω) / R_M.

    Attributes:
      R_M: winding resistance in [Ω].
      L_M: winding inductance in [H]; its time constant L_M/R_M (≈ 56 µs) is far below the 1 ms step, so a lap
        cannot identify it (see :mod:`motors.actuator`: a lag of the winding voltage, 0 removes the lag's state).
      K: torque constant = back-EMF constant in [N·m/A] = [V·s/rad].
      b_M: viscous friction at the motor shaft in [N·m·s/rad] (a datasheet fit gives it the viscous share of the
        no-load friction, :mod:`motors.datasheet`).
      J_rotor: rotor inertia in [kg·m²].
      gear: gearbox ratio G, motor turns per wheel turn [-].
      efficiency: gearbox efficiency η in (0, 1] [-]: a loss proportional to the transmitted torque.
      friction: the dry (Coulomb) part τ0 of the no-load friction at the motor shaft in [N·m] (brushes, bearings,
        gearbox drag).
    """

    R_M: float
    L_M: float
    K: float
    b_M: float
    J_rotor: float
    gear: float
    efficiency: float
    friction: float

    def __post_init__(self) -> None:
        for name, lower, strict in (
            ("R_M", 0.0, True),
            ("L_M", 0.0, False),
            ("K", 0.0, True),
            ("b_M", 0.0, False),
            ("J_rotor", 0.0, False),
            ("gear", 0.0, True),
            ("efficiency", 0.0, True),
            ("friction", 0.0, False),
        ):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise MotorError(f"motor.{name}: must be a finite number, got {value!r}")
            if value < lower or (strict and value == lower):
                op = ">" if strict else ">="
                raise MotorError(f"motor.{name}: must be {op} {lower:g}, got {value:g}")
        if self.efficiency > 1.0:
            raise MotorError(f"motor.efficiency: must be <= 1 (a gearbox gives no torque for free), got {self.efficiency:g}")

    @property
    def electrical_time_constant_s(self) -> float:
        """L_M / R_M in [s]."""
        return self.L_M / self.R_M

    def stall_torque_wheel(self, voltage: float) -> float:
        """Output torque in [N·m] where the torque-speed line at ``voltage`` [V] reaches zero speed (a datasheet's
        stall torque: the dry friction still opposes the last motion); signed as the voltage, 0 inside the dead band
        |U| ≤ R_M·τ0/K."""
        magnitude = self.gear * self.efficiency * max(0.0, self.K * abs(voltage) / self.R_M - self.friction)
        return math.copysign(magnitude, voltage)

    def stall_current(self, voltage: float) -> float:
        """Current with the rotor held in [A] at ``voltage`` [V]."""
        return voltage / self.R_M

    def no_load_speed_wheel(self, voltage: float) -> float:
        """Steady wheel speed in free air in [rad/s] at ``voltage`` [V], signed as the voltage (0 where the motor
        cannot overcome its dry friction)."""
        eta, K, R = self.efficiency, self.K, self.R_M
        omega_m = eta * max(0.0, K * abs(voltage) / R - self.friction) / (eta * K * K / R + self.b_M)
        return math.copysign(omega_m, voltage) / self.gear

    def no_load_current(self, voltage: float) -> float:
        """Steady current with no external load in [A] at ``voltage`` [V]."""
        omega_m = self.no_load_speed_wheel(voltage) * self.gear
        return (voltage - self.K * omega_m) / self.R_M

    def replace(self, **changes: float) -> "MotorConstants":
        return dataclasses.replace(self, **changes)
