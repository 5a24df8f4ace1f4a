"""Eqs. 8–9 in Python: the reference the firmware's C (``twin/csrc/firmware``) is tested against.

Written as Pololu's QTRSensors library does it (``calibrate``, ``readCalibrated``, ``readLine``), in
integer arithmetic, so the reference and the C agree exactly.
"""

from __future__ import annotations

import math
from typing import Sequence

NOISE_THRESHOLD = 50  # readLine averages calibrated values above this
LINE_THRESHOLD = 200  # readLine sees the line if any calibrated value exceeds this
CAL_READS = 10  # readings per calibration call (LF_CAL_READS; Pololu's QTRSensors::calibrate)


def calibrate_call(cal_min: list[int], cal_max: list[int], reads: Sequence[Sequence[int]]) -> None:
    """One call of Pololu's ``calibrate`` (libpololu-avr, PololuQTRSensors.cpp, ``calibrateOnOrOff``: ten reads per
    call, :data:`CAL_READS`), in place: per sensor the calibrated maximum rises to the call's smallest reading and
    the calibrated minimum falls to its largest, so a single noise spike never widens the range."""
    for i in range(len(cal_min)):
        column = [int(r[i]) for r in reads]
        cal_max[i] = max(cal_max[i], min(column))
        cal_min[i] = min(cal_min[i], max(column))


def calibrate_update(cal_min: list[int], cal_max: list[int], call: list[list[int]], raw: Sequence[int]) -> None:
    """The firmware's calibration, one reading per loop iteration (``lf_calibrate_update``): the reading joins the call
    under way (``call``, in place); the :data:`CAL_READS`-th completes it (:func:`calibrate_call`) and starts the next."""
    call.append([int(r) for r in raw])
    if len(call) == CAL_READS:
        calibrate_call(cal_min, cal_max, call)
        call.clear()


def read_calibrated(raw: Sequence[int], cal_min: Sequence[int], cal_max: Sequence[int]) -> list[int]:
    """Eq. 8: s_i = (s_raw − s_min)·1000 / (s_max − s_min), integer division, clipped to 0..1000.

    A sensor that was never calibrated (max ≤ min) reads 0.
    """
    out = []
    for r, lo, hi in zip(raw, cal_min, cal_max):
        den = int(hi) - int(lo)
        value = (int(r) - int(lo)) * 1000 // den if den > 0 else 0  # floor ≠ C's truncation only below 0
        out.append(min(1000, max(0, value)))
    return out


def read_line(calibrated: Sequence[int], last_position: int) -> tuple[int, bool, int]:
    """Eq. 9's weighted average Σ s_i·i·1000 / Σ s_i as ``readLine`` computes it.

    Values above 50 count; the line is seen if any value exceeds 200. A lost line reports the end on the
    side it was last seen: 0 if ``last_position`` was left of centre, else (count − 1)·1000.

    Returns:
      (position, line_seen, new last_position).
    """
    n = len(calibrated)
    avg = total = 0
    seen = False
    for i, v in enumerate(calibrated):
        if v > LINE_THRESHOLD:
            seen = True
        if v > NOISE_THRESHOLD:
            avg += v * i * 1000
            total += v
    if not seen:
        return (0 if last_position < (n - 1) * 1000 // 2 else (n - 1) * 1000), False, last_position
    position = avg // total
    return position, True, position


def line_angle(position: int, count: int, pitch_m: float, sensor_distance_m: float) -> float:
    """Eq. 9: e = atan2(lateral offset of the line, S) in [rad], > 0 for a line to the left.

    The paper divides by 100000 for its 10 mm sensor pitch; here the pitch is a parameter. Sensor 0 is the
    leftmost, so a position below the centre (count − 1)·500 is a line to the left.
    """
    lateral_m = float((count - 1) * 500 - position) * pitch_m / 1000.0
    return math.atan2(lateral_m, sensor_distance_m)
