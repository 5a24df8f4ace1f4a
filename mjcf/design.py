"""Design parameters of the default robot (paper §3.2: L, R, S, m_c, m_w, d), checked on construction.

Defaults are a Pololu 3pi+ 32U4 class line follower (see docs/robot.md for sources).
"""

from __future__ import annotations

import dataclasses

from mjcf.errors import MjcfError, check_positive_fields


@dataclasses.dataclass(frozen=True)
class RobotDesign:
    """Named design parameters; lengths in [m], masses in [kg].

    Attributes:
      L: half the wheel separation (Eq. 2), axle centre to wheel mid-plane.
      R: wheel radius.
      S: centre of rotation (axle midpoint) to the sensor array, along the heading.
      m_c: chassis mass, everything but the two wheels (batteries, boards, sensor bar, caster).
      m_w: mass of one wheel with its tyre.
      d: centre of gravity of the chassis ahead of the axle.
      wheel_width: tyre width.
      chassis_thickness: height of the chassis puck (boards and battery pack).
      caster_radius: radius of the front and rear ball casters.
      sensor_height: sensor array height above the floor.
      sensor_bar_width: length of the sensor bar across the heading.
    """

    L: float = 0.0425
    R: float = 0.016
    S: float = 0.040
    m_c: float = 0.200
    m_w: float = 0.005
    d: float = 0.006
    wheel_width: float = 0.007
    chassis_thickness: float = 0.012
    caster_radius: float = 0.005
    sensor_height: float = 0.003
    sensor_bar_width: float = 0.080

    def __post_init__(self) -> None:
        check_positive_fields(self, "cad", may_be_zero=("d",))
        if self.chassis_radius < 0.01:
            raise MjcfError(f"cad.L: {self.L:g} m leaves no room for a chassis between the wheels")
        if self.R - self.chassis_thickness / 2 <= 0.002:
            raise MjcfError(f"cad.R: {self.R:g} m wheels leave the chassis on the floor")
        if not (0.0 <= self.d < self.caster_x):
            raise MjcfError(
                f"cad.d: the centre of gravity ({self.d:g} m) must lie between the axle and the front caster "
                f"({self.caster_x:g} m ahead) or the robot tips over"
            )
        if self.S <= 0.5 * self.chassis_radius:
            raise MjcfError(f"cad.S: {self.S:g} m puts the sensor array inside the chassis")
        if self.caster_radius >= self.R:
            raise MjcfError(f"cad.caster_radius: must be smaller than the wheel radius R = {self.R:g} m")

    @property
    def chassis_radius(self) -> float:
        """Radius of the chassis puck: it fits between the wheels with 3 mm to spare [m]."""
        return self.L - self.wheel_width / 2 - 0.003

    @property
    def caster_x(self) -> float:
        """Front caster position ahead of the axle [m]."""
        return self.chassis_radius - self.caster_radius - 0.002

    @property
    def total_mass(self) -> float:
        """m = m_c + 2 m_w [kg] (paper, after Eq. 5)."""
        return self.m_c + 2 * self.m_w

    def replace(self, **changes: float) -> "RobotDesign":
        return dataclasses.replace(self, **changes)


DESIGN_UNITS = {
    "L": "m", "R": "m", "S": "m", "m_c": "kg", "m_w": "kg", "d": "m", "wheel_width": "m",
    "chassis_thickness": "m", "caster_radius": "m", "sensor_height": "m", "sensor_bar_width": "m",
}
