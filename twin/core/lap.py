"""Judging a lap from the closed loop's trace: progress along the centre line, completion, failures.

The robot starts on the start line at progress 0. Progress is the arc length of the centre-line point
nearest the centre of rotation (computed by the C loop at every tick, ``lf_locate``), unwrapped tick by tick; the lap completes when it reaches the track length
(the crossing time is interpolated linearly between the two control ticks around it). A lap fails when

* ``off_track``: the centre of rotation is more than ``max_cross_track_m`` from the line, or its progress
  jumps by more than ``max_progress_jump_m`` in one tick (it crossed to another part of the track);
* ``line_lost``: no sensor has seen the line (calibrated value > 200) for ``max_line_lost_s`` (judged for the twin's
  own firmware, whose belief the trace carries; not for a controller FMU or a 3pi program, judged by the rest);
* ``wrong_way``: its progress fell more than ``max_backtrack_m`` behind the furthest it had reached (the robot turned
  round, after a slide say, and follows the line backwards: it would never finish, and the lap ends there instead of
  at the timeout);
* ``timeout``: the lap is not done after ``timeout_s`` of simulated time;
* ``diverged``: the physics produced a non-finite state or MuJoCo raised an error;
* ``calibration``: after the calibration turn some sensor's range max − min is below
  ``min_calibration_range_us`` (it never saw both the line and the ground), or the turn would take longer
  than ``calibration_timeout_s`` of simulated time (then it is not simulated at all);
* ``refused``: the C loop found that a simulation's userdata did not fit the model it was stepped with
  (a program error, reported as a result rather than a crash);
* ``firmware_stalled``: the robot's binary in the loop stopped (:mod:`twin.pil.lap`);
* ``stopped``: undecided, ended early because its caller no longer needed it (``run_laps``' ``deadline_s`` or ``cut``):
  its ``simulated_s`` is how far it got, a lower bound of when it would have ended.

A failed lap is a result, not an exception. The codes are :class:`twin.core.outcomes.Outcome`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mjcf.track import Track
from twin.core import native as core
from twin.core.outcomes import LAP_STATUS, Outcome
from twin.errors import TwinError

COL = {name: i for i, name in enumerate(core.RECORD_FIELDS)}
_UNSTARTED = core.JudgeC()  # a C judge that has seen no record (all zeros: running, not started)


@dataclasses.dataclass(frozen=True)
class LapLimits:
    """Failure thresholds (see the module docstring). Lengths [m], times [s], readings [µs]."""

    max_cross_track_m: float = 0.10
    max_progress_jump_m: float = 0.10
    max_line_lost_s: float = 0.5
    timeout_s: float = 60.0
    min_calibration_range_us: float = 300.0
    # the default turn takes 1.9 s; 20 s allows a turn ten times slower, while a near-stalled turn (hours of
    # simulated time, e.g. control.cal_duty 0.01 with control.full_speed 1) fails at once instead of hanging
    calibration_timeout_s: float = 20.0
    # a line follower's centre of rotation does not move back along the line while it follows it (a pivot in a
    # hairpin moves it back a few cm at most): 25 cm back, more than the off-track and jump limits, is a turn round
    max_backtrack_m: float = 0.25

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise TwinError(f"lap limit {f.name}: must be a finite number > 0, got {v!r}")


@dataclasses.dataclass(frozen=True)
class LapTrace:
    """The run at every control tick: ``records`` (n, RECORD_WORDS) as written by the C loop, and the
    centre line's view of it. Columns by name: ``trace.column("e_rad")``."""

    records: np.ndarray
    progress_m: np.ndarray  # unwrapped progress along the centre line
    cross_track_m: np.ndarray  # signed distance of the centre of rotation from the line (+ left)
    count: int  # sensors

    def column(self, name: str) -> np.ndarray:
        return self.records[:, COL[name]]

    @property
    def time_s(self) -> np.ndarray:
        return self.column("time_s")

    @property
    def raw_us(self) -> np.ndarray:
        return self.records[:, core.RAW_COLUMN : core.RAW_COLUMN + self.count]

    @property
    def calibrated(self) -> np.ndarray:
        return self.records[:, core.CALIBRATED_COLUMN : core.CALIBRATED_COLUMN + self.count]


