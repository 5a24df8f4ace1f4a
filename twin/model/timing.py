"""The robot's timing: when the duties a control tick decides reach the motors (issue 33).

On the robot a control tick does not act in the instant it reads. The tick's interrupt wakes the MCU, which charges
the QTR-RC lines and releases them (the readings' instant), waits until the last line has fallen or the read times
out (each line's decay time is its raw reading: long over the dark line, short over white), computes Eqs. 8–11 in
software floating point and writes the PWM compare values. The C loop (``twin/csrc/sim/mujoco_glue.c``) reads the
sensors at the tick and lets the new duties take effect

    release + max_i(raw_i) + compute

later (ten reads in a calibration tick), blended over the physics step in which they arrive, as the emulated MCU's
PWM is (``twin/csrc/pil/avr_motors.c``). The read's share is physics (the sensors' own readings); the two others are
the firmware's, measured on the emulated ATmega328P at 20 MHz by ``twin/csrc/pil/avr_timing.c``
(``lap --firmware avr --json``: ``mcu.release_mean_us``, ``mcu.compute_mean_us``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from twin.errors import TwinError
from twin.model.control import RUN

# Measured: the twin's firmware (twin/csrc/firmware/avr) on the emulated ATmega328P, seed 0, default gains on the
# default, oval and circle tracks and plainly tuned gains on the default track and the chicane (`python -m twin.run
# lap --firmware avr --json`, fields mcu.release_mean_us and mcu.compute_path_mean_us): release 21.8–21.9 µs (max
# 35.7); compute by code path (lf_step's branches; the interrupts that fall in it scatter each tick by ~55 µs):
# general 1241–1258 µs (6787 ticks, mean 1247.5), centred 1096–1131 µs (1715 ticks, mean 1100), lost 1114 µs (78
# ticks, the chicane: the only lap that lost the line), calibrate 950–964 µs (5 laps). One constant for all paths
# (1225 µs, the laps' overall mean) left the C loop's lap 0.215 % longer than the MCU's on the chicane with plainly
# tuned gains, whose laps take the paths in other shares (docs/models.md, "The robot's timing").
# tests/test_timing.py measures them again against these defaults.
RELEASE_US = 22.0
COMPUTE_US = 1248.0
COMPUTE_CENTRED_US = 1100.0
COMPUTE_LOST_US = 1115.0
COMPUTE_CALIBRATE_US = 955.0
# The compute's code paths, in the order of enum lf_compute_path (twin/csrc/sim/twin_core.h), and the model-space
# address of each one's time (under timing.; the Timing field is the address with _us).
COMPUTE_ADDRESSES = {"general": "compute", "centred": "compute_centred", "lost": "compute_lost",
                     "calibrate": "compute_calibrate"}
COMPUTE_PATHS = tuple(COMPUTE_ADDRESSES)
PWM_COUNTS = 256  # the 3pi's motor PWM: Timers 0 and 2, 8 bits (twin/csrc/firmware/avr/motors.c)


@dataclasses.dataclass(frozen=True)
class Timing:
    """The firmware's share of the robot's reaction time.

    Attributes:
      release_us: from the control tick to the sensor lines' release, in [µs].
      compute_us: from the read's end (the last line's fall, or the timeout) to the PWM write, in [µs], on the
        compute's general path: the line seen off centre (and an external controller's every tick).
      compute_centred_us: the same when the line reads exactly at the centre (e = 0) [µs].
      compute_lost_us: the same when the line is lost [µs].
      compute_calibrate_us: the same in a calibration tick [µs].
      pwm_counts: the motor PWM's period in timer counts: a duty is driven as the nearest whole count, at most one
        short of the period (full drive is 255/256 on the 3pi); 0 drives any duty as it is.
    """

    release_us: float = RELEASE_US
    compute_us: float = COMPUTE_US
    compute_centred_us: float = COMPUTE_CENTRED_US
    compute_lost_us: float = COMPUTE_LOST_US
    compute_calibrate_us: float = COMPUTE_CALIBRATE_US
    pwm_counts: int = PWM_COUNTS

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                unit = " µs" if field.name.endswith("_us") else ""
                raise TwinError(f"timing.{field.name.removesuffix('_us')}: must be a finite number >= 0{unit}, got {value!r}")

    def pwm_duty(self, duty: float) -> float:
        """``duty`` in [-1, 1] as the PWM drives it (reference of pwm_duty in mujoco_glue.c)."""
        if self.pwm_counts <= 0:
            return duty
        counts = min(math.floor(abs(duty) * self.pwm_counts + 0.5), self.pwm_counts - 1)
        return math.copysign(counts / self.pwm_counts, duty)

    def compute_time_us(self, path: str) -> float:
        """The compute's time [µs] on code ``path`` (one of :data:`COMPUTE_PATHS`)."""
        return getattr(self, f"{COMPUTE_ADDRESSES[path]}_us")

    def reaction_s(self, read_us: float, path: str = "general") -> float:
        """Seconds from a tick to its duties taking effect, for a read lasting ``read_us`` [µs] and a compute on code
        ``path``."""
        return (self.release_us + read_us + self.compute_time_us(path)) * 1e-6


def compute_path(mode: int, line_seen: bool, e_rad: float) -> str:
    """The code path of a tick whose firmware ran in ``mode`` (twin.model.control's IDLE, CALIBRATE, RUN), saw the
    line or not, and read bearing ``e_rad``: reference of lf_compute_path (twin/csrc/sim/twin_core.h)."""
    if mode != RUN:
        return "calibrate"
    if not line_seen:
        return "lost"
    return "centred" if e_rad == 0 else "general"


def applied_voltages(tick_s: np.ndarray, duty: np.ndarray, read_us: np.ndarray, timing: Timing, supply_v: float,
                     step_s: float, steps: int, paths: list[str] | None = None) -> np.ndarray:
    """The motor voltages [V] of each of ``steps`` physics steps from time 0, shape (steps, 2): the Python reference
    of the C loop's rule (decide, drive in mujoco_glue.c). Tick k at ``tick_s[k]`` [s] (on a step) decided
    ``duty[k]`` (left, right in [-1, 1]) from a read lasting ``read_us[k]`` [µs] and a compute on code path
    ``paths[k]`` (default: all general); its duties take effect :meth:`Timing.reaction_s` after it, and over the
    step they arrive in the voltage is the mean of the old and the new, weighted by the time each is in force; a tick
    takes a duty still waiting."""
    applied = np.zeros((steps, 2))
    now, pending, due, k = np.zeros(2), None, math.inf, 0
    for n in range(steps):
        t = n * step_s
        if k < len(tick_s) and abs(tick_s[k] - t) < 0.5 * step_s:
            if pending is not None:
                now = pending
            pending = np.array([timing.pwm_duty(float(d)) for d in duty[k]])
            due = t + timing.reaction_s(float(read_us[k]), paths[k] if paths is not None else "general")
            k += 1
        if pending is not None and due < t + step_s:
            old = max(0.0, (due - t) / step_s)
            applied[n] = old * now + (1.0 - old) * pending
            now, pending = pending, None
        else:
            applied[n] = now
    return applied * supply_v
