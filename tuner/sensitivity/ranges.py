"""Over what each parameter is varied: its documented physical range, and which parameters a batch of laps can vary.

A **factor** is one varied parameter with its range. By default every continuous parameter that can differ between
the laps of one batch (change cost ``model_field`` or ``controller``) and has a physical range is varied, each over
its documented physical range (:data:`PHYSICAL_RANGES`: factors of the twin's own value, with their source), or,
where none is documented, over :data:`ASSUMED` (÷1.25 to ×1.25, i.e. −20 % to +25 %, the range ``diagnose``
assumes); and the gains a person tunes (Eq. 13, :data:`GAINS`), explored over the same −20 %/+25 % around their
values.

Left out by default, with the reason (:func:`default_factors` returns them): parameters that rebuild the robot or
track (``cad.*``, ``environment.*``, the sensor count and pitch: a design study varies them), whole numbers, the
solver's numerical settings, the control period (a whole number of physics steps), the gear ratio (fixed by the
gear train), the firmware's other settings (:func:`is_setting`: fixed on the robot, no physical range), parameters
that act on nothing in a lap (:data:`INERT`: the floor's own friction) and parameters whose value is 0 (no scale to vary them by). ``--param`` with ``--bounds`` varies any of the continuous
ones anyway.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Mapping, Sequence

from twin.model.identifiability import unresolved
from twin.model.space import ChangeCost, ModelSpace
from tuner.search.space import TunerError


@dataclasses.dataclass(frozen=True)
class PhysicalRange:
    """A documented range as factors of the parameter's own value, and where it comes from."""

    low: float
    high: float
    source: str


PHYSICAL_RANGES: dict[str, PhysicalRange] = {
    "motion.mu": PhysicalRange(1 / 3, 4 / 3, "clean rubber on a laminated board ≈ 0.9 (the model's nominal); dust or "
                               "worn tyres take it down to a third, a sticky floor up a third"),
    "motion.floor_mu": PhysicalRange(1 / 3, 4 / 3, "the floor's grip on what is not a tyre or a caster (a chassis): "
                                     "the tyres' spread"),
    "motor.supply_voltage": PhysicalRange(4.0 / 6.0, 6.2 / 6.0, "four AAA cells: 4 × 1.0 V at the end of a NiMH "
                                          "discharge (Panasonic HHR70AAAJ) to 4 × 1.55 V fresh alkaline (Pololu 3pi+ "
                                          "guide §5.7: 6 V nominal)"),
    "motor.R_M": PhysicalRange(0.9, 1.5, "copper's resistance rises 0.39 %/K (a winding 50 K warmer: +20 %); worn "
                               "brushes add contact resistance"),
    "motor.K": PhysicalRange(0.9, 1.05, "ferrite magnets lose about 0.2 %/K of their flux (a motor 50 K warmer: "
                             "−10 %); +5 % for the unit-to-unit spread, assumed"),
    "cad.m_c": PhysicalRange(1.0, 2.0, "a payload up to the chassis' own mass (a second battery pack, a camera)"),
}
ASSUMED = PhysicalRange(0.8, 1.25, "no documented range: −20 %/+25 % (÷1.25 to ×1.25) assumed")

# left out by default (still allowed with --param and --bounds, except where it says cannot)
NUMERICAL = {"motion.timestep": "the physics step: a numerical setting, not the robot (cannot: the control period "
                                "must stay a whole number of steps)",
             "motion.impratio": "a numerical setting of the contact solver, not the robot"}
DISCRETE = {"control.dt": "the control period is a whole number of physics steps: not continuous (cannot)",
            "motor.gear": "the gear train fixes the ratio: no physical spread"}
CANNOT = ("motion.timestep", "control.dt")
# act on nothing in a lap: the tyres and the ball casters have contact priority (mjcf.world, mjcf.urdf_to_mjcf), so
# the floor's own friction governs only a chassis touching the floor, which a lap never has
INERT = {"motion.floor_mu": "acts on nothing in a lap: the tyres' μ (motion.mu) and the casters' rolling resistance "
                            "(motion.caster_mu) govern their contacts; the floor's own friction only meets a chassis "
                            "scraping the floor"}
SETTINGS = ("sensor.timeout",)  # besides control.*: the firmware's read timeout
GAINS = ("control.v_max", "control.kb", "control.kp", "control.ki", "control.kd")  # Eq. 13: varied by default


