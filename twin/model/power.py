"""The motor driver's supply: the battery, its internal resistance, and the 3pi's boost regulator (issue 33, item 3).

``motor.supply_voltage`` is the battery's open-circuit voltage E. Between the cells and the H-bridges sits a
resistance R_s (``power.source_resistance``: the cells' internal resistance, contacts and wiring), so the supply
sags as the motors draw. A robot whose motors run straight from the battery (the 3pi+ 32U4: its DRV8838 drivers are
fed from the battery switch) gets, over a step whose mean duties are d_j, with each motor's back-EMF e_j and winding
resistance R_j (each draws d_j·i_j from the supply, i_j = (d_j·v − e_j)/R_j, while that is positive: the driver
returns nothing to the battery, as the lap's energy counts it),

    v = (E + R_s·Σ d_j·e_j/R_j) / (1 + R_s·Σ d_j²/R_j).

The original 3pi boosts its four AAA cells to a regulated 9.25 V for the motors (``power.regulator_voltage``), so its
motors "run the same speed as the batteries drop from 5.5 down to 3.5 V" and it "will operate at maximum performance
until it suddenly shuts off" (Pololu 3pi Robot User's Guide, §5.b Power management): the regulator holds its output
while the battery's terminal voltage t stays at or above its lowest input (``power.regulator_min_input``, 3.5 V)
and shuts off for the rest of the run below it (the MCU's 5 V comes from the boosted rail too). The battery gives
the motors' power P at t = E − R_s·P/t, t = (E + √(E² − 4·R_s·P))/2 (the regulator's own loss is not published:
none assumed). ``twin/csrc/sim/mujoco_glue.c`` (``lf_bus_voltage``) computes both every physics step in the C loop,
the processor in the loop and the FMU; :meth:`Power.bus_voltage` is its reference.

Defaults: R_s = 0.12 Ω, four cells of 30 mΩ (Panasonic HHR70AAAJ AAA NiMH data sheet: approx. internal impedance at
1 kHz, charged; contacts and wiring not included, and a cell's resistance grows as it discharges); no regulator.
Within one lap the battery's open-circuit voltage is taken as constant: a lap of the default robot draws ≈ 0.6 mAh of
a 700 mAh cell (0.09 %), so its discharge shows between laps, where the twin's history aligns and forecasts
``motor.supply_voltage``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Sequence

from twin.errors import TwinError

CELL_OHM = 0.030  # [Ω] Panasonic HHR70AAAJ (AAA NiMH, 700 mAh), approx. internal impedance at 1 kHz, charged
SOURCE_OHM = 4 * CELL_OHM  # four AAA cells in series (3pi, 3pi+ 32U4)
THREE_PI_REGULATOR_V = 9.25  # [V] Pololu 3pi Robot User's Guide §5.b
THREE_PI_REGULATOR_MIN_INPUT_V = 3.5  # [V] ibid.: "the same speed as the batteries drop from 5.5 down to 3.5 V"


@dataclasses.dataclass(frozen=True)
class Power:
    """The supply of the motor driver.

    Attributes:
      battery_v: the battery's open-circuit voltage E in [V] (``motor.supply_voltage``).
      source_ohm: resistance between the cells and the H-bridges R_s in [Ω] (``power.source_resistance``).
      regulator_v: the boost regulator's output in [V]; 0: the motors run from the battery (``power.regulator_voltage``).
      regulator_min_input_v: the regulator's lowest input voltage in [V] (``power.regulator_min_input``).
    """

    battery_v: float
    source_ohm: float = SOURCE_OHM
    regulator_v: float = 0.0
    regulator_min_input_v: float = 0.0

    def __post_init__(self) -> None:
        for field, address in (("battery_v", "motor.supply_voltage"), ("source_ohm", "power.source_resistance"),
                               ("regulator_v", "power.regulator_voltage"),
                               ("regulator_min_input_v", "power.regulator_min_input")):
            value = getattr(self, field)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise TwinError(f"{address}: must be a finite number >= 0, got {value!r}")
        if self.regulator_v > 0 and self.regulator_min_input_v > self.regulator_v:
            raise TwinError(f"power.regulator_min_input: {self.regulator_min_input_v:g} V is above the regulator's "
                            f"own output {self.regulator_v:g} V (power.regulator_voltage): a boost regulator's input is "
                            "below its output")

    @property
    def nominal_v(self) -> float:
        """The voltage PWM duty 1 gives with no load [V]: the regulator's, or the battery's (the control's clamp)."""
        return self.regulator_v if self.regulator_v > 0 else self.battery_v

    def starts(self) -> bool:
        """Whether the regulator (if any) runs with the motors at rest: the open-circuit voltage reaches its input."""
        return self.regulator_v <= 0 or self.battery_v >= self.regulator_min_input_v

    def bus_voltage(self, duties: Sequence[float], back_emf_v: Sequence[float],
                    winding_ohm: Sequence[float]) -> tuple[float, float]:
        """(the H-bridges' supply v [V], the battery's terminal voltage [V]) for mean duties in [-1, 1], the motors'
        back-EMF K·ω_m [V] and winding resistances [Ω]; v = 0 where the regulator shuts off (reference of
        ``lf_bus_voltage``, which also keeps it off for the rest of the run)."""
        E, Rs = self.battery_v, self.source_ohm
        if self.regulator_v > 0:
            V = self.regulator_v
            watts = sum(max(0.0, d * (d * V - e) / r) * V for d, e, r in zip(duties, back_emf_v, winding_ohm))
            disc = E * E - 4.0 * Rs * watts
            terminal = 0.5 * (E + math.sqrt(disc)) if disc >= 0 else 0.0
            return (0.0 if terminal < self.regulator_min_input_v else V), terminal
        draws = [True] * len(duties)
        v = E
        for _ in range(2 if Rs > 0 else 0):
            num = E + Rs * sum(d * e / r for d, e, r, on in zip(duties, back_emf_v, winding_ohm, draws) if on)
            den = 1.0 + Rs * sum(d * d / r for d, r, on in zip(duties, winding_ohm, draws) if on)
            v = num / den
            dropped = [on and d * (d * v - e) < 0 for d, e, on in zip(duties, back_emf_v, draws)]
            if not any(dropped):
                break
            draws = [on and not drop for on, drop in zip(draws, dropped)]
        return v, v
