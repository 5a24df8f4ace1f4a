"""Which parts of a robot description are the drive wheels, the caster and the sensor mount; how to read it."""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True)
class RobotConfig:
    """Names in the URDF; each None is auto-detected when unambiguous.

    Attributes:
      wheel_joints: (left, right) continuous joints of the drive wheels. Auto: the two continuous
        joints, told apart by their side of the root link (REP-103: +y is left).
      caster: link or collision name of the caster(s), given their own rolling resistance (mjcf.world). Auto:
        links or collisions whose name contains "caster".
      sensor_link: link the line-sensor array is mounted on (its origin is the array's centre).
        Auto: a link whose name contains "sensor", else the root link.
      sensor_mount: (link, (x, y, z)): the array's centre in that link's frame [m]; overrides ``sensor_link``.
      sensor_ahead: S, the array's distance ahead of the axle centre along the root's x [m]: the array moves there
        (keeping the mount's height and side offset) and hangs from the root link.
      package_dirs: ``package://NAME`` and ``$(find NAME)`` → directory, for packages not found beside the
        description.
      xacro_args: ``NAME=VALUE`` arguments of a xacro description.
    """

    wheel_joints: tuple[str, str] | None = None
    caster: str | None = None
    sensor_link: str | None = None
    sensor_mount: tuple[str, tuple[float, float, float]] | None = None
    sensor_ahead: float | None = None
    package_dirs: tuple[tuple[str, str], ...] = ()
    xacro_args: tuple[tuple[str, str], ...] = ()
