"""Datasheet figures → constants of Eqs. 6–7.

A gearmotor datasheet gives figures at the gearbox output: nominal voltage U, stall torque τ_s,
stall current I_s, no-load speed Ω_0 (and no-load current I_0). Eqs. 6–7 have one K, no gearbox
efficiency, and viscous friction b_M as the only loss, so they cannot reproduce every figure at once.
We match the three that shape a lap:

    R_M = U / I_s                          stall current (rotor still, no back-EMF)
    K   = τ_s R_M / (G U)                  stall torque at the output
    b_M = (K U / ω_0 − K²) / R_M           no-load speed, ω_0 = G Ω_0 at the motor shaft

Gearbox losses then live in b_M, so the model's no-load current b_M ω_0 / K is larger than the
datasheet's I_0; :meth:`Datasheet.derived_no_load_current` reports it so the mismatch is visible.
Inductance and rotor inertia are rarely on hobby datasheets; they are given explicitly.
"""

from __future__ import annotations

import dataclasses
import math

from motors.constants import MotorConstants, MotorError

RPM = 2.0 * math.pi / 60.0  # [rad/s] per [rev/min]


@dataclasses.dataclass(frozen=True)
class Datasheet:
    """Gearmotor datasheet figures, at the gearbox output.

    Attributes:
      voltage: nominal voltage in [V].
      stall_torque: output stall torque in [N·m].
      stall_current: stall current in [A].
      no_load_speed: output no-load speed in [rad/s].
      no_load_current: no-load current in [A], or None where not published (informative only, see module docstring).
      gear: gearbox ratio [-].
      inductance: winding inductance in [H].
      rotor_inertia: rotor inertia in [kg·m²].
      source: where the figures come from.
    """

    voltage: float
    stall_torque: float
    stall_current: float
    no_load_speed: float
    no_load_current: float | None
    gear: float
    inductance: float
    rotor_inertia: float
    source: str = ""

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            if field.name == "source" or (field.name == "no_load_current" and getattr(self, field.name) is None):
                continue
            value = getattr(self, field.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise MotorError(f"datasheet.{field.name}: must be a finite number >= 0, got {value!r}")
        for name in ("voltage", "stall_torque", "stall_current", "no_load_speed", "gear"):
            if getattr(self, name) == 0:
                raise MotorError(f"datasheet.{name}: must be > 0")
        # b_M >= 0 needs K·ω_0 <= U: the stall torque and no-load speed must be consistent.
        if self.stall_torque * self.no_load_speed > self.voltage * self.stall_current * 1.0000001:
            raise MotorError(
                "datasheet: stall torque × no-load speed exceeds U × I_stall; no ideal DC motor has these figures"
            )

    def constants(self) -> MotorConstants:
        """Constants of Eqs. 6–7 matching stall current, stall torque and no-load speed exactly."""
        R = self.voltage / self.stall_current
        K = self.stall_torque * R / (self.gear * self.voltage)
        omega_0 = self.gear * self.no_load_speed
        b = max(0.0, (K * self.voltage / omega_0 - K * K) / R)
        return MotorConstants(R_M=R, L_M=self.inductance, K=K, b_M=b, J_rotor=self.rotor_inertia, gear=self.gear)

    def derived_no_load_current(self) -> float:
        """No-load current in [A] that the fitted constants predict (compare with ``no_load_current``)."""
        return self.constants().no_load_current(self.voltage)


# Pololu micro metal gearmotor, 30:1 MP 6 V (item #2369), as fitted to the 3pi+ 32U4 "Standard Edition".
# Pololu product page / 3pi+ user's guide: 720 rpm no-load and 40 mA at 6 V, stall 0.33 kg·cm = 0.032 N·m at 0.67 A.
# Inductance and rotor inertia are not published: 0.5 mH and 0.02 g·cm² (2e-9 kg·m²) are typical of 10 mm-class
# ("N20") brushed motors and are assumptions, not measurements.
POLOLU_MP_6V_30_1 = Datasheet(
    voltage=6.0,
    stall_torque=0.33 * 9.80665e-2,  # 0.33 kg·cm → [N·m]
    stall_current=0.67,
    no_load_speed=720.0 * RPM,
    no_load_current=0.040,
    gear=29.86,  # Pololu's exact ratio for the "30:1" gearbox
    inductance=0.5e-3,
    rotor_inertia=2.0e-9,
    source="Pololu 30:1 Micro Metal Gearmotor MP 6V (#2369); L_M and J_rotor assumed",
)
