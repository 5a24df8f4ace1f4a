"""Why a calibration turn left a sensor without range: the likely cause, named with its fix.

Checked in order, each from the twin's own models: the array too high for the sensor model to tell the line
from the ground (:mod:`line_sensor.working_range`); a turn too short for the sensor to reach the line (turning
in place by θ about the axle brings a sensor at lateral offset y and distance S over the line's centre at
θ = atan(|y| / S), and over its far edge at atan((|y| + w/2) / S)); else a turn that fell short of its plan,
which is timed for the firmware's expected wheel speed (``control.cal_duty`` × ``control.full_speed``): either
so fast that the array turns more than half the line's angular width (w / S) between two reads and can miss it,
or (the rest) motors that do not reach that speed with this robot in the time the sweep is planned to take.
"""

from __future__ import annotations

import math

from line_sensor.working_range import span_us
from mjcf.track import GROUND_GREY, LINE_GREY


def calibration_cause(twin, params, sensor, min_span_us: float) -> str:
    """A short clause for a failed calibration of a lap run with ``params`` (``ControlParams``) and ``sensor``
    (``SensorModel``)."""
    h = twin.sensor_height()
    width = twin.space.get("environment.line_width")
    contrast = span_us(sensor, h, width, GROUND_GREY / 255, LINE_GREY / 255)
    if contrast < min_span_us:
        return (f"sensor height: {h * 1000:.1f} mm above the floor, where the line reads only {contrast:.0f} µs "
                f"darker than the ground (needs {min_span_us:g}); mount the array lower "
                "(--sensor-mount, or cad.sensor_height)")
    outer = (params.count - 1) / 2 * params.pitch_m
    needed = math.atan2(outer + width / 2, params.sensor_distance_m)
    if needed > params.cal_sweep_rad:
        return (f"turn too short: the outer sensors pass the whole line only at ±{needed:.2f} rad, the turn goes "
                f"±{params.cal_sweep_rad:g} rad; raise control.cal_sweep")
    omega = params.cal_duty * params.wheel_speed_max * params.wheel_radius_m / params.half_track_m  # [rad/s] planned
    step, line = omega * params.dt_s, width / params.sensor_distance_m  # [rad] per read, the line's angular width
    if step > line / 2:
        return (f"turn too fast: the array turns {step:.3f} rad between reads, more than half the line's width as "
                f"the sensors see it ({line:.3f} rad), so reads can miss the line; lower control.cal_duty")
    quarter_s = params.cal_sweep_rad / omega  # each sweep's first quarter, planned
    return (f"turn fell short of its plan: it is timed for wheels at control.cal_duty {params.cal_duty:g} × "
            f"control.full_speed {params.wheel_speed_max:.3g} rad/s, {quarter_s:.2g} s a quarter sweep, which these "
            "motors do not reach with this robot (too weak, or too slow to get up to speed in so short a sweep); "
            "raise control.cal_sweep or control.cal_duty, or choose a stronger motor (--motor, --set motor.*)")
