"""Which parts of a URDF are the drive wheels, the caster and the sensor mount."""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True)
class RobotConfig:
    """Names in the URDF; each None is auto-detected when unambiguous.

    Attributes:
      wheel_joints: (left, right) continuous joints of the drive wheels. Auto: the two continuous
        joints, told apart by their side of the root link (REP-103: +y is left).
      caster: link or collision name of the caster(s), made frictionless. Auto: links or collisions
        whose name contains "caster".
      sensor_link: link the line-sensor array is mounted on (its origin is the array's centre).
        Auto: a link whose name contains "sensor", else the root link.
      package_dirs: ``package://NAME`` → directory, for packages not found beside the URDF.
    """

    wheel_joints: tuple[str, str] | None = None
    caster: str | None = None
    sensor_link: str | None = None
    package_dirs: tuple[tuple[str, str], ...] = ()
