"""Every number of a robot description that the converter reads, checked in one place by one rule: it parses, the
attribute holds as many as URDF says, each is finite and within the magnitude its quantity can physically have.

yourdfpy turns ``nan`` and ``1e308`` into floats without a word; downstream they become a rotation of NaNs (MuJoCo
then diverges after a step), a wheel MuJoCo cannot place, or a motor sized to an infinite torque. So the numbers are
checked on the description's own XML, where the message can name the link or joint, the element and the attribute.
The bounds are wide (a robot of at most 100 m, 10 t, …): they catch units mistakes and junk, not unusual robots.
"""

from __future__ import annotations

import dataclasses
import math
import xml.etree.ElementTree as ET

from mjcf.errors import MjcfError


@dataclasses.dataclass(frozen=True)
class Quantity:
    """What one kind of number may be: ``lo <= v <= hi`` in ``unit``, and not 0 when ``nonzero``."""

    unit: str
    lo: float
    hi: float
    nonzero: bool = False


POSITION = Quantity("m", -100.0, 100.0)
SIZE = Quantity("m", 0.0, 100.0, nonzero=True)
ANGLE = Quantity("rad", -100.0, 100.0)
DIRECTION = Quantity("", -1e3, 1e3)  # an axis: normalised later, so only its scale must be sane
MASS = Quantity("kg", 0.0, 1e4)
MOMENT = Quantity("kg·m²", 0.0, 1e4)  # ixx, iyy, izz
PRODUCT = Quantity("kg·m²", -1e4, 1e4)  # ixy, ixz, iyz
SCALE = Quantity("", -1e3, 1e3, nonzero=True)  # a mesh's scale (negative mirrors it)
JOINT_LIMIT = Quantity("rad or m", -math.inf, math.inf)  # 1e16 is a common way of writing "unlimited"
DAMPING = Quantity("N·m·s/rad", 0.0, 1e4)
FRICTION = Quantity("N·m", 0.0, 1e4)
COLOUR = Quantity("", 0.0, 1.0)

# element → attribute → (how many numbers: one count or a choice, quantity); under <link> and <joint>
_ORIGIN = {"xyz": (3, POSITION), "rpy": (3, ANGLE)}
_GEOMETRY = {"box": {"size": (3, SIZE)}, "cylinder": {"radius": (1, SIZE), "length": (1, SIZE)},
             "sphere": {"radius": (1, SIZE)}, "capsule": {"radius": (1, SIZE), "length": (1, SIZE)},
             "mesh": {"scale": ((1, 3), SCALE)}}
_INERTIA = {a: (1, MOMENT) for a in ("ixx", "iyy", "izz")} | {a: (1, PRODUCT) for a in ("ixy", "ixz", "iyz")}
_JOINT = {"origin": _ORIGIN, "axis": {"xyz": (3, DIRECTION)},
          "limit": {"lower": (1, JOINT_LIMIT), "upper": (1, JOINT_LIMIT)},
          "dynamics": {"damping": (1, DAMPING), "friction": (1, FRICTION)}}


def check_numbers(path: str, root: ET.Element) -> None:
    """Check the numbers of a URDF's links, joints and materials.

    Raises:
      MjcfError: ``PATH: link NAME, collision 1 <origin rpy="nan 0 0">: rpy is not a finite number``: the first
        number that breaks the rule, with its place and what it may be.
    """
    for link in root.findall("link"):
        where = f"link {link.get('name')}"
        inertial = link.find("inertial")
        if inertial is not None:
            _element(path, f"{where}, inertial", inertial.find("origin"), _ORIGIN)
            _element(path, f"{where}, inertial", inertial.find("mass"), {"value": (1, MASS)})
            _element(path, f"{where}, inertial", inertial.find("inertia"), _INERTIA)
        for kind in ("visual", "collision"):
            for i, shape in enumerate(link.findall(kind)):
                here = f"{where}, {kind} {i}"
                _element(path, here, shape.find("origin"), _ORIGIN)
                for geometry in shape.findall("geometry"):
                    for el in geometry:
                        _element(path, here, el, _GEOMETRY.get(el.tag, {}))
                material = shape.find("material")
                if material is not None:
                    _element(path, f"{here}, material", material.find("color"), {"rgba": (4, COLOUR)})
    for joint in root.findall("joint"):
        for tag, attributes in _JOINT.items():
            _element(path, f"joint {joint.get('name')}", joint.find(tag), attributes)
    for material in root.findall("material"):
        _element(path, f"material {material.get('name')}", material.find("color"), {"rgba": (4, COLOUR)})


def _element(path: str, where: str, el: ET.Element | None, attributes: dict) -> None:
    if el is None:
        return
    for name, (count, quantity) in attributes.items():
        text = el.get(name)
        if text is None:
            continue
        problem = _problem(text, count, quantity)
        if problem:
            raise MjcfError(f"{path}: {where} <{el.tag} {name}=\"{text[:60]}\">: {name} {problem}")


def _problem(text: str, count, quantity: Quantity) -> str | None:
    """Why ``text`` is not ``count`` numbers of ``quantity``, or None."""
    parts = text.split()
    counts = count if isinstance(count, tuple) else (count,)
    if len(parts) not in counts:
        return f"must be {' or '.join(str(c) for c in counts)} number{'s' if counts[-1] > 1 else ''}, got {len(parts)}"
    for part in parts:
        try:
            v = float(part)
        except ValueError:
            return f"holds {part[:30]!r}, not a number"
        if not math.isfinite(v):
            return f"holds {part}, not a finite number"
        if not quantity.lo <= v <= quantity.hi or (quantity.nonzero and v == 0):
            unit = f" {quantity.unit}" if quantity.unit else ""
            zero = ", not 0" if quantity.nonzero else ""
            units = "; check the units (metres, kilograms, radians)" if quantity.unit else ""
            return f"holds {v:g}{unit}, outside {quantity.lo:g} … {quantity.hi:g}{unit}{zero}{units}"
    return None
