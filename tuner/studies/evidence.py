"""What a lap says about why a design is as fast as it is: the evidence a design report backs its trends with.

From one traced lap of the design's converged gains:

* ``at_voltage_limit``: share of the lap with a motor at its voltage limit (|u| ≥ 98 % of the supply): the
  motor, not the controller, sets the pace (speed-limited);
* ``high_torque``: share of the lap with a motor asked for ≥ half its voltage while turning below a third of
  its no-load speed: near stall, torque-limited (a hard launch, a tight turn's inner wheel pushing back);
* ``slip``: mean relative difference between the wheels' rolling speed R·(ω_l + ω_r)/2 and the body's ground
  speed, over the lap at speed: grip-limited;
* ``look_ahead_ms``: how long the robot takes to cover its sensor distance S at its mean speed: how early a bend
  is seen;
* ``mean_speed_mps``, ``peak_turn_radps``.
"""

from __future__ import annotations

import numpy as np

from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin

LIMIT_FRACTION = 0.98
MOVING_MPS = 0.1  # [m/s] slip is measured only above this ground speed


def evidence(twin: DigitalTwin, seed: int = 1) -> dict:
    """The metrics above for one lap of the twin's current values (its gains already set)."""
    r = run_laps(twin, [{}], seed=seed, nthread=1)[0]
    tr = r.trace
    if tr is None or len(tr.time_s) < 3:
        return {}
    supply = twin.power().nominal_v  # the voltage duty 1 commands (the trace's u is duty × this)
    full = twin.space.get("control.full_speed")
    radius = twin.info.wheel_radius
    u = np.abs(np.column_stack([tr.column("u_left_v"), tr.column("u_right_v")]))
    w = np.abs(np.column_stack([tr.column("wheel_left_radps"), tr.column("wheel_right_radps")]))
    running = tr.column("mode") == tr.column("mode")[-1]  # the lap itself, after the calibration turn
    t = tr.time_s
    xy = np.column_stack([tr.column("x_m"), tr.column("y_m")])
    ground = np.linalg.norm(np.gradient(xy, t, axis=0), axis=1)
    rolling = radius * (tr.column("wheel_left_radps") + tr.column("wheel_right_radps")) / 2
    moving = running & (ground > MOVING_MPS)
    mean_speed = float(np.mean(ground[running])) if running.any() else 0.0
    return {
        "at_voltage_limit": float(np.mean(np.any(u >= LIMIT_FRACTION * supply, axis=1)[running])),
        "high_torque": float(np.mean(np.any((u >= 0.5 * supply) & (w < full / 3), axis=1)[running])),
        "slip": float(np.mean(np.abs(rolling[moving] - ground[moving]) / ground[moving])) if moving.any() else 0.0,
        "look_ahead_ms": 1000 * twin.sensor_distance / mean_speed if mean_speed > 0 else None,
        "mean_speed_mps": mean_speed,
        "peak_turn_radps": float(np.max(np.abs(tr.column("omega_radps")[running]))) if running.any() else 0.0,
        "lap_completed": r.completed,
    }


def describe(e: dict) -> str:
    if not e:
        return "no evidence (the lap left no trace)"
    return (f"motor at its voltage limit {e['at_voltage_limit']:.0%} of the lap, near stall {e['high_torque']:.0%}, "
            f"slip {e['slip']:.1%}, mean speed {e['mean_speed_mps']:.2f} m/s, looks {e['look_ahead_ms']:.0f} ms ahead")