@dataclasses.dataclass(frozen=True)
class LapResult:
    """One lap. ``lap_time_s`` is None unless ``completed``; ``failure`` names why not (module docstring)."""

    completed: bool
    failure: str | None
    detail: str
    lap_time_s: float | None
    simulated_s: float  # simulated time until the lap ended or failed
    distance_m: float  # progress along the centre line when it ended
    track_length_m: float
    max_cross_track_m: float
    mean_cross_track_m: float
    energy_j: float
    calibration_min_us: tuple[int, ...]
    calibration_max_us: tuple[int, ...]
    parameters: dict
    trace: LapTrace | None = None

    def summary(self) -> dict:
        """The JSON-ready fields (no trace)."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "trace"}
        out["calibration_min_us"], out["calibration_max_us"] = list(self.calibration_min_us), list(self.calibration_max_us)
        return out


def earliest(events, n: int) -> tuple[int, tuple[Outcome, str] | None]:
    """The first of ``n`` ticks at which one of ``events`` [(mask (n,), outcome, detail)] happens, and which: the
    earliest event wins, ties go to the one listed first; (n, None) if none happens."""
    end, why = n, None
    for mask, code, detail in events:
        hit = np.flatnonzero(mask)
        if len(hit) and hit[0] < end:
            end, why = int(hit[0]), (code, detail)
    return end, why


def event_details(lim: LapLimits) -> dict[str, str]:
    """What each event that ends a lap says, by event (an off-track lap says which of its two events ended it)."""
    return {"diverged": "the physics produced a non-finite pose",
            "off_track": f"more than {lim.max_cross_track_m * 100:g} cm from the line",
            "cut_across": "cut across to another part of the track",
            "line_lost": f"line not seen for {lim.max_line_lost_s:g} s",
            "wrong_way": f"turned round: {lim.max_backtrack_m * 100:g} cm behind the furthest it had gone",
            "completed": "lap completed",
            "timeout": f"no lap after {lim.timeout_s:g} s"}


class LapJudge:
    """Follows one simulation's trace chunk by chunk and decides when and how its lap ends."""

    def __init__(self, track: Track, limits: LapLimits, keep_trace: bool = True, line_loss: bool = True):
        """``line_loss``: judge ``line_lost`` from the trace's ``line_seen`` (the twin's own firmware's belief); off
        for a controller whose belief the twin cannot read (a controller FMU), which is judged by the geometry
        alone, as a 3pi program is (its board reports the line always seen)."""
        self.track, self.limits, self.keep_trace, self.line_loss = track, limits, keep_trace, line_loss
        self.u_last: float | None = None  # unwrapped progress at the last tick
        self.u_max = -np.inf  # the furthest unwrapped progress so far
        self.s_last = 0.0
        self.prev = (0.0, 0.0, 0.0)  # time, progress and energy at the last tick
        self.t_seen = 0.0  # last time the line was seen
        self.n = 0
        self.abs_sum = 0.0
        self.abs_max = 0.0
        self.chunks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.outcome: tuple[Outcome, str, float, float, float] | None = None  # failure, detail, time, progress, energy

    @property
    def done(self) -> bool:
        return self.outcome is not None

    def feed(self, rec: np.ndarray) -> None:
        """Take the next ticks: records (k, RECORD_WORDS) with the C loop's progress and offset columns."""
        if self.done or len(rec) == 0:
            return
        s, offset = rec[:, COL["progress_m"]], rec[:, COL["offset_m"]]
        length = self.track.length_m
        t = rec[:, COL["time_s"]]
        if self.u_last is None:  # the first tick: the start line, wherever 0 wraps
            self.s_last = float(s[0])
            self.u_last = float(s[0] if s[0] < length / 2 else s[0] - length)
            self.prev = (float(t[0]), self.u_last, float(rec[0, COL["energy_j"]]))
            self.u_max = self.u_last
        du = np.diff(np.concatenate([[self.s_last], s]))
        du = np.mod(du + length / 2, length) - length / 2
        # summed record by record from the last tick's progress (accumulate is sequential), as the C judge sums it:
        # the progress, and so a completed lap's time, does not depend on how the trace was chunked
        u = np.cumsum(np.concatenate([[self.u_last], du]))[1:]
        # the furthest before each record (the C judge's u_max: a record that falls behind it is not a new furthest)
        u_max = np.maximum.accumulate(np.concatenate([[self.u_max], u]))
        seen = rec[:, COL["line_seen"]] > 0 if self.line_loss else np.ones(len(rec), bool)
        last_seen = np.maximum.accumulate(np.where(seen, t, -np.inf))
        last_seen = np.maximum(last_seen, self.t_seen)
        lim = self.limits
        finite = np.isfinite(rec[:, COL["x_m"]]) & np.isfinite(rec[:, COL["y_m"]])
        say = event_details(lim)
        events = [  # in the order lap_judge.c tests them: at one record, the first listed wins
            (~finite, Outcome.DIVERGED, say["diverged"]),
            (np.abs(offset) > lim.max_cross_track_m, Outcome.OFF_TRACK, say["off_track"]),
            (np.abs(du) > lim.max_progress_jump_m, Outcome.OFF_TRACK, say["cut_across"]),
            (t - last_seen > lim.max_line_lost_s, Outcome.LINE_LOST, say["line_lost"]),
            (u < u_max[:-1] - lim.max_backtrack_m, Outcome.WRONG_WAY, say["wrong_way"]),
            (u >= length, Outcome.COMPLETED, say["completed"]),
            (t > lim.timeout_s, Outcome.TIMEOUT, say["timeout"]),
        ]
        end, why = earliest(events, len(rec))
        keep = slice(0, end + 1 if why else end)
        self._account(rec[keep], u[keep], offset[keep])
        prev = self.prev if end == 0 else (float(t[end - 1]), float(u[end - 1]), float(rec[end - 1, COL["energy_j"]]))
        self.u_last, self.s_last, self.t_seen = float(u[-1]), float(s[-1]), float(last_seen[-1])
        self.u_max = float(u_max[-1])
        self.prev = (float(t[-1]), float(u[-1]), float(rec[-1, COL["energy_j"]]))
        if why is None:
            return
        code, detail = why
        t_end, u_end, energy = float(t[end]), float(u[end]), float(rec[end, COL["energy_j"]])
        if code == Outcome.COMPLETED and u_end > prev[1]:
            f = (length - prev[1]) / (u_end - prev[1])  # interpolate the crossing between two ticks
            t_end = prev[0] + f * (t_end - prev[0])
            energy = prev[2] + f * (energy - prev[2])
            u_end = length
        self.outcome = (code, detail, t_end, u_end, energy)

    def _account(self, rec: np.ndarray, u: np.ndarray, offset: np.ndarray) -> None:
        if len(rec) == 0:
            return
        # running sums from the C loop, so the statistics do not depend on how the trace was chunked
        self.n += len(rec)
        self.abs_sum = float(rec[-1, COL["offset_abs_sum_m"]])
        self.abs_max = float(rec[-1, COL["offset_abs_max_m"]])
        if self.keep_trace:
            self.chunks.append((rec.copy(), u.copy(), offset.copy()))

    def fail(self, code: Outcome, detail: str, t: float, energy: float) -> None:
        """End the lap from outside the trace (a MuJoCo error, a failed calibration)."""
        if not self.done:
            self.outcome = (code, detail, t, self.u_last or 0.0, energy)

    def result(self, count: int, cal_min, cal_max, parameters: dict) -> LapResult:
        return judged(self, self.track.length_m, count, cal_min, cal_max, parameters)


