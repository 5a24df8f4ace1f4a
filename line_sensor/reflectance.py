"""The physics of one reflectance sensor over the track, in Python: the reference of
``twin/csrc/sim/sensor_physics.c``, operation for operation so the two agree bit for bit.

A QTR-RC sensor lights the floor with an IR LED and times how long its phototransistor takes to discharge
a capacitor: more light, shorter time. The model:

* footprint: the floor texture averaged over a disc of radius ``aperture + h·tan(half_angle)`` around the
  ray's hit point, weighted by (1 − r²/radius²)², so the reading blurs as the sensor rises;
* response: photocurrent I = ρ·(1 + noise·n) / (1 + (h/h_c)²), time t = t_unit / I, capped at the timeout;
* noise: n has zero mean and unit variance, a scaled sum of four uniforms from splitmix64 (no libm calls,
  so it is the same on every platform).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from line_sensor.geometry import SensorError

MASK64 = (1 << 64) - 1


@dataclasses.dataclass(frozen=True)
class SensorModel:
    """Emitter/phototransistor parameters (defaults: a QTR-RC sensor at its 3 mm optimum height).

    Attributes:
      aperture_m: footprint radius at zero height [m].
      half_angle_rad: cone half-angle, how fast the footprint grows with height [rad].
      falloff_height_m: height at which the returned light halves [m].
      t_unit_us: discharge time for a perfect reflector at zero height [µs]; white board (ρ ≈ 0.92) at
        3 mm reads ≈ 200 µs, black tape ≈ 2400 µs, as Pololu's QTR-RC documentation shows.
      timeout_us: read timeout, the reading when no light returns [µs] (Pololu's default 2500).
      noise_rel: standard deviation of the relative photocurrent noise [-].
    """

    aperture_m: float = 0.0015
    half_angle_rad: float = 0.5
    falloff_height_m: float = 0.006
    t_unit_us: float = 150.0
    timeout_us: float = 2500.0
    noise_rel: float = 0.02

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if not isinstance(v, (int, float)) or not math.isfinite(v):
                raise SensorError(f"sensor.{f.name}: must be a finite number, got {v!r}")
            if v < 0 or (v == 0 and f.name != "noise_rel"):
                raise SensorError(f"sensor.{f.name}: must be > 0, got {v:g}")
        if not self.half_angle_rad < math.pi / 2:
            raise SensorError(f"sensor.half_angle_rad: must be below π/2, got {self.half_angle_rad:g}")
        if not 1 <= self.timeout_us <= 65535:
            raise SensorError(f"sensor.timeout_us: must fit the 16-bit reading (1..65535), got {self.timeout_us:g}")

    def footprint_radius(self, height_m: float) -> float:
        """Radius of the floor disc the sensor sees at ``height_m`` [m]."""
        return self.aperture_m + height_m * math.tan(self.half_angle_rad)

    def raw_reading(self, reflectance: float, height_m: float, noise: float) -> int:
        """RC discharge time in [µs] (integer, as the MCU counts it) for a footprint reflectance 0..1."""
        h = height_m / self.falloff_height_m
        current = reflectance * (1.0 + self.noise_rel * noise) / (1.0 + h * h)
        if not current > 0.0:
            return int(self.timeout_us)
        t = self.t_unit_us / current
        if t >= self.timeout_us:
            return int(self.timeout_us)
        return int(t + 0.5)


def footprint_reflectance(
    grey: np.ndarray, origin_xy: tuple[float, float], metres_per_pixel: float, x: float, y: float, radius_m: float
) -> float:
    """Weighted mean reflectance 0..1 of the texture ``grey`` (H, W) uint8 over a disc at (x, y) in [m].

    Row 0 of ``grey`` is the top (largest y), as in :class:`mjcf.track.FloorTexture` and MuJoCo's tex_data.
    """
    h, w = grey.shape[:2]
    ox, oy = origin_xy
    mpp = metres_per_pixel
    inv_r2 = 1.0 / (radius_m * radius_m)
    c0 = max(0, math.floor((x - radius_m - ox) / mpp))
    c1 = min(w - 1, math.floor((x + radius_m - ox) / mpp))
    r0 = max(0, math.floor(h - (y + radius_m - oy) / mpp))
    r1 = min(h - 1, math.floor(h - (y - radius_m - oy) / mpp))
    total = weight = 0.0
    for r in range(r0, r1 + 1):
        dy = oy + (h - r - 0.5) * mpp - y
        for c in range(c0, c1 + 1):
            dx = ox + (c + 0.5) * mpp - x
            q = (dx * dx + dy * dy) * inv_r2
            if q < 1.0:
                wt = (1.0 - q) * (1.0 - q)
                total += wt * float(grey[r, c])
                weight += wt
    if weight > 0.0:
        return total / (255.0 * weight)
    c = math.floor((x - ox) / mpp)
    r = math.floor(h - (y - oy) / mpp)
    if c < 0 or r < 0 or c >= w or r >= h:
        return 0.0
    return float(grey[r, c]) / 255.0


class NoiseSource:
    """splitmix64 and the Irwin–Hall noise of the C core, for a given 64-bit state."""

    def __init__(self, state: int):
        self.state = state & MASK64

    def next_u64(self) -> int:
        self.state = (self.state + 0x9E3779B97F4A7C15) & MASK64
        z = self.state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK64
        return z ^ (z >> 31)

    def noise(self) -> float:
        total = 0.0
        for _ in range(4):
            total += float(self.next_u64() >> 11) * (1.0 / 9007199254740992.0)
        return (total - 2.0) * 1.7320508075688772

    @staticmethod
    def phase_base(seed: int, mode: int) -> int:
        """The state a phase's readings draw from (reference of lf_noise_base)."""
        return NoiseSource((seed ^ ((mode & 0xFFFFFFFF) * 0xD1B54A32D192ED03)) & MASK64).next_u64()

    @staticmethod
    def reading(base: int, read: int, sensor: int) -> float:
        """The noise of ``sensor``'s ``read``-th reading of a phase (reference of lf_reading_noise)."""
        key = NoiseSource(((read << 8) | (sensor & 0xFF)) & MASK64).next_u64()
        return NoiseSource(base ^ key).noise()
