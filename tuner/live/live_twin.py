"""The twin beside the robot (paper §3.8, §4.2): compare each lap of its telemetry with the twin's prediction, and
re-align the twin when they keep disagreeing. Reading the link, logging and locking are :mod:`twin.link.reader`'s;
laps are assembled and judged for plausibility by :class:`twin.telemetry.laps.LapAssembler` (an implausible lap is
reported, log warning and ``--json``, and counted, never used for re-alignment).

* A completed lap is compared with the twin's lap under its current parameters: lap time and line position.
  When the lap time differs by more than ``threshold`` for ``k_laps`` laps in a row, the aligner
  (:func:`tuner.align.lap_time.align_lap_time`, every range that explains it) runs in a background thread on its own
  copy of the twin, on the mean of those laps; its result is applied, logged with the reason, and saved.
* The state file (:mod:`tuner.live.state`) holds the aligned value and the alignments. A restart replays the log
  (:func:`tuner.live.replay.resume`) and reloads the state.
* With an :class:`tuner.live.act.Actor` (``live --act``) the twin also acts: alignment then runs in the calling
  thread (the caller feeds it from a thread of its own, :class:`tuner.live.worker.Worker`, so the link is read
  on), then the actor decides whether to re-tune, and after every lap it sends one command. The twin's gains
  follow the robot's: each lap is predicted with the gains its header says were in force.
* ``on_record`` receives what is worth keeping (each lap, both sides; each alignment), for the journal beside the
  log and the history database.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import threading
import time
from typing import Callable

import numpy as np

from tuner.align.lap_time import align_lap_time
from tuner.history import first_failure, trend_of
from tuner.live.act import Actor
from tuner.live.state import read_state, write_state
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapLimits
from twin.telemetry.laps import LapAssembler, RobotLap
from twin.telemetry.wire import GAIN_ADDRESSES, Boot, Header, Reply

log = logging.getLogger(__name__)



@dataclasses.dataclass(frozen=True)
class LiveOptions:
    address: str = "motion.mu"  # what re-alignment adjusts
    bounds: tuple[float, float] | None = None  # None: the aligner's default range for the address
    threshold: float = 0.005  # relative lap-time discrepancy that counts as disagreeing
    k_laps: int = 2  # laps in a row above the threshold before re-aligning
    seed: int = 0


class LiveTwin:
    """The decisions of live mode, independent of where the lines come from."""

    def __init__(self, twin: DigitalTwin, options: LiveOptions, state_path: str | None = None,
                 on_lap: Callable[[dict], None] | None = None, actor: Actor | None = None,
                 on_record: Callable[[dict], None] | None = None):
        self.twin, self.o, self.state_path, self.on_lap = twin, options, state_path, on_lap
        self.actor, self.on_record = actor, on_record
        twin.model()
        self.assembler = LapAssembler(twin.track.length_m, LapLimits().timeout_s)
        self.laps: list[dict] = []
        self.alignments: list[dict] = []
        self.streak = 0
        self._thread: threading.Thread | None = None
        self._result: dict | None = None
        self._prediction: tuple[float, object] | None = None
        self.rebuild_from_log = False  # a damaged state was copied aside: replay the log with re-alignment
        if state_path:
            existed = os.path.lexists(state_path)
            state = read_state(state_path, twin)
            if state is None:
                self.rebuild_from_log = existed
            else:
                twin.update(state["values"])
                self.alignments = state["alignments"]
                log.info("resumed state from %s: %s", state_path, state["values"])

    def prediction(self):
        """The twin's lap under its current parameters and gains (cached until they change)."""
        key = (self.twin.space.get(self.o.address), tuple(self.twin.space.get(a) for a in GAIN_ADDRESSES))
        if self._prediction is None or self._prediction[0] != key:
            self._prediction = (key, run_laps(self.twin, [{}], seed=self.o.seed)[0])
        return self._prediction[1]

    def feed(self, rec, replay: bool = False, arrival: float | None = None) -> None:
        """One record from the robot (None: nothing came for a while); ``arrival``: when it came
        (``time.monotonic``; default now), against which the actor judges its answer deadlines."""
        self._apply_alignment()
        arrival = time.monotonic() if arrival is None else arrival
        if self.actor is not None:
            self.actor.live = not replay
            self.actor.idle(arrival)
        if rec is None:
            return
        if self.actor is not None and isinstance(rec, (Header, Boot, Reply)):
            self.actor.on_record(rec, arrival)
        lap = self.assembler.feed(rec)
        if lap is not None:
            self._lap(lap, replay)

    def _lap(self, lap: RobotLap, replay: bool) -> None:
        twin_lap = self.prediction()
        entry = {"lap": lap.index, "robot_lap_time_s": lap.lap_time_s, "twin_lap_time_s": twin_lap.lap_time_s,
                 self.o.address: self.twin.space.get(self.o.address), "replayed": replay, "implausible": lap.implausible,
                 "robot": lap.robot, "gains_seq": lap.gains_seq,
                 "gains": {a: self.twin.space.get(a) for a in GAIN_ADDRESSES}}
        if lap.implausible:  # reported, never acted on (a replayed one was reported when it arrived)
            log.log(logging.INFO if replay else logging.WARNING, "lap %d ignored: %s", lap.index, lap.implausible)
            entry["discrepancy"] = None
            self._record(entry, lap, twin_lap, replay)
            if self.actor is not None:
                self.actor.end_of_lap()
            return
        if lap.lap_time_s is not None and twin_lap.completed:
            entry["discrepancy"] = (lap.lap_time_s - twin_lap.lap_time_s) / twin_lap.lap_time_s
            tr = twin_lap.trace
            if len(lap.t):
                entry["position_rms"] = float(np.sqrt(np.mean(
                    (np.interp(lap.t, tr.time_s, tr.column("position")) - lap.pos) ** 2)))
        else:
            entry["discrepancy"] = None  # one of them failed: that alone is a disagreement
        off = entry["discrepancy"] is None or abs(entry["discrepancy"]) > self.o.threshold
        self.streak = self.streak + 1 if off else 0
        self._record(entry, lap, twin_lap, replay)
        if self.actor is not None:
            self.actor.observe(entry, self.laps)
            if self.actor.busy():
                self.streak = 0  # a change is being confirmed: its laps are the actor's to judge
        if not replay and self.streak >= self.o.k_laps and self._thread is None:
            measured = [e for e in self.laps[-self.o.k_laps:] if e["robot_lap_time_s"]]
            if measured:
                self._start_alignment(float(np.mean([e["robot_lap_time_s"] for e in measured])), entry,
                                      (measured[0]["lap"], measured[-1]["lap"]))
            elif self.actor is not None:  # every lap failed: no lap time to align on, but failures say much
                self._apply_alignment(result=self._from_failures())
        if self.actor is not None:
            self.actor.end_of_lap()

    def _from_failures(self) -> dict:
        """When the robot's last laps all failed with gains the twin finishes with: where it is now along the
        trend of its alignments, else the most the parameter can be (the value where the twin's laps with these
        gains first fail, raced downward from the twin's value: the robot's must lie beyond it). An estimate, not
        a measurement: it moves the twin (so that acting can re-tune) but is marked ``from_failures`` and claims
        no interval, and no trend or forecast takes it as evidence (:func:`tuner.history.trend.measured`)."""
        address, value = self.o.address, self.twin.space.get(self.o.address)
        t = trend_of(self.alignments, address)
        failed = self.laps[-self.streak:] if self.streak else self.laps[-1:]
        laps = (failed[0]["lap"], failed[-1]["lap"])
        reason = f"the robot's last {self.streak} laps failed, the twin's finish at {address} = {value:.4g}"
        if t is not None and (t.at(laps[1]) - value) * t.slope > 0:
            est = t.at(laps[1])
            how = f"its trend ({t.slope:+.3g} per lap) puts it at {est:.4g} now"
        else:
            p = self.twin.space.parameter(address)
            gains = {a: self.twin.space.get(a) for a in GAIN_ADDRESSES}
            end = max(p.lower, value * 0.5) if (t is None or t.slope <= 0) else min(p.upper, value * 1.5)
            est, _, _ = first_failure(self.twin, gains, address, value, end, 1, self.o.seed, self._limits())
            if est is None:
                return {"explained": False, "value": None, "reason": reason, "before": value, "laps": laps,
                        "from_failures": True, "message": f"the twin's laps with these gains finish from {value:.4g} to {end:.4g}: the "
                                   "failures are not explained by it"}
            how = f"the twin's laps with these gains first fail at {est:.4g}"
        return {"explained": True, "value": est, "reason": reason, "before": value, "measured_lap_time_s": None,
                "message": f"{address} estimated from failed laps: {how}", "from_failures": True,
                "interval": None, "identifiable": False, "laps": laps}

    def _limits(self) -> LapLimits:
        """Laps of the twin's own searches end as failures at twice the robot's lap (not at 60 s)."""
        done = [e["robot_lap_time_s"] for e in self.laps if e["robot_lap_time_s"]]
        return LapLimits(timeout_s=2 * float(np.median(done[-10:]))) if done else LapLimits()

    def _record(self, entry: dict, lap: RobotLap, twin_lap, replay: bool) -> None:
        self.laps.append(entry)
        if self.on_lap:
            self.on_lap({**entry, "lap_record": lap, "twin_lap": twin_lap})
        if self.on_record and not replay:
            self.on_record({"kind": "lap", **entry, "lap_record": lap, "twin_lap": twin_lap})

    def _start_alignment(self, measured: float, why: dict, laps: tuple[int, int]) -> None:
        """Align on ``measured`` [s], the mean lap time of the robot's laps ``laps`` (first, last)."""
        values = dict(self.twin.space.values)
        twin_s = "failed" if why["twin_lap_time_s"] is None else f"{why['twin_lap_time_s']:.3f} s"
        reason = (f"robot laps {measured:.3f} s (mean of the completed of {self.o.k_laps}) against the twin's "
                  f"{twin_s} for {self.streak} laps")
        log.info("re-aligning %s: %s", self.o.address, reason)
        other = self.twin.clone() if self.actor is None else self.twin  # acting: this thread, this twin

        def work():
            try:
                r = align_lap_time(other, measured, self.o.address, bounds=self.o.bounds, seed=self.o.seed,
                                   limits=LapLimits(timeout_s=max(2 * measured, measured + 10)),
                                   interval=False)  # beside the robot: its consistent range, not 55-165 laps more
                interval = getattr(r, "consistent", None)
                self._result = {"explained": r.explained, "value": r.value, "message": r.message, "reason": reason,
                                "measured_lap_time_s": measured, "before": values[self.o.address], "laps": laps,
                                "interval": list(interval) if interval else None,
                                "identifiable": getattr(r, "identifiable", None)}
            except Exception as e:  # the live loop goes on; the failure is reported, not raised here
                self._result = {"explained": False, "value": None, "message": f"alignment failed: {e}", "reason": reason,
                                "laps": laps}

        if self.actor is not None:
            work()  # acting decides in order: the alignment, then what to do with it, before the next lap
            self._apply_alignment(result=self._result)
            return
        self._thread = threading.Thread(target=work, name="align", daemon=True)
        self._thread.start()

    def _apply_alignment(self, wait: bool = False, result: dict | None = None) -> None:
        if result is None:
            if self._thread is None or (self._thread.is_alive() and not wait):
                return
            self._thread.join()
            result, self._thread = self._result, None
        r, self._result = result, None
        first, last = r.pop("laps", None) or (len(self.laps) - 1, len(self.laps) - 1)
        r["first_lap"], r["lap"] = first, last  # the laps it measured, not when its result arrived
        r["time"] = time.time()
        r["address"] = self.o.address
        r["robot"] = self.assembler.header.robot if self.assembler.header else None
        if r["explained"] and r["value"] is not None:
            self.twin.set(self.o.address, r["value"])
            log.info("aligned %s: %.5g → %.5g (%s)", self.o.address, r["before"], r["value"], r["reason"])
        else:
            log.warning("alignment did not explain the robot: %s", r["message"])
        self.alignments.append(r)
        self.streak = 0
        self.save_state()
        if self.on_record:
            self.on_record({"kind": "alignment", **r})
        if self.actor is not None:
            slope = trend_of(self.alignments, self.o.address)
            self.actor.consider(r, len(self.laps), self._limits().timeout_s / 2, slope.slope if slope else None)

    def finish(self) -> None:
        """Wait for a running alignment and apply it."""
        self._apply_alignment(wait=True)

    def save_state(self) -> None:
        if self.state_path:
            write_state(self.state_path, {self.o.address: self.twin.space.get(self.o.address)}, self.alignments)
