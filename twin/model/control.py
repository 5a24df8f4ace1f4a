"""Control and software model (paper §3.6, Eqs. 10–11) in Python: the reference of the firmware's C.

The firmware (``twin/csrc/firmware/line_follower.c``) runs every Δt: Eqs. 8–9 turn raw readings into the
line angle e, Eqs. 10–11 turn e into (v, ω), and (v, ω) becomes PWM duty for each motor. This module
repeats every step with the same operations in the same order, so tests can demand bit equality.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Sequence

from line_sensor.geometry import MAX_SENSORS
from line_sensor.processing import calibrate_update, line_angle, read_calibrated, read_line
from twin.errors import TwinError

IDLE, CALIBRATE, RUN = 0, 1, 2
QUARTER_TICKS_MAX = 2**29  # LF_QUARTER_TICKS_MAX: tick counts saturate as the firmware's do
TICKS_MAX = 2**32 - 1  # LF_TICKS_MAX (uint32)
INT32_MAX = 2**31 - 1  # cal_sweeps is an int32_t in C


@dataclasses.dataclass(frozen=True)
class ControlParams:
    """What the firmware is told (``lf_params`` in C). Lengths [m], angles [rad], time [s].

    Attributes:
      count, pitch_m, sensor_distance_m: the sensor array (count, spacing, S).
      v_max, k_b, k_p, k_i, k_d: Eqs. 10–11 (x of Eq. 13) in [m/s], [m/s/rad], [1/s], [1/s²], [-].
      dt_s: control period Δt.
      wheel_radius_m, half_track_m: R and L.
      wheel_speed_max: wheel speed the firmware expects at full duty [rad/s] (``control.full_speed``).
      accel_max: ramp limit of the forward-speed command [m/s²].
      integral_limit: anti-windup bound on ∫e dt [rad·s].
      cal_duty, cal_sweep_rad, cal_sweeps: the in-place calibration turn (duty, nominal sweep, sweeps).
    """

    count: int
    pitch_m: float
    sensor_distance_m: float
    v_max: float
    k_b: float
    k_p: float
    k_i: float
    k_d: float
    dt_s: float
    wheel_radius_m: float
    half_track_m: float
    wheel_speed_max: float
    accel_max: float
    integral_limit: float
    cal_duty: float
    cal_sweep_rad: float
    cal_sweeps: int

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if not isinstance(v, (int, float)) or not math.isfinite(v):
                raise TwinError(f"control.{f.name}: must be a finite number, got {v!r}")
            if v < 0:
                raise TwinError(f"control.{f.name}: must be >= 0, got {v:g}")
        for name in ("dt_s", "wheel_radius_m", "half_track_m", "wheel_speed_max", "sensor_distance_m", "pitch_m", "cal_duty"):
            if getattr(self, name) <= 0:
                raise TwinError(f"control.{name}: must be > 0, got {getattr(self, name):g}")
        # the C arrays hold MAX_SENSORS readings, and ctypes would wrap an int32 silently
        if not (isinstance(self.count, int) and 1 <= self.count <= MAX_SENSORS):
            raise TwinError(f"control.count: must be a whole number in [1, {MAX_SENSORS}], got {self.count!r}")
        if not (isinstance(self.cal_sweeps, int) and self.cal_sweeps <= INT32_MAX):
            raise TwinError(f"control.cal_sweeps: must be a whole number <= {INT32_MAX}, got {self.cal_sweeps!r}")


@dataclasses.dataclass
class FirmwareState:
    """``lf_state`` in C: calibration, readLine memory, PID memory and the last outputs."""

    cal_min: list[int]
    cal_max: list[int]
    value: list[int]
    position: int = 0
    last_position: int = 0
    line_seen: bool = False
    mode: int = IDLE
    tick: int = 0
    e: float = 0.0
    e_prev: float = 0.0
    integral: float = 0.0
    v: float = 0.0
    omega: float = 0.0
    duty_left: float = 0.0
    duty_right: float = 0.0
    call: list[list[int]] = dataclasses.field(default_factory=list)  # the calibration call under way: its readings

    @classmethod
    def uncalibrated(cls, count: int, timeout_us: int) -> "FirmwareState":
        return cls(cal_min=[timeout_us] * count, cal_max=[0] * count, value=[0] * count)

    def reset(self, mode: int) -> None:
        """Start a phase; the calibration is kept, a calibration call under way dropped (``lf_reset``)."""
        cal_min, cal_max, value = self.cal_min, self.cal_max, self.value
        self.__init__(cal_min, cal_max, value, mode=mode)


def control(s: FirmwareState, p: ControlParams, e: float) -> None:
    """Eqs. 10–11 once per period (``lf_control``): v = v_max − K_B|e| ≥ 0, ramped up at accel_max;
    ω = K_P e + K_I ∫e dt + K_D de/dt with the integral clamped and no derivative on the first tick."""
    v_target = p.v_max - p.k_b * abs(e)
    v_ramp = s.v + p.accel_max * p.dt_s
    derivative = 0.0 if s.tick == 0 else (e - s.e_prev) / p.dt_s
    if v_target < 0:
        v_target = 0.0
    s.integral += e * p.dt_s
    s.integral = min(p.integral_limit, max(-p.integral_limit, s.integral))
    s.e = e
    s.v = v_target if v_target < v_ramp else v_ramp
    s.omega = p.k_p * e + p.k_i * s.integral + p.k_d * derivative
    s.e_prev = e


def wheel_duties(p: ControlParams, v: float, omega: float) -> tuple[float, float]:
    """(v, ω) → left and right PWM duty (``lf_wheel_duties``): wheel speeds (v ∓ ωL)/R over the no-load
    speed; when a wheel saturates, both shift together (turn rate kept, forward speed given up)."""
    scale = 1.0 / (p.wheel_radius_m * p.wheel_speed_max)
    left = (v - omega * p.half_track_m) * scale
    right = (v + omega * p.half_track_m) * scale
    hi = max(left, right)
    if hi > 1.0:
        left -= hi - 1.0
        right -= hi - 1.0
    lo = min(left, right)
    if lo < -1.0:
        left += -1.0 - lo
        right += -1.0 - lo
    return min(1.0, max(-1.0, left)), min(1.0, max(-1.0, right))


def _quarter_ticks(p: ControlParams) -> int:
    omega = p.cal_duty * p.wheel_speed_max * p.wheel_radius_m / p.half_track_m
    ticks = p.cal_sweep_rad / (omega * p.dt_s) if omega * p.dt_s > 0 else math.inf  # C divides to inf
    if not ticks < QUARTER_TICKS_MAX:
        return QUARTER_TICKS_MAX
    return 1 if ticks < 1.0 else int(ticks + 0.5)


def calibration_ticks(p: ControlParams) -> int:
    """Length of the calibration turn in ticks: per sweep a quarter right, a half left, a quarter right;
    saturates at ``TICKS_MAX`` as the firmware's uint32 does."""
    return min(4 * _quarter_ticks(p) * max(p.cal_sweeps, 0), TICKS_MAX)


