"""Constants of Eqs. 6–7, checked on construction."""

from __future__ import annotations

import dataclasses
import math

from lf_common.errors import LineFollowerError


class MotorError(LineFollowerError, ValueError):
    """A motor parameter is missing, not finite or out of range."""


@dataclasses.dataclass(frozen=True)
class MotorConstants:
    """One brushed DC gearmotor, in SI units, all referred to the motor shaft except ``gear``.

    Attributes:
      R_M: winding resistance in [Ω].
      L_M: winding inductance in [H]; 0 makes the current algebraic.
      K: torque constant = back-EMF constant in [N·m/A] = [V·s/rad].
      b_M: viscous friction at the motor shaft in [N·m·s/rad] (gearbox losses lumped in).
      J_rotor: rotor inertia in [kg·m²].
      gear: gearbox ratio G, motor turns per wheel turn [-].
    """

    R_M: float
    L_M: float
    K: float
    b_M: float
    J_rotor: float
    gear: float

    def __post_init__(self) -> None:
        for name, lower, strict in (
            ("R_M", 0.0, True),
            ("L_M", 0.0, False),
            ("K", 0.0, True),
            ("b_M", 0.0, False),
            ("J_rotor", 0.0, False),
            ("gear", 0.0, True),
        ):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise MotorError(f"motor.{name}: must be a finite number, got {value!r}")
            if value < lower or (strict and value == lower):
                op = ">" if strict else ">="
                raise MotorError(f"motor.{name}: must be {op} {lower:g}, got {value:g}")

    @property
    def electrical_time_constant_s(self) -> float:
        """L_M / R_M in [s]."""
        return self.L_M / self.R_M

    def stall_torque_wheel(self, voltage: float) -> float:
        """Torque at the wheel with the rotor held, in [N·m], at ``voltage`` in [V]."""
        return self.gear * self.K * voltage / self.R_M

    def no_load_speed_wheel(self, voltage: float) -> float:
        """Steady wheel speed in free air (no load inertia matters) in [rad/s] at ``voltage`` in [V]."""
        return voltage * self.K / (self.K**2 + self.R_M * self.b_M) / self.gear

    def no_load_current(self, voltage: float) -> float:
        """Steady current with no external load in [A] at ``voltage`` in [V]."""
        omega_m = self.no_load_speed_wheel(voltage) * self.gear
        return (voltage - self.K * omega_m) / self.R_M

    def replace(self, **changes: float) -> "MotorConstants":
        return dataclasses.replace(self, **changes)