class CJudgeView:
    """A lap judged by the C loop alone (``lap_judge.c``, fed every record by the control callback), read from the
    simulation's head: what :class:`LapJudge` decides from the same records, bit for bit (tests/test_lap_judge_c.py),
    with no trace drained into Python between chunks. For laps whose trace is not kept.

    ``head()`` gives the simulation's current :class:`twin.core.native.Sim` (rewritten when the batch resets), or
    None before it has one; ``record(k)`` gives its k-th record of the phase (still in the trace ring: the lap stops
    at the record that ends it). A failure from outside the trace (``fail``) is kept here."""

    keep_trace = False
    chunks: tuple = ()

    def __init__(self, head, record, limits: LapLimits, length_m: float):
        self.head, self.record, self.limits, self.length_m = head, record, limits, length_m
        self.external: tuple | None = None

    @property
    def _c(self):
        head = self.head()
        return head.judge if head is not None else _UNSTARTED  # before the batch has its heads

    @property
    def done(self) -> bool:
        return self.external is not None or self._c.status != 0

    @property
    def prev(self) -> tuple[float, float, float]:
        """Time, progress and energy at the last record before the end (as LapJudge's while the lap runs)."""
        c = self._c
        return c.prev_t, c.prev_u, c.prev_energy

    @property
    def u_last(self) -> float | None:
        c = self._c
        return c.u_last if c.started else None

    @property
    def n(self) -> int:
        return int(self._c.records)

    @property
    def abs_sum(self) -> float:
        return self._c.abs_sum

    @property
    def abs_max(self) -> float:
        return self._c.abs_max

    def feed(self, rec: np.ndarray) -> None:
        """Nothing to do: the C judge has seen every record."""

    def fail(self, code: Outcome, detail: str, t: float, energy: float) -> None:
        if not self.done:
            self.external = (code, detail, t, self.u_last or 0.0, energy)

    @property
    def outcome(self) -> tuple[Outcome, str, float, float, float] | None:
        if self.external is not None:
            return self.external
        c = self._c
        if c.status == 0:
            return None
        code = Outcome(LAP_STATUS[c.status])
        say = event_details(self.limits)
        event = code.value
        if code == Outcome.OFF_TRACK:  # the record that ended it says which: cross-track is tested first
            last = self.record(int(c.records) - 1)
            event = "off_track" if abs(last[COL["offset_m"]]) > self.limits.max_cross_track_m else "cut_across"
        return code, say.get(event, event.replace("_", " ")), c.end_t, c.end_u, c.end_energy

    def result(self, count: int, cal_min, cal_max, parameters: dict) -> LapResult:
        return judged(self, self.length_m, count, cal_min, cal_max, parameters)


