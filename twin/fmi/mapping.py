"""How a controller FMU's variable joins a twin port (``--map``): a linear relation with sign, scale and offset, and
the check of the units that the FMU declares.

The grammar (spaces allowed between the parts)::

    MAP    = VARIABLE "=" [SIGN] [NUMBER "*"] PORT [SIGN NUMBER]
    SIGN   = "+" | "-"
    NUMBER = digits with an optional fraction and exponent (255, 0.5, .5, 1e-3)

It reads as the equation it is: ``VARIABLE = sign · NUMBER · PORT ± NUMBER``. An FMU input is set to that value of
the port; an FMU output drives the port through the inverse (``PORT = (VARIABLE − offset) / scale``, so the scale
must not be 0). ``servoRightVal=-1*wheel_duty_right`` drives the right wheel with the negated servo output (a
mirrored servo); ``lfLeftVal=sensor.white_8bit[5]`` feeds an input the port as it is.
"""

from __future__ import annotations

import dataclasses
import math
import re

from twin.errors import TwinError
from twin.fmi.variables import UNITS

NUMBER = r"(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?"
PORT = r"[A-Za-z_][\w.]*(?:\[\d+\])?"
RELATION = re.compile(rf"\s*(?P<sign>[+-])?\s*(?:(?P<scale>{NUMBER})\s*\*\s*)?(?P<port>{PORT})\s*"
                      rf"(?:(?P<op>[+-])\s*(?P<offset>{NUMBER}))?\s*")
GRAMMAR = "FMU_VARIABLE=[-][SCALE*]TWIN_PORT[+OFFSET|-OFFSET], e.g. servoRightVal=-1*wheel_duty_right"


@dataclasses.dataclass(frozen=True)
class Link:
    """``variable = scale · port + offset``; ``scaled``: the map gave a scale (a unit conversion asked for);
    ``at_start``: the value an FMU input gets for its first step instead (what a replaced multi-model instance
    outputs after its initialisation), or None."""

    variable: str
    port: str
    scale: float = 1.0
    offset: float = 0.0
    scaled: bool = False
    at_start: float | None = None

    def to_fmu(self, port_value: float) -> float:
        return self.scale * port_value + self.offset

    def from_fmu(self, fmu_value: float) -> float:
        return (fmu_value - self.offset) / self.scale

    @property
    def expression(self) -> str:
        """The right-hand side as the grammar writes it (the bare port when it is the identity)."""
        text = self.port if self.scale == 1.0 else f"{self.scale:g}*{self.port}"
        return text + (f"{self.offset:+g}" if self.offset else "")


def parse_map(items: list[str] | None) -> dict[str, Link]:
    """``["servoRightVal=-1*wheel_duty_right", ...]`` (``--map``) → {variable: Link}; the names are checked against
    the FMU later, malformed relations here (one TwinError line)."""
    out: dict[str, Link] = {}
    for item in items or ():
        name, sep, relation = item.partition("=")
        name = name.strip()
        m = RELATION.fullmatch(relation) if sep and name else None
        if m is None:
            raise TwinError(f"--map {item!r}: expected {GRAMMAR}")
        scale = float(m["scale"] or 1.0) * (-1.0 if m["sign"] == "-" else 1.0)
        offset = float(m["offset"] or 0.0) * (-1.0 if m["op"] == "-" else 1.0)
        if scale == 0.0 or not math.isfinite(scale) or not math.isfinite(offset):
            raise TwinError(f"--map {item!r}: the scale must be a finite number other than 0 and the offset finite")
        if name in out:
            raise TwinError(f"--map {item!r}: {name} is mapped twice")
        out[name] = Link(name, m["port"], scale, offset, scaled=m["scale"] is not None)
    return out


def _dimension(unit: str | None, definitions: dict) -> tuple[dict[str, int], float] | None:
    """(SI base exponents without rad, factor) of a unit named in the FMU's UnitDefinitions or in the twin's table;
    None if it cannot be told. No unit, "" and "1" are dimensionless."""
    if unit in (None, "", "1"):
        return {}, 1.0
    if unit in definitions and definitions[unit] is not None:
        b = definitions[unit]
        exps = {k: getattr(b, k) for k in ("kg", "m", "s", "A", "K", "mol", "cd")}
        return {k: e for k, e in exps.items() if e}, float(b.factor)
    for name, base, factor in UNITS.values():
        if name == unit:
            return {k: e for k, e in base.items() if e and k != "rad"}, factor
    return None


def check_unit(path: str, md, variable, link: Link, port_unit: str | None) -> None:
    """Refuse (one TwinError line) a variable whose declared unit is not the port's: of another dimension, or of
    another size with no scale in the map to convert it. A unit that cannot be told apart passes."""
    unit = variable.unit or (variable.declaredType.unit if variable.declaredType is not None else None)
    if unit is None:
        return
    definitions = {u.name: u.baseUnit for u in getattr(md, "unitDefinitions", None) or ()}
    theirs, ours = _dimension(unit, definitions), _dimension(port_unit, {})
    if theirs is None or ours is None:
        return
    shown = port_unit or "1 (dimensionless)"
    if theirs[0] != ours[0]:
        raise TwinError(f"--controller-fmu {path}: {variable.name} is in {unit}, {link.port} in {shown}: they are "
                        "not of one kind; map it to a port of its kind")
    if not math.isclose(theirs[1], ours[1], rel_tol=1e-12) and not link.scaled:
        ratio = ours[1] / theirs[1]
        raise TwinError(f"--controller-fmu {path}: {variable.name} is in {unit}, {link.port} in {shown}: give the "
                        f"scale, e.g. --map '{variable.name}={ratio:g}*{link.port}'")
