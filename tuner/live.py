"""The twin beside the robot (paper §3.8, §4.2): compare each lap of its telemetry with the twin's prediction, and
re-align the twin when they keep disagreeing. Reading the link, logging and locking are :mod:`twin.link`'s.

* Each lap is judged before it counts (:class:`LapAssembler`): sample times must increase and the LAP come no
  earlier than its last sample (less ``SPAN_TOLERANCE_S``), positions lie within the header's sensor range
  (0 … (sensors − 1)·1000), the LAP's lap time agree with its START→LAP span (within ``SPAN_TOLERANCE_S`` +
  ``SPAN_TOLERANCE_REL`` of it: 0.05 s + 1 %, for firmware clocks and millisecond rounding), and the lap time be
  one a robot can drive on this track (no faster than ``MAX_SPEED_MPS`` = 5 m/s on average, no longer than the
  twin's lap timeout, 60 s). An implausible lap is reported (log warning, ``--json``) and counted, never used
  for re-alignment.
* A completed lap is compared with the twin's lap under its current parameters: lap time and line position.
  When the lap time differs by more than ``threshold`` for ``k_laps`` laps in a row, the aligner
  (:func:`tuner.align.align_lap_time`, every range that explains it) runs in a background thread on its own
  copy of the twin, on the mean of those laps; its result is applied, logged with the reason, and saved.
* The state file (``"generator"`` JSON, written atomically) holds the aligned value and the alignments. A restart
  replays the log (:func:`resume`) and reloads the state; a state file that is unreadable, of the wrong shape, or
  not written by this program is set aside (renamed ``<state>.corrupt-<time>``, never deleted) with a warning and
  rebuilt by replaying the log with re-alignment.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import threading
import time
from typing import Callable

import numpy as np

from lf_common.errors import LineFollowerError
from lf_common.files import GENERATOR, check_output_file, parse_json, read_text, write_json
from tuner.align import align_lap_time
from twin.closed_loop import run_laps
from twin.digital_twin import DigitalTwin
from twin.lap import LapLimits
from twin.errors import TwinError
from twin.link import LinkStats
from twin.wire import Event, Header, LineSplitter, Sample, WireError, decode

log = logging.getLogger(__name__)


@dataclasses.dataclass
class RobotLap:
    index: int
    lap_time_s: float | None  # None: the robot reported a failure
    t: np.ndarray  # sample times since the lap's start [s]
    pos: np.ndarray
    wl: np.ndarray
    wr: np.ndarray
    implausible: str | None = None  # why this lap cannot be what a robot on this track did


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
        self.start: float | None = None
        self.rows: list[tuple[float, float, float, float]] = []
        self.problem: str | None = None  # the first implausibility seen in the current lap
        self.count = 0

    def feed(self, rec) -> RobotLap | None:
        if isinstance(rec, Header):
            self.sensors = rec.sensors
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
            lap = RobotLap(self.count, rec.lap_time_s, a[:, 0], a[:, 1], a[:, 2], a[:, 3], problem)
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


@dataclasses.dataclass(frozen=True)
class LiveOptions:
    address: str = "motion.mu"  # what re-alignment adjusts
    bounds: tuple[float, float] | None = (0.15, 2.0)
    threshold: float = 0.005  # relative lap-time discrepancy that counts as disagreeing
    k_laps: int = 2  # laps in a row above the threshold before re-aligning
    seed: int = 0


class LiveTwin:
    """The decisions of live mode, independent of where the lines come from."""

    def __init__(self, twin: DigitalTwin, options: LiveOptions, state_path: str | None = None,
                 on_lap: Callable[[dict], None] | None = None):
        self.twin, self.o, self.state_path, self.on_lap = twin, options, state_path, on_lap
        twin.model()
        self.assembler = LapAssembler(twin.track.length_m, LapLimits().timeout_s)
        self.laps: list[dict] = []
        self.alignments: list[dict] = []
        self.streak = 0
        self._thread: threading.Thread | None = None
        self._result: dict | None = None
        self._prediction: tuple[float, object] | None = None
        self.rebuild_from_log = False  # a corrupt state was set aside: replay the log with re-alignment
        if state_path:
            existed = os.path.lexists(state_path)
            state = _read_state(state_path, twin)
            if state is None:
                self.rebuild_from_log = existed
            else:
                twin.update(state["values"])
                self.alignments = state["alignments"]
                log.info("resumed state from %s: %s", state_path, state["values"])

    def prediction(self):
        """The twin's lap under its current parameters (cached until they change)."""
        v = self.twin.space.get(self.o.address)
        if self._prediction is None or self._prediction[0] != v:
            self._prediction = (v, run_laps(self.twin, [{}], seed=self.o.seed)[0])
        return self._prediction[1]

    def feed(self, rec, replay: bool = False) -> None:
        self._apply_alignment()
        if rec is None:
            return
        lap = self.assembler.feed(rec)
        if lap is not None:
            self._lap(lap, replay)

    def _lap(self, lap: RobotLap, replay: bool) -> None:
        twin_lap = self.prediction()
        entry = {"lap": lap.index, "robot_lap_time_s": lap.lap_time_s, "twin_lap_time_s": twin_lap.lap_time_s,
                 self.o.address: self.twin.space.get(self.o.address), "replayed": replay, "implausible": lap.implausible}
        if lap.implausible:  # reported, never acted on (a replayed one was reported when it arrived)
            log.log(logging.INFO if replay else logging.WARNING, "lap %d ignored: %s", lap.index, lap.implausible)
            entry["discrepancy"] = None
            self.laps.append(entry)
            if self.on_lap:
                self.on_lap({**entry, "lap_record": lap, "twin_lap": twin_lap})
            return
        if lap.lap_time_s is not None and twin_lap.completed:
            entry["discrepancy"] = (lap.lap_time_s - twin_lap.lap_time_s) / twin_lap.lap_time_s
            tr = twin_lap.trace
            if len(lap.t):
                entry["position_rms"] = float(np.sqrt(np.mean(
                    (np.interp(lap.t, tr.time_s, tr.column("position")) - lap.pos) ** 2)))
        else:
            entry["discrepancy"] = None  # one of them failed: that alone is a disagreement
        self.laps.append(entry)
        off = entry["discrepancy"] is None or abs(entry["discrepancy"]) > self.o.threshold
        self.streak = self.streak + 1 if off else 0
        if self.on_lap:
            self.on_lap({**entry, "lap_record": lap, "twin_lap": twin_lap})
        if not replay and self.streak >= self.o.k_laps and self._thread is None:
            recent = [e["robot_lap_time_s"] for e in self.laps[-self.o.k_laps:] if e["robot_lap_time_s"]]
            if recent:
                self._start_alignment(float(np.mean(recent)), entry)

    def _start_alignment(self, measured: float, why: dict) -> None:
        values = dict(self.twin.space.values)
        other = self.twin.clone()  # built in the background thread, never shared with the live loop
        reason = (f"robot laps {measured:.3f} s (mean of {self.o.k_laps}) against the twin's "
                  f"{why['twin_lap_time_s']:.3f} s for {self.streak} laps")
        log.info("re-aligning %s: %s", self.o.address, reason)

        def work():
            try:
                r = align_lap_time(other, measured, self.o.address, bounds=self.o.bounds, seed=self.o.seed)
                self._result = {"explained": r.explained, "value": r.value, "message": r.message, "reason": reason,
                                "measured_lap_time_s": measured, "before": values[self.o.address]}
            except Exception as e:  # the live loop goes on; the failure is reported, not raised here
                self._result = {"explained": False, "value": None, "message": f"alignment failed: {e}", "reason": reason}

        self._thread = threading.Thread(target=work, name="align", daemon=True)
        self._thread.start()

    def _apply_alignment(self, wait: bool = False) -> None:
        if self._thread is None or (self._thread.is_alive() and not wait):
            return
        self._thread.join()
        r, self._thread, self._result = self._result, None, None
        r["lap"] = len(self.laps)
        r["time"] = time.time()
        if r["explained"] and r["value"] is not None:
            self.twin.set(self.o.address, r["value"])
            log.info("aligned %s: %.5g → %.5g (%s)", self.o.address, r["before"], r["value"], r["reason"])
        else:
            log.warning("alignment did not explain the robot: %s", r["message"])
        self.alignments.append(r)
        self.streak = 0
        self.save_state()

    def finish(self) -> None:
        """Wait for a running alignment and apply it."""
        self._apply_alignment(wait=True)

    def save_state(self) -> None:
        if self.state_path:
            write_json(self.state_path, {"values": {self.o.address: self.twin.space.get(self.o.address)},
                                         "alignments": self.alignments}, "live state file")