def judged(judge, length_m: float, count: int, cal_min, cal_max, parameters: dict) -> LapResult:
    """The result of a judge that has ended (``outcome``: code, detail, time, distance, energy; running ``n``,
    ``abs_sum``, ``abs_max`` of the cross-track error; the kept trace ``chunks``)."""
    if judge.outcome is None:
        raise TwinError("lap judge: the lap has not ended")
    code, detail, t_end, distance, energy = judge.outcome
    trace = None
    if judge.keep_trace and judge.chunks:
        rec, u, off = (np.concatenate(x) for x in zip(*judge.chunks))
        trace = LapTrace(rec, u, off, count)
    completed = code == Outcome.COMPLETED
    return LapResult(  # failure: the plain string, as JSON and every reader of a result take it
        completed=completed, failure=None if completed else Outcome(code).value, detail=detail,
        lap_time_s=t_end if completed else None, simulated_s=t_end, distance_m=max(0.0, distance),
        track_length_m=length_m, max_cross_track_m=judge.abs_max,
        mean_cross_track_m=judge.abs_sum / judge.n if judge.n else 0.0, energy_j=energy,
        calibration_min_us=tuple(int(v) for v in cal_min), calibration_max_us=tuple(int(v) for v in cal_max),
        parameters=parameters, trace=trace,
    )
