"""Datasheet figures → constants of the gearmotor model (:class:`motors.constants.MotorConstants`).

A gearmotor datasheet gives figures at the gearbox output at a nominal voltage U: stall torque τ_s, stall current
I_s, no-load speed Ω_0 and no-load current I_0. A brushed motor with winding resistance R, one constant K
(torque = back-EMF), a friction at its shaft and a gearbox of ratio G and efficiency η fits all four exactly
(ω_0 = G·Ω_0 at the motor shaft, L_M = 0 in steady state). At no load the motor's torque K·I_0 only overcomes its
own friction; how much of it is dry (Coulomb, τ0, the same at every speed) and how much viscous (b_M·ω, growing
with speed) is a fifth figure no datasheet prints: ``dry_share`` s says it, and every s in [0, 1] fits the four
figures exactly:

    R   = U / I_s                              the rotor held: no back-EMF
    K   = (U − R·I_0) / ω_0                     the back-EMF at no load
    τ0  = s·K·I_0                               the dry part of the no-load friction
    η   = τ_s / (G·(K·I_s − τ0))                the stall torque (no viscous loss at zero speed)
    b_M = η·(1 − s)·K·I_0 / ω_0                 the viscous part, at the no-load speed, as the gearbox passes it

Why s matters and what it is here (``DRY_SHARE``): with all of the no-load friction dry (s = 1, maxon's
convention: M_R = k_M·I_0) a motor breaks away only above U_0 = R·I_0 (0.36 V for the 3pi+'s MP 6V 30:1, 1.03 V
for the original 3pi's), and at the low duties of a calibration turn or a timed turn it runs far slower than its
duty says; with none (s = 0) it runs at any voltage. Two outside figures pull apart. Small brushed gearmotors run
on below R·I_0 once turning (Pololu's support, on a 25D gearmotor: starts at 1.8 V, runs down to 0.5 V, with
R·I_0 ≈ 0.24 V): much of the kinetic friction is dry. Pololu's maze solver turns the real 3pi a quarter turn with
duty 80/255 for 200 ms; at the steady turn rate that is 109° with s = 0, 95° with s = 0.5, 80° with s = 1
(before the spin-up, which takes some degrees off each), and with s = 1 a register-level copy of it no longer
finds its way through the twin's maze (tests/test_board.py). s = 0.5 is the figure used, a judgement between the
two that no datasheet here settles; ``dry_share`` is a field, so a measured coast-down or start-up voltage can
replace it per motor.

The figures are consistent when K > 0 and η ≤ 1; :class:`Datasheet` refuses others by name. Inductance and rotor
inertia are rarely on hobby datasheets; they are given explicitly. A datasheet without a no-load current cannot be
fitted: the catalogue says which figure it assumes instead (:mod:`motors.catalogue`).
"""

from __future__ import annotations

import dataclasses
import math

from motors.constants import MotorConstants, MotorError

RPM = 2.0 * math.pi / 60.0  # [rad/s] per [rev/min]
DRY_SHARE = 0.5  # [-] the dry (Coulomb) part of a datasheet's no-load friction, the rest viscous (module docstring)


@dataclasses.dataclass(frozen=True)
class Datasheet:
    """Gearmotor datasheet figures, at the gearbox output.

    Attributes:
      voltage: nominal voltage in [V].
      stall_torque: output stall torque in [N·m].
      stall_current: stall current in [A].
      no_load_speed: output no-load speed in [rad/s].
      no_load_current: no-load current in [A], or None where not published (then :meth:`constants` refuses).
      gear: gearbox ratio [-].
      inductance: winding inductance in [H].
      rotor_inertia: rotor inertia in [kg·m²].
      source: where the figures come from.
      no_load_current_assumed: the no-load current is not the source's but assumed (the source says from where).
      dry_share: the dry (Coulomb) part of the no-load friction in [0, 1] [-], the rest viscous (module docstring).
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
    no_load_current_assumed: bool = False
    dry_share: float = DRY_SHARE

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            if field.name in ("source", "no_load_current_assumed", "dry_share") or (field.name == "no_load_current" and getattr(self, field.name) is None):
                continue
            value = getattr(self, field.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise MotorError(f"datasheet.{field.name}: must be a finite number >= 0, got {value!r}")
        for name in ("voltage", "stall_torque", "stall_current", "no_load_speed", "gear"):
            if getattr(self, name) == 0:
                raise MotorError(f"datasheet.{name}: must be > 0")
        if not (isinstance(self.dry_share, (int, float)) and 0.0 <= self.dry_share <= 1.0):
            raise MotorError(f"datasheet.dry_share: must be a number in [0, 1], got {self.dry_share!r}")
        if self.no_load_current is not None:
            self._fit()  # refuses figures no motor of this model has

    def _fit(self) -> tuple[float, float, float, float, float]:
        """(R, K, η, τ0, b_M) of the module docstring; a MotorError naming the inconsistent figures."""
        if self.no_load_current is None:
            raise MotorError("datasheet.no_load_current: not given; the fit needs it (assume one and say so in source)")
        U, I_s, I_0 = self.voltage, self.stall_current, self.no_load_current
        if I_0 >= I_s:
            raise MotorError(f"datasheet: no-load current {I_0:g} A is not below the stall current {I_s:g} A")
        R = U / I_s
        omega_0 = self.gear * self.no_load_speed
        K = (U - R * I_0) / omega_0
        tau0 = self.dry_share * K * I_0
        eta = self.stall_torque / (self.gear * (K * I_s - tau0))
        if eta > 1.0 + 1e-9:
            raise MotorError(f"datasheet: stall torque needs a gearbox efficiency of {eta:.3g} > 1 with these speed and "
                             "currents; no ideal DC motor has these figures")
        eta = min(1.0, eta)
        return R, K, eta, tau0, eta * (K * I_0 - tau0) / omega_0

    def constants(self) -> MotorConstants:
        """Constants matching stall current, stall torque, no-load speed and no-load current exactly."""
        R, K, eta, tau0, b_M = self._fit()
        return MotorConstants(R_M=R, L_M=self.inductance, K=K, b_M=b_M, J_rotor=self.rotor_inertia, gear=self.gear,
                              efficiency=eta, friction=tau0)

    def derived_no_load_current(self) -> float:
        """No-load current in [A] that the fitted constants predict (the datasheet's, by construction)."""
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
