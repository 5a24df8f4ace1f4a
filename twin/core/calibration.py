"""The calibration turn judged, for the C loop and the firmware binary alike: a turn too long to simulate, or one
that left a sensor without range, with the likely cause named with its fix.

Causes are checked in order, each from the twin's own models: the array too high for the sensor model to tell the line
from the ground (:mod:`line_sensor.working_range`); a turn too short for the sensor to reach the line (turning
in place by θ about the axle brings a sensor at lateral offset y and distance S over the line's centre at
θ = atan(|y| / S), and over its far edge at atan((|y| + w/2) / S)); else a turn that fell short of its plan,
which is timed for the firmware's expected wheel speed (``control.cal_duty`` × ``control.full_speed``): either
so fast that the array turns more than half the line's angular width (w / S) between two reads and can miss it,
or (the rest) motors that do not reach that speed with this robot in the time the sweep is planned to take.
"""

from __future__ import annotations

import math

from typing import Sequence

import numpy as np

from line_sensor.working_range import span_us
from mjcf.track import GROUND_GREY, LINE_GREY
from mjcf.world import MOTORS
from motors.actuator import USER_JOINT_FRICTION
from twin.model.control import calibration_ticks


def turn_too_long(params, limits) -> str | None:
    """Why a turn planned by ``params`` (``ControlParams``) is not simulated at all, or None: it would take longer
    than ``limits.calibration_timeout_s`` (``LapLimits``) of simulated time."""
    seconds = calibration_ticks(params) * params.dt_s
    if seconds <= limits.calibration_timeout_s:
        return None
    return (f"the calibration turn would take {seconds:.6g} s (limit {limits.calibration_timeout_s:g} s simulated): "
            "raise control.cal_duty or control.full_speed, or lower control.cal_sweep or control.cal_sweeps")


def range_too_small(twin, params, sensor, cal_min_us: Sequence[float], cal_max_us: Sequence[float],
                    limits) -> str | None:
    """Why the turn's calibration (per-sensor min and max [µs]) cannot be used, or None: a sensor spans less than
    ``limits.min_calibration_range_us``; named with its likely cause."""
    spans = np.asarray(cal_max_us) - np.asarray(cal_min_us)
    if np.min(spans) >= limits.min_calibration_range_us:
        return None
    bad = int(np.argmin(spans))
    seen = (f"spans only {spans[bad]:g} µs" if spans[bad] > 0 else
            "has no range at all (its calibrated maximum never rose above its minimum)")
    return (f"sensor {bad} {seen} after the calibration turn; likely "
            f"{calibration_cause(twin, params, sensor, limits.min_calibration_range_us)}")


def wheel_braking(twin, wheel_speed_radps: float) -> str:
    """A clause on what the description's own wheel joints take from the motors at ``wheel_speed_radps`` [rad/s]:
    their damping (τ = d·ω) and friction loss [N·m] (URDF <dynamics>, mjcf.urdf_parse), or "" when they take
    nothing."""
    model = twin.model()
    dofs = [model.jnt_dofadr[model.joint(j).id] for j in twin.info.wheel_joints]
    damping = max(float(model.dof_damping[d]) for d in dofs)
    # the joints' friction loss also holds the motors' own dry friction (motors.actuator): only the description's
    friction = max(float(model.actuator_user[model.actuator(a).id, USER_JOINT_FRICTION]) for a in MOTORS)
    if damping <= 0 and friction <= 0:
        return ""
    stall = twin.motor().stall_torque_wheel(twin.physics().supply_voltage)
    return (f"; the wheel joints' own damping {damping:g} N·m·s/rad and friction loss {friction:g} N·m take "
            f"{damping * wheel_speed_radps + friction:.3g} N·m a wheel at that speed, against the motor's {stall:.3g} "
            "N·m stall torque at the wheel (the description's <dynamics>: check their units and size)")


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
            "raise control.cal_sweep or control.cal_duty, or choose a stronger motor (--motor, --set motor.*)"
            + wheel_braking(twin, params.cal_duty * params.wheel_speed_max))
