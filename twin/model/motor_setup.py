"""A motor, as model-space values: the simulated motor (``motor.*``) and the firmware's belief about it
(``control.full_speed``, the wheel speed it expects at full duty), so the two agree as they do on a robot whose
firmware was written for its motors."""

from __future__ import annotations

import logging

from motors.catalogue import CATALOGUE, names
from motors.choice import MotorChoice, choose
from motors.datasheet import Datasheet
from twin.errors import TwinError

log = logging.getLogger(__name__)

MOTOR_MODEL = "motor.model"  # categorical address: a catalogue motor by name (what --motor NAME sets)


def motor_values(d: Datasheet, supply_voltage: float) -> dict[str, float]:
    """``motor.*`` constants of a datasheet, and ``control.full_speed`` at ``supply_voltage`` [V]."""
    c = d.constants()
    return {"motor.R_M": c.R_M, "motor.L_M": c.L_M, "motor.K": c.K, "motor.b_M": c.b_M, "motor.J_rotor": c.J_rotor,
            "motor.gear": c.gear, "motor.efficiency": c.efficiency, "motor.friction": c.friction,
            "control.full_speed": c.no_load_speed_wheel(supply_voltage)}


def catalogue_motor(name: str) -> Datasheet:
    if name not in CATALOGUE:
        raise TwinError(f"motor {name!r}: not in the motor catalogue (motors.catalogue); choose one of: {', '.join(names())}")
    return CATALOGUE[name]


def motor_for_robot(twin, supply_voltage: float) -> MotorChoice:
    """The motor :func:`motors.choice.choose` picks for the twin's built robot (its mass and wheel radius)."""
    model = twin.model()
    mass = float(model.body_subtreemass[model.body(twin.info.root_body).id])
    return choose(CATALOGUE, mass, twin.info.wheel_radius, supply_voltage)


def use_motor(twin, d: Datasheet, keep=()) -> None:
    """Give the twin motor ``d`` at its supply voltage (the regulator's, or the battery's: twin.model.power), except
    for the addresses in ``keep`` (values the user gave, which win)."""
    supply = twin.power().nominal_v
    twin.update({a: v for a, v in motor_values(d, supply).items() if a not in keep})