def calibration_direction(p: ControlParams, tick: int) -> int:
    """+1 turning left, −1 right, 0 when the calibration is over."""
    q = _quarter_ticks(p)
    if tick >= calibration_ticks(p):
        return 0
    return 1 if (tick % (4 * q)) // q in (1, 2) else -1


def firmware_step(s: FirmwareState, p: ControlParams, raw: Sequence[int]) -> None:
    """One loop iteration (``lf_step``): calibrate while turning in place, or follow the line."""
    s.value = read_calibrated(raw, s.cal_min, s.cal_max)
    if s.mode == CALIBRATE:
        direction = calibration_direction(p, s.tick)
        calibrate_update(s.cal_min, s.cal_max, s.call, raw)
        s.duty_left = -direction * p.cal_duty
        s.duty_right = direction * p.cal_duty
        if direction == 0:
            s.mode = IDLE
    elif s.mode == RUN:
        s.position, s.line_seen, s.last_position = read_line(s.value, s.last_position)
        control(s, p, line_angle(s.position, p.count, p.pitch_m, p.sensor_distance_m))
        s.duty_left, s.duty_right = wheel_duties(p, s.v, s.omega)
    else:
        s.duty_left = s.duty_right = 0.0
    s.tick = min(s.tick + 1, TICKS_MAX)


# Nominal firmware settings: the control model's defaults in the model space (``control.*``).
# Gains were hand-tuned on the default robot and track to complete the lap with margin; the tuner improves them.
DEFAULTS = {
    "v_max": 0.6,          # [m/s] about half the 3pi+'s top speed at 6 V
    "k_b": 0.5,            # [m/s/rad]
    "k_p": 15.0,           # [1/s]
    "k_i": 0.0,            # [1/s²]
    "k_d": 0.3,            # [-]
    "dt": 0.005,           # [s] a 200 Hz loop: a QTR-RC read takes up to its 2.5 ms timeout
    "accel_max": 3.0,      # [m/s²] below the ≈ 9 m/s² grip limit at μ = 0.9: launches without wheelspin
    "integral_limit": 0.5, # [rad·s]
    "cal_duty": 0.15,      # Pololu's example turns at 40/400 of full speed while calibrating
    "cal_sweep": 1.3,      # [rad] nominal sweep each way; the outer sensors need ≈ 0.7 rad at S = 40 mm, and the
                           # caster's drag shortens the turn at a 4.8 V battery (the robust envelope's corner)
    "cal_sweeps": 2,
}
