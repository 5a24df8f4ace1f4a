"""How high a reflectance sensor can sit and still tell a line from the ground, from the sensor model itself.

At height h the sensor sees a disc of radius r(h) = aperture + h·tan(half_angle), weighted by (1 − ρ²/r²)²
(:mod:`line_sensor.reflectance`); centred on a line of width w, the part of that weight on the line is f(h). The
line then reads t_line = t_unit·(1 + (h/h_c)²) / (ρ_line·f + ρ_ground·(1 − f)) and the ground
t_ground = t_unit·(1 + (h/h_c)²) / ρ_ground, both capped at the timeout. Calibration needs the difference
(the span) to reach a minimum: above some height the blur (f falls) and the dimming (both readings reach the
timeout) take it away. Noise is left out: this is the working range of the mean reading.
"""

from __future__ import annotations

import functools

import numpy as np

from line_sensor.reflectance import SensorModel

_GRID = 201  # points across the footprint's diameter for the line's share of the weight


@functools.lru_cache(maxsize=64)
def _line_share(radius_m: float, line_width_m: float) -> float:
    """f: the share of the footprint's weight that falls on a line of ``line_width_m`` through its centre."""
    if radius_m <= line_width_m / 2:
        return 1.0
    u = np.linspace(-radius_m, radius_m, _GRID)
    x, y = np.meshgrid(u, u)
    rho2 = (x * x + y * y) / (radius_m * radius_m)
    w = np.where(rho2 < 1.0, (1.0 - rho2) ** 2, 0.0)
    return float(w[np.abs(x) <= line_width_m / 2].sum() / w.sum())


def span_us(model: SensorModel, height_m: float, line_width_m: float, ground: float, line: float) -> float:
    """Mean reading over the line's centre minus over bare ground at ``height_m`` [µs] (reflectances 0..1)."""
    dim = 1.0 + (height_m / model.falloff_height_m) ** 2
    f = _line_share(model.footprint_radius(height_m), line_width_m)
    t_ground = min(model.t_unit_us * dim / ground, model.timeout_us)
    t_line = min(model.t_unit_us * dim / (line * f + ground * (1.0 - f)), model.timeout_us)
    return t_line - t_ground


def max_working_height_m(model: SensorModel, line_width_m: float, ground: float, line: float, min_span_us: float,
                         limit_m: float = 0.5) -> float:
    """The greatest height at which the span still reaches ``min_span_us`` (0 if not even at the floor); the
    span falls with height, so bisection finds it to 0.1 mm."""
    if span_us(model, 0.0, line_width_m, ground, line) < min_span_us:
        return 0.0
    lo, hi = 0.0, limit_m
    if span_us(model, hi, line_width_m, ground, line) >= min_span_us:
        return hi
    while hi - lo > 1e-4:
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if span_us(model, mid, line_width_m, ground, line) >= min_span_us else (lo, mid)
    return lo


def describe(model: SensorModel) -> str:
    return (f"sensor.falloff_height {model.falloff_height_m * 1000:g} mm, sensor.half_angle {model.half_angle_rad:g} rad, "
            f"sensor.timeout {model.timeout_us:g} µs")


__all__ = ["span_us", "max_working_height_m", "describe"]
