"""Robot laps from its telemetry records (:mod:`twin.telemetry.wire`): the samples between a START and its LAP or
FAIL event, each lap judged for plausibility before anyone may use it.

A lap is implausible when its sample times do not increase or the LAP comes before its last sample (less
``SPAN_TOLERANCE_S``), a position lies outside the header's sensor range (0 … (sensors − 1)·1000), the LAP's lap
time disagrees with its START→LAP span (by more than ``SPAN_TOLERANCE_S`` + ``SPAN_TOLERANCE_REL`` of it: 0.05 s +
1 %, for firmware clocks and millisecond rounding), or the lap time is not one a robot can drive on this track
(faster than ``MAX_SPEED_MPS`` = 5 m/s on average, or longer than the longest lap allowed).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from twin.telemetry.wire import Event, Header, Sample


def line_sides_m(position: np.ndarray, sensors: int, pitch_m: float) -> np.ndarray:
    """The signed offset of the line from the sensor array's centre [m] at each line position (0 … (sensors − 1)·1000
    across the array), + towards the array's last sensor: what a robot's telemetry and the twin's trace say alike."""
    return (np.asarray(position, float) - (sensors - 1) * 500.0) / 1000.0 * pitch_m


def line_offsets_m(position: np.ndarray, sensors: int, pitch_m: float) -> np.ndarray:
    """|offset| of the line from the sensor array's centre [m] at each line position (:func:`line_sides_m`)."""
    return np.abs(line_sides_m(position, sensors, pitch_m))


@dataclasses.dataclass
class RobotLap:
    index: int
    lap_time_s: float | None  # None: the robot reported a failure
    t: np.ndarray  # sample times since the lap's start [s]
    pos: np.ndarray
    wl: np.ndarray
    wr: np.ndarray
    implausible: str | None = None  # why this lap cannot be what a robot on this track did
    robot: str | None = None  # the robot's id from the lap's header (None: a version 1 robot)
    gains_seq: int | None = None  # the command whose gains were in force, from the lap's header (0: as booted)
    failure: str | None = None  # the FAIL event's reason
    sensors: int = 8  # the header's sensor count: positions run 0 … (sensors − 1)·1000


SPAN_TOLERANCE_S = 0.05  # a LAP's lap time may differ from its START→LAP span by this much, plus …
SPAN_TOLERANCE_REL = 0.01  # … this fraction of it (firmware clocks and millisecond rounding)
MAX_SPEED_MPS = 5.0  # no line follower of this class averages more (the 3pi+ Hyper edition tops out near 4 m/s)
DEFAULT_SENSORS = 8


class LapAssembler:
    """Wire records → laps. A lap is the samples between a START and its LAP or FAIL event, judged for
    plausibility against the track length and the longest lap (see the module docstring)."""

    def __init__(self, track_length_m: float = 0.0, max_lap_s: float = math.inf):
        self.track_length_m, self.max_lap_s = track_length_m, max_lap_s
        self.sensors = DEFAULT_SENSORS
        self.header: Header | None = None  # the last header: the robot's id and the gains in force
        self.start: float | None = None
        self.rows: list[tuple[float, float, float, float]] = []
        self.problem: str | None = None  # the first implausibility seen in the current lap
        self.count = 0

    def feed(self, rec) -> RobotLap | None:
        if isinstance(rec, Header):
            self.sensors, self.header = rec.sensors, rec
            return None
        if isinstance(rec, Event) and rec.event == "START":
            self.start, self.rows, self.problem = rec.t, [], None
            return None
        if self.start is None:
            return None  # joined mid-lap: wait for the next start
        if isinstance(rec, Sample):
            t = rec.t - self.start
            if self.rows and t <= self.rows[-1][0]:
                self.problem = self.problem or f"sample time {rec.t:g} s does not follow {self.rows[-1][0] + self.start:g} s"
            if not 0 <= rec.pos <= (self.sensors - 1) * 1000:
                self.problem = self.problem or f"line position {rec.pos} outside 0…{(self.sensors - 1) * 1000} for {self.sensors} sensors"
            self.rows.append((t, rec.pos, rec.wl, rec.wr))
            return None
        if isinstance(rec, Event) and rec.event in ("LAP", "FAIL"):
            problem = self.problem or (self._judge_lap(rec) if rec.event == "LAP" else None)
            a = np.array(self.rows) if self.rows else np.zeros((0, 4))
            h = self.header
            lap = RobotLap(self.count, rec.lap_time_s, a[:, 0], a[:, 1], a[:, 2], a[:, 3], problem,
                           h.robot if h else None, h.gains_seq if h else None, rec.reason, self.sensors)
            self.count += 1
            self.start, self.rows, self.problem = None, [], None
            return lap
        return None

    def _judge_lap(self, rec: Event) -> str | None:
        span = rec.t - self.start
        if self.rows and span < self.rows[-1][0] - SPAN_TOLERANCE_S:  # (a sample may carry the crossing tick)
            return f"LAP at {rec.t:g} s comes before its last sample at {self.rows[-1][0] + self.start:g} s"
        if abs(rec.lap_time_s - span) > SPAN_TOLERANCE_S + SPAN_TOLERANCE_REL * span:
            return f"lap time {rec.lap_time_s:g} s disagrees with its START→LAP span of {span:g} s"
        fastest = self.track_length_m / MAX_SPEED_MPS
        if rec.lap_time_s < fastest:
            return f"lap time {rec.lap_time_s:g} s is faster than {MAX_SPEED_MPS:g} m/s around {self.track_length_m:.2f} m"
        if rec.lap_time_s > self.max_lap_s:
            return f"lap time {rec.lap_time_s:g} s is longer than the twin's lap limit of {self.max_lap_s:g} s"
        return None
