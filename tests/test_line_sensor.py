"""Sensor model: the C sensor physics equals its Python reference bit for bit; readings behave physically."""

from __future__ import annotations

import ctypes
import math
import random

import numpy as np
import pytest

from line_sensor.reflectance import NoiseSource, SensorModel, footprint_reflectance
from mjcf.track import GROUND_GREY, LINE_GREY, Track, builtin
from twin.core.native import Texture, lib, sensor_to_c

pytestmark = pytest.mark.quick  # the whole module is in the quick tier (tests/test_tiers.py)


@pytest.fixture(scope="module")
def floor():
    track = Track("straight-ish", builtin("oval").centre, line_width_m=0.019)
    return track, track.rasterise(metres_per_pixel=0.001)


def c_texture(tex) -> tuple[Texture, np.ndarray]:
    data = np.ascontiguousarray(np.repeat(tex.grey[:, :, None], 3, axis=2))  # RGB, as MuJoCo holds it
    t = Texture(data.ctypes.data_as(ctypes.POINTER(ctypes.c_uint8)), tex.grey.shape[1], tex.grey.shape[0], 3,
                tex.origin_xy[0], tex.origin_xy[1], tex.metres_per_pixel)
    return t, data


def test_footprint_c_equals_python(floor):
    track, tex = floor
    t, keep = c_texture(tex)
    rng = random.Random(3)
    for _ in range(300):
        p = track.point_at(rng.uniform(0, track.length_m)) + np.array([rng.gauss(0, 0.01), rng.gauss(0, 0.01)])
        radius = rng.uniform(0.0002, 0.006)
        c = lib.lf_footprint_reflectance(ctypes.byref(t), p[0], p[1], radius)
        py = footprint_reflectance(tex.grey, tex.origin_xy, tex.metres_per_pixel, p[0], p[1], radius)
        assert c == py
    del keep


def test_response_and_noise_c_equal_python():
    model = SensorModel(noise_rel=0.05)
    cm = sensor_to_c(model)
    rng = random.Random(5)
    for _ in range(2000):
        rho, h, n = rng.uniform(0, 1), rng.uniform(0, 0.01), rng.gauss(0, 1)
        assert lib.lf_raw_reading(ctypes.byref(cm), rho, h, n) == model.raw_reading(rho, h, n)
        assert lib.lf_footprint_radius(ctypes.byref(cm), h) == model.footprint_radius(h)
    state = ctypes.c_uint64(12345)
    ref = NoiseSource(12345)
    draws = []
    for _ in range(5000):
        c = lib.lf_noise(ctypes.byref(state))
        assert c == ref.noise()
        draws.append(c)
    # zero mean, unit variance: 5000 draws, 4-sigma bounds on the sample statistics
    assert abs(np.mean(draws)) < 4 / math.sqrt(5000)
    assert abs(np.std(draws) - 1.0) < 0.05


def test_reading_across_a_line_edge_is_monotonic(floor):
    """Moving a sensor from the ground onto the tape, its reading only ever rises (darker = longer discharge)."""
    track, tex = floor
    model = SensorModel(noise_rel=0.0)
    s = 0.3  # on the first straight
    p = track.point_at(s)
    tangent = track.point_at(s + 0.001) - p
    normal = np.array([-tangent[1], tangent[0]]) / np.hypot(*tangent)
    half = track.line_width_m / 2
    readings, reflectances = [], []
    for off in np.linspace(half + 0.008, half - 0.008, 161):  # 16 mm across the edge, 0.1 mm steps
        q = p + off * normal
        rho = footprint_reflectance(tex.grey, tex.origin_xy, tex.metres_per_pixel, q[0], q[1], model.footprint_radius(0.003))
        reflectances.append(rho)
        readings.append(model.raw_reading(rho, 0.003, 0.0))
    assert np.all(np.diff(reflectances) <= 1e-12)
    assert np.all(np.diff(readings) >= 0)
    assert reflectances[0] == pytest.approx(GROUND_GREY / 255, abs=1e-9)  # fully on the ground
    assert reflectances[-1] == pytest.approx(LINE_GREY / 255, abs=1e-9)  # fully on the tape
    assert readings[0] < 300 and readings[-1] > 2000  # white ≈ 200 µs, black ≈ 2400 µs (QTR-RC)


def test_footprint_grows_with_height_and_light_falls_off(floor):
    track, tex = floor
    model = SensorModel(noise_rel=0.0)
    p = track.point_at(0.3)
    # over the line's centre, a footprint wider than the 19 mm tape sees white ground, more as it rises
    rho = [footprint_reflectance(tex.grey, tex.origin_xy, tex.metres_per_pixel, p[0], p[1], model.footprint_radius(h))
           for h in (0.002, 0.018, 0.024, 0.03)]  # radius 2.6, 11.3, 14.6, 17.9 mm
    assert rho[0] == pytest.approx(LINE_GREY / 255, abs=1e-9)
    assert np.all(np.diff(rho) > 0)
    # on white, the raw time grows with height as 1 + (h/h_c)^2 (within the rounding to whole µs)
    t3, t6 = model.raw_reading(0.9, 0.003, 0.0), model.raw_reading(0.9, 0.006, 0.0)
    assert t6 / t3 == pytest.approx((1 + 1.0) / (1 + 0.25), rel=0.01)
    assert model.raw_reading(0.0, 0.003, 0.0) == model.timeout_us  # no light back: the read times out


def test_bad_sensor_model_is_refused():
    from line_sensor.geometry import SensorError

    with pytest.raises(SensorError, match="sensor.aperture_m"):
        SensorModel(aperture_m=float("nan"))
    with pytest.raises(SensorError, match="sensor.timeout_us"):
        SensorModel(timeout_us=70000)


def test_working_height_agrees_with_the_sensor_physics():
    """The height limit of line_sensor.working_range (a continuous integral) against the reference sensor physics
    on a rasterised line (texture, footprint average, RC time): just below the limit the span reaches the
    calibration minimum, just above it does not."""
    from line_sensor.reflectance import SensorModel, footprint_reflectance
    from line_sensor.working_range import max_working_height_m
    from mjcf.track import GROUND_GREY, LINE_GREY

    model, width, mpp, min_span = SensorModel(), 0.019, 0.0002, 300.0
    size = 801  # 160 mm of floor, the line down the middle
    x = (np.arange(size) - size // 2) * mpp
    grey = np.where(np.abs(x) <= width / 2, LINE_GREY, GROUND_GREY).astype(np.uint8)[None, :].repeat(size, axis=0)
    origin = (-(size // 2) * mpp, -(size // 2) * mpp)

    def span(h):
        r = model.footprint_radius(h)
        on_line = footprint_reflectance(grey, origin, mpp, 0.0, 0.0, r)
        ground = GROUND_GREY / 255
        return model.raw_reading(on_line, h, 0.0) - model.raw_reading(ground, h, 0.0)

    top = max_working_height_m(model, width, GROUND_GREY / 255, LINE_GREY / 255, min_span)
    assert 0.01 < top < 0.05
    assert span(top - 0.001) >= min_span > span(top + 0.001)
