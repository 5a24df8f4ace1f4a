"""Named robots as model-space values: ``--robot 3pi`` (and a 3pi program run without ``--robot``) is the original
Pololu 3pi, the robot libpololu-avr's 3pi programs are written for.

Sources: Pololu 3pi Robot User's Guide (https://www.pololu.com/docs/0J21): section 1 (about 9.5 cm across, 83 g without
batteries, four AAA cells), section 5.b (the motors run from a 9.25 V boost regulator, the same speed as the
batteries drop from 5.5 to 3.5 V, then it shuts off), section 5.c (30:1 micro metal gearmotors, the
catalogue's ``pololu-3pi-30``; wheels of 0.67 in radius; "about 7 oz with batteries"), section 5.d (the reflectance
sensors are QTR-RC circuits) and Pololu's forum on the 3pi's QTR-RC timing ("3PI vs QTR capacitor values and timing":
2.2 nF against the QTR-8RC's 10 nF, so its decay times are ~4.5 times shorter). Estimates, not published: the wheel
separation (the wheels sit inside the 9.5 cm outline: 82 mm), the sensors' distance ahead of the axle (37 mm, near
the front edge) and their spacing: the 3pi's five sensors sit on an arc at the front, three close together in the
middle and two further out (Pololu forum, "Extreme line following"); a straight row at an even 12 mm pitch stands in.
"""

from __future__ import annotations

import dataclasses

from line_sensor.reflectance import SensorModel
from motors.catalogue import CATALOGUE
from motors.datasheet import Datasheet
from twin.errors import TwinError
from twin.model.motor_setup import use_motor
from twin.model.power import THREE_PI_REGULATOR_MIN_INPUT_V, THREE_PI_REGULATOR_V

OZ = 0.028349523125  # [kg]


@dataclasses.dataclass(frozen=True)
class NamedRobot:
    """A robot as values at model-space addresses, its motor (a name in the motor catalogue), and its battery's voltage
    [V] (``motor.supply_voltage``, what ADC6 reads through the 3pi's divider; the motors' supply: twin.model.power)."""

    name: str
    description: str
    values: dict
    motor_model: str
    battery_v: float

    @property
    def motor(self) -> Datasheet:
        return CATALOGUE[self.motor_model]


THREE_PI = NamedRobot(
    name="3pi",
    description="Pololu 3pi (ATmega328P at 20 MHz, 5 QTR-RC sensors, 30:1 gearmotors at a regulated 9.25 V)",
    values={
        "cad.L": 0.041, "cad.R": 0.67 * 0.0254, "cad.S": 0.037, "cad.m_c": 7 * OZ - 2 * 0.005, "cad.m_w": 0.005,
        "cad.sensor_bar_width": 0.065,
        "sensor.count": 5, "sensor.pitch": 0.012,
        "sensor.t_unit": SensorModel().t_unit_us * 2.2 / 10.0,  # 2.2 nF on the 3pi, 10 nF on a QTR-8RC
        "motor.supply_voltage": 4 * 1.2,  # the battery: four AAA NiMH cells; the motors get the regulator's 9.25 V
        "power.regulator_voltage": THREE_PI_REGULATOR_V, "power.regulator_min_input": THREE_PI_REGULATOR_MIN_INPUT_V,
    },
    motor_model="pololu-3pi-30",
    battery_v=4 * 1.2,  # four AAA NiMH cells
)

ROBOTS = {THREE_PI.name: THREE_PI}


def named_robot(name: str) -> NamedRobot | None:
    """The named robot, None if ``name`` is not one (it may be a description's path)."""
    return ROBOTS.get(name)


def use_robot(twin, robot: NamedRobot, keep=()) -> None:
    """Give ``twin`` the robot's values and motor, except the addresses in ``keep`` (values the user gave, which win)."""
    if twin.robot_urdf is not None:
        raise TwinError(f"robot {robot.name}: the twin already runs the description {twin.robot_urdf}")
    twin.update({a: v for a, v in robot.values.items() if a not in keep})
    use_motor(twin, robot.motor, keep=keep)