STATE = "live state file"
STATE_LIMIT = 16 * 2**20  # [bytes]; a state of a thousand alignments is under 1 MB


class _Corrupt(Exception):
    """The state file cannot be what this program wrote."""


def _read_state(path: str, twin: DigitalTwin) -> dict | None:
    """The state file's values and alignments; None if there is none, or after setting a corrupt one aside
    (renamed, never deleted) with a warning. A folder, link or device there, or a folder that cannot be
    written, is refused at once (:class:`OutputError`): it would fail at the first save."""
    check_output_file(path, lambda _: True, STATE)
    if not os.path.exists(path):
        return None
    try:
        return _parse_state(path, twin)
    except _Corrupt as e:
        aside = _set_aside(path)
        log.warning("%s: %s; set aside as %s, rebuilding the state from the log", path, e, aside)
        return None


def _parse_state(path: str, twin: DigitalTwin) -> dict:
    try:
        state = parse_json(read_text(path, STATE_LIMIT, STATE), path)
    except LineFollowerError as e:
        raise _Corrupt(str(e).removeprefix(f"{path}: ")) from None
    if not isinstance(state, dict) or state.get("generator") != GENERATOR:
        raise _Corrupt(f"not a state file written by {GENERATOR}")
    values, alignments = state.get("values"), state.get("alignments")
    if not (isinstance(values, dict) and isinstance(alignments, list) and all(isinstance(a, dict) for a in alignments)
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values.values())):
        raise _Corrupt('wrong shape (expected "values": {address: number}, "alignments": [{…}])')
    try:
        twin.checked_values(values)  # known addresses, finite, within range
    except TwinError as e:
        raise _Corrupt(str(e)) from None
    return {"values": values, "alignments": alignments}