def is_setting(address: str) -> bool:
    """A number a person chooses for the firmware (``control.*``, the read timeout): known exactly on the robot, so
    never a cause of a robot unlike its twin."""
    return address.startswith("control.") or address in SETTINGS


@dataclasses.dataclass(frozen=True)
class Factor:
    """One varied parameter: ``lower`` … ``upper`` in its unit; ``source`` says where the range comes from."""

    address: str
    lower: float
    upper: float
    unit: str
    source: str
    documented: bool  # the range has a source (not assumed, not given)


def physical_range(space: ModelSpace, address: str) -> tuple[float, float, str, bool] | None:
    """(lower, upper, source, documented) of a parameter around its current value, inside the model space's range;
    None when its value is 0 or below (a factor gives it no width)."""
    p, v = space.parameter(address), space.get(address)
    if v <= 0:
        return None
    r = PHYSICAL_RANGES.get(address, ASSUMED)
    return max(p.lower, v * r.low), min(p.upper, v * r.high), r.source, r is not ASSUMED


def why_not_varied(space: ModelSpace, address: str) -> str | None:
    """Why a parameter cannot differ between the laps of one batch, or None if it can."""
    p = space.parameter(address)
    if p.cost is ChangeCost.REBUILD:
        return "rebuilds the robot or track: not in one batch (a design study varies it)"
    if p.integer:
        return "a whole number: not continuous"
    if address in CANNOT:
        return NUMERICAL.get(address) or DISCRETE[address]
    return None


def default_factors(space: ModelSpace) -> tuple[list[Factor], dict[str, str]]:
    """The default analysis: every parameter a batch can vary, each over its physical range; and {address: reason}
    for every parameter left out."""
    factors, left_out = [], {}
    for a in space.addresses:
        why = (why_not_varied(space, a) or NUMERICAL.get(a) or DISCRETE.get(a) or INERT.get(a)
               or unresolved(space.values, a))
        if why is None and is_setting(a) and a not in GAINS:
            why = "a firmware setting, fixed on the robot: no physical range (vary it with --param and --bounds)"
        rng = None if why else physical_range(space, a)
        if rng is None and why is None:
            why = f"its value is {space.get(a):g}: no scale to vary it by (give --param {a} --bounds {a}=LO,HI)"
        if why:
            left_out[a] = why
            continue
        lo, hi, source, documented = rng
        if lo < hi:
            factors.append(Factor(a, lo, hi, space.parameter(a).unit, source, documented))
        else:
            left_out[a] = "its range collapses inside the model space's bounds"
    return factors, left_out


def chosen_factors(space: ModelSpace, addresses: Sequence[str], bounds: Mapping[str, tuple[float, float]] = {}) -> list[Factor]:
    """``--param`` and ``--bounds``: the named parameters, each over its bounds or else its physical range.

    Raises:
      TunerError: an address twice, a bound for an address not named, a parameter a batch cannot vary, bounds
        inverted or outside the model space's range, or no range known (value 0 and no bounds).
    """
    if len(set(addresses)) != len(addresses):
        raise TunerError(f"sensitivity: a parameter is given twice ({', '.join(addresses)})")
    for a in bounds:
        if a not in addresses:
            raise TunerError(f"--bounds {a}: not a varied parameter ({', '.join(addresses)})")
    out = []
    for a in addresses:
        p = space.parameter(a)  # an unknown address: one line naming the nearest
        why = why_not_varied(space, a)
        if why:
            raise TunerError(f"{a}: {why}")
        if a in bounds:
            lo, hi = (float(x) for x in bounds[a])
            source, documented = "given (--bounds)", False
        else:
            rng = physical_range(space, a)
            if rng is None:
                raise TunerError(f"{a}: its value is {space.get(a):g}, so it has no range by default: give "
                                 f"--bounds {a}=LO,HI")
            lo, hi, source, documented = rng
        if not (math.isfinite(lo) and math.isfinite(hi)) or not lo < hi:
            raise TunerError(f"{a}: bounds [{lo:g}, {hi:g}] are not finite or are inverted or empty")
        p.check(f"{a} lower bound", lo)
        p.check(f"{a} upper bound", hi)
        if a == "motor.L_M" and not (lo > 0 and space.get(a) > 0):
            raise TunerError("motor.L_M: switching between zero and non-zero inductance rebuilds the model: vary it "
                             "above 0, from a twin whose inductance is above 0")
        out.append(Factor(a, lo, hi, p.unit, source, documented))
    return out
