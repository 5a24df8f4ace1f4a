"""The twin beside the robot (paper §3.8, §4.2): read its telemetry live, compare each lap with the twin's
prediction, and re-align the twin when they keep disagreeing.

* Every received line (valid or not) is appended to the telemetry log and the log is flushed to disk at every
  lap event, so nothing received is lost if the link or this process dies.
* Corrupted or truncated lines are counted and skipped; a dropped link is reopened with exponential backoff.
* Each completed lap is compared with the twin's lap under its current parameters: lap time, and the line
  position trace. When the lap time differs by more than ``threshold`` for ``k_laps`` laps in a row, the
  aligner (:func:`tuner.align.align_lap_time`) runs in a background thread on its own copy of the twin, on the
  mean of those laps; its result is applied, logged with the reason, and saved in the state file.
* A restart replays the log and reloads the state file, so it resumes where it stopped.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import threading
import time
from typing import Callable

import numpy as np

from tuner.align import align_lap_time
from twin.closed_loop import run_laps
from twin.digital_twin import DigitalTwin
from twin.wire import Event, Header, Sample, WireError, decode

log = logging.getLogger(__name__)


@dataclasses.dataclass
class RobotLap:
    index: int
    lap_time_s: float | None  # None: the robot reported a failure
    t: np.ndarray  # sample times since the lap's start [s]
    pos: np.ndarray
    wl: np.ndarray
    wr: np.ndarray


class LapAssembler:
    """Wire records → completed laps. A lap is the samples between a START and its LAP or FAIL event."""

    def __init__(self):
        self.start: float | None = None
        self.rows: list[tuple[float, float, float, float]] = []
        self.count = 0

    def feed(self, rec) -> RobotLap | None:
        if isinstance(rec, (Header,)):
            return None
        if isinstance(rec, Event) and rec.event == "START":
            self.start, self.rows = rec.t, []
            return None
        if self.start is None:
            return None  # joined mid-lap: wait for the next start
        if isinstance(rec, Sample):
            self.rows.append((rec.t - self.start, rec.pos, rec.wl, rec.wr))
            return None
        if isinstance(rec, Event) and rec.event in ("LAP", "FAIL"):
            a = np.array(self.rows) if self.rows else np.zeros((0, 4))
            lap = RobotLap(self.count, rec.lap_time_s, a[:, 0], a[:, 1], a[:, 2], a[:, 3])
            self.count += 1
            self.start, self.rows = None, []
            return lap
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
        self.assembler = LapAssembler()
        self.laps: list[dict] = []
        self.alignments: list[dict] = []
        self.streak = 0
        self._thread: threading.Thread | None = None
        self._result: dict | None = None
        self._prediction: tuple[float, object] | None = None
        if state_path and os.path.isfile(state_path):
            with open(state_path) as f:
                state = json.load(f)
            twin.update(state.get("values", {}))
            self.alignments = state.get("alignments", [])
            log.info("resumed state from %s: %s", state_path, state.get("values"))

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
                 self.o.address: self.twin.space.get(self.o.address), "replayed": replay}
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
        settings = (self.twin.track_source, self.twin.robot_urdf, self.twin.robot_config, self.twin.track_metres_per_pixel)
        reason = (f"robot laps {measured:.3f} s (mean of {self.o.k_laps}) against the twin's "
                  f"{why['twin_lap_time_s']:.3f} s for {self.streak} laps")
        log.info("re-aligning %s: %s", self.o.address, reason)

        def work():
            try:
                other = DigitalTwin(track=settings[0], robot_urdf=settings[1], robot_config=settings[2],
                                    track_metres_per_pixel=settings[3])
                other.space.values.update(values)
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
            log.warning("aligned %s: %.5g → %.5g (%s)", self.o.address, r["before"], r["value"], r["reason"])
        else:
            log.warning("alignment did not explain the robot: %s", r["message"])
        self.alignments.append(r)
        self.streak = 0
        self.save_state()

    def finish(self) -> None:
        """Wait for a running alignment and apply it."""
        self._apply_alignment(wait=True)

    def save_state(self) -> None:
        if not self.state_path:
            return
        tmp = f"{self.state_path}.{os.getpid()}.tmp"
        with open(tmp, "w") as f:
            json.dump({"values": {self.o.address: self.twin.space.get(self.o.address)}, "alignments": self.alignments}, f,
                      indent=2)
        os.replace(tmp, self.state_path)


@dataclasses.dataclass
class LinkStats:
    lines: int = 0
    corrupted: int = 0
    reconnects: int = 0
    robot_laps: int = 0


def replay_log(path: str, live: LiveTwin, stats: LinkStats, realign: bool = False) -> None:
    """Feed a telemetry log (wire lines) through live mode: without re-aligning to resume after a restart,
    or with it to replay a recorded session as if it were live."""
    with open(path, "rb") as f:
        for raw in f:
            stats.lines += realign
            try:
                rec = decode(raw)
            except WireError:
                stats.corrupted += 1
                continue
            if realign and isinstance(rec, Event) and rec.event in ("LAP", "FAIL"):
                stats.robot_laps += 1
                live.finish()  # as fast as the file goes, each lap sees the alignment the previous ones asked for
            live.feed(rec, replay=not realign)


def run_link(url: str, live: LiveTwin, log_path: str, stats: LinkStats, stop: Callable[[], bool],
             backoff_max_s: float = 2.0, timeout_s: float = 0.2) -> None:
    """Read the link until ``stop()`` says so, logging every line and reopening the link when it drops."""
    import serial

    backoff = 0.05
    with open(log_path, "ab") as logf:
        while not stop():
            try:
                port = serial.serial_for_url(url, baudrate=115200, timeout=timeout_s)
            except (serial.SerialException, OSError, ValueError) as e:
                log.info("link %s not available (%s); retrying in %.2f s", url, e, backoff)
                time.sleep(backoff)
                backoff = min(backoff_max_s, backoff * 2)
                stats.reconnects += 1
                continue
            backoff = 0.05
            try:
                pending = b""
                while not stop():
                    chunk = port.readline()
                    if not chunk:
                        live.feed(None)  # lets a finished alignment apply while the link is quiet
                        continue
                    pending += chunk
                    if not pending.endswith(b"\n"):
                        if len(pending) > 4096:
                            pending = b""
                        continue
                    line, pending = pending, b""
                    logf.write(line)
                    stats.lines += 1
                    try:
                        rec = decode(line)
                    except WireError:
                        stats.corrupted += 1
                        continue
                    if isinstance(rec, Event) and rec.event in ("LAP", "FAIL"):
                        logf.flush()
                        os.fsync(logf.fileno())  # a whole lap is on disk before it is acted on
                        stats.robot_laps += 1
                    live.feed(rec)
            except (serial.SerialException, OSError) as e:
                log.warning("link %s dropped (%s); reopening", url, e)
                stats.reconnects += 1
            finally:
                logf.flush()
                try:
                    port.close()
                except Exception:
                    pass
