"""Geometry of a downward reflectance array (Pololu QTR-8 style)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from lf_common.errors import LineFollowerError


MAX_SENSORS = 16  # the firmware's arrays (LF_MAX_SENSORS in twin/csrc/firmware/line_follower.h)


class SensorError(LineFollowerError, ValueError):
    """A sensor parameter is missing, not finite or out of range."""


@dataclasses.dataclass(frozen=True)
class SensorArray:
    """An evenly spaced row of sensors across the heading.

    Attributes:
      count: number of sensors [-] (QTR-8: 8).
      pitch: centre-to-centre spacing in [m] (QTR-8: 9.525 mm).
    """

    count: int = 8
    pitch: float = 0.009525

    def __post_init__(self) -> None:
        if not isinstance(self.count, int) or not 2 <= self.count <= MAX_SENSORS:
            raise SensorError(f"sensor.count: must be an integer in [2, {MAX_SENSORS}], got {self.count!r}")
        if not (isinstance(self.pitch, (int, float)) and math.isfinite(self.pitch) and 0.001 <= self.pitch <= 0.05):
            raise SensorError(f"sensor.pitch: must be in [0.001, 0.05] m, got {self.pitch!r}")

    def lateral_offsets(self) -> np.ndarray:
        """(count,) offsets along +y (left) in [m] in the array frame; sensor 0 is the leftmost, as on a QTR."""
        return (np.arange(self.count)[::-1] - (self.count - 1) / 2) * self.pitch

    @property
    def width(self) -> float:
        """Distance between the outermost sensors in [m]."""
        return (self.count - 1) * self.pitch