def _set_aside(path: str) -> str:
    stem = f"{path}.corrupt-{time.strftime('%Y%m%dT%H%M%S')}"
    aside, n = stem, 1
    while os.path.lexists(aside):  # never over an earlier one
        aside, n = f"{stem}.{n}", n + 1
    os.rename(path, aside)
    return aside


def replay_log(path: str, live: LiveTwin, stats: LinkStats, realign: bool = False) -> None:
    """Feed a telemetry log (wire lines) through live mode: without re-aligning to resume after a restart,
    or with it to replay a recorded session as if it were live. Read in chunks: a line of any length costs
    no more memory than a chunk."""
    lines = LineSplitter()
    with open(path, "rb") as f:
        while chunk := f.read(1 << 16):
            for raw in lines.feed(chunk):
                _replay_line(raw, live, stats, realign)
    if lines.cut():
        _replay_line(None, live, stats, realign)


def _replay_line(raw: bytes | None, live: LiveTwin, stats: LinkStats, realign: bool) -> None:
    stats.lines += 1
    if raw is None:  # longer than any wire line, or cut off
        stats.corrupted += 1
        return
    # as fast as the file goes, each lap waits for the alignment the previous ones asked for
    feed_line(raw, live, stats, replay=not realign, before_lap=live.finish if realign else None)


def feed_line(raw: bytes, live: LiveTwin, stats: LinkStats, replay: bool = False,
              before_lap: Callable[[], None] | None = None) -> bool:
    """One received wire line → the live twin (a corrupted one only counted); True for a lap event (LAP, FAIL).
    ``before_lap`` runs just before a lap event is fed."""
    try:
        rec = decode(raw)
    except WireError:
        stats.corrupted += 1
        return False
    lap_event = isinstance(rec, Event) and rec.event in ("LAP", "FAIL")
    if lap_event:
        stats.robot_laps += 1
        if before_lap is not None:
            before_lap()
    live.feed(rec, replay=replay)
    return lap_event


def resume(live: LiveTwin, log_path: str) -> int:
    """Replay the laps already in the log (after a restart); with a state that was set aside, re-align on them
    to rebuild it. Returns how many laps the log held."""
    if not os.path.exists(log_path) or os.path.getsize(log_path) == 0:
        return 0
    replay_log(log_path, live, LinkStats(), realign=live.rebuild_from_log)
    live.finish()
    if live.rebuild_from_log:
        live.save_state()
        live.rebuild_from_log = False
    return len(live.laps)
