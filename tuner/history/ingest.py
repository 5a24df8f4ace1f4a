"""Rows from a telemetry log and the journal beside it (:mod:`tuner.history.journal`): one code path for the live
twin writing as it goes and for ``history --rebuild`` reading the files back, so the two give the same rows.

The robot's side of every lap comes from the log (lap time, completed or why not, the gains' sequence number, the
line position, whence the cross-track error: the line's offset from the array's centre, in metres by the sensor
pitch the twin had); the twin's side (its prediction, the aligned values, the gains it believed in force) and
everything the twin did come from the journal, each row keyed by its place there under the log's id
(:func:`tuner.history.journal.log_id`), not its path: the same lap from a copy of the log is the same row.
"""

from __future__ import annotations

import os

from tuner.history import schema as s
from tuner.history.store import History
from twin.telemetry.laps import RobotLap, line_offsets_m, line_sides_m

DEFAULT_PITCH_M = 0.009525  # QTR-8's, when the journal does not say
CHANGE_STATUS = {"send": "sent", "ack": "acked", "nak": "nak", "silent": "silent", "in_force": "in_force",
                 "confirm": "confirmed", "rollback": "rolled_back", "superseded": "superseded", "withdraw": "withdrawn"}


def robot_name(robot: str | None, log_path: str) -> str:
    """A robot's name: its wire id, or for a version 1 robot (no id) the log it spoke into."""
    return robot or f"unnamed@{os.path.basename(log_path)}"[:64]


def cross_track(lap: RobotLap, pitch_m: float) -> tuple[float | None, float | None, float | None]:
    """(max |offset|, mean |offset|, mean signed offset) of the line from the array's centre [m], from the lap's line
    positions (the twin reads its own laps the same way: :func:`tuner.history.twin_edge.lap_features`)."""
    if not len(lap.pos):
        return None, None, None
    offset = line_offsets_m(lap.pos, lap.sensors, pitch_m)
    return float(offset.max()), float(offset.mean()), float(line_sides_m(lap.pos, lap.sensors, pitch_m).mean())


def log_key(log_id: str) -> str:
    """What every row key of a log starts with (``<key>#…``)."""
    return f"log:{log_id}"


class LogIngest:
    """The rows of one telemetry log (``log_path``, known by ``log_id``) and its journal, written through
    ``history`` on a connection per call."""

    def __init__(self, history: History, log_path: str, log_id: str):
        self.h, self.log, self.key = history, os.path.abspath(log_path), log_key(log_id)
        self.session_key, self.session_lap, self.settings = f"{self.key}#log", 0, {}
        self.runs: dict[tuple[str, str], int] = {}
        self.pitch = DEFAULT_PITCH_M
        self.robot: str | None = None  # the robot last heard from: what a record without one is about

    def _run(self, c, robot: str | None, when: float | None) -> tuple[int, int]:
        """(run id, robot id) of the current session with this robot (default: the robot last heard from)."""
        self.robot = robot = robot or self.robot
        name = robot_name(robot, self.log)
        robot_id = History.robot(c, name, "robot", when)
        key = (self.session_key, name)
        if key not in self.runs:
            self.runs[key] = History.put(c, s.runs, f"{self.session_key}:{name}", robot_id=robot_id, command="live",
                                         log_path=self.log, started=self.settings.get("time"),
                                         first_lap=self.session_lap, settings=self.settings or None)
        return self.runs[key], robot_id

    def session(self, record: dict, index: int) -> None:
        """A live session began (a journal ``session`` record at line ``index``)."""
        self.session_key, self.session_lap = f"{self.key}#j{index}", int(record.get("lap") or 0)
        self.settings = {k: v for k, v in record.items() if k != "kind"}
        self.pitch = float(record.get("pitch_m") or DEFAULT_PITCH_M)

    def lap(self, c, lap: RobotLap, twin_side: dict | None) -> None:
        """One robot lap from the log, with the twin's side of it if the journal has it."""
        twin_side = twin_side or {}
        when = twin_side.get("time")
        run_id, robot_id = self._run(c, lap.robot, when)
        xmax, xmean, side = cross_track(lap, self.pitch)
        History.put(c, s.laps, f"{self.key}#lap{lap.index}", run_id=run_id, robot_id=robot_id, lap=lap.index,
                    time=when, completed=lap.lap_time_s is not None, lap_time_s=lap.lap_time_s, failure=lap.failure,
                    implausible=lap.implausible, energy_j=None, xte_max_m=xmax, xte_mean_m=xmean,
                    line_side_m=side, gains_seq=lap.gains_seq, gains=twin_side.get("gains"),
                    twin_lap_time_s=twin_side.get("twin_lap_time_s"), discrepancy=twin_side.get("discrepancy"),
                    values=twin_side.get("value"))

    def alignment(self, c, r: dict, index: int) -> None:
        run_id, robot_id = self._run(c, r.get("robot"), r.get("time"))
        lo, hi = r.get("interval") or (None, None)
        History.put(c, s.alignments, f"{self.key}#j{index}", run_id=run_id, robot_id=robot_id, lap=r.get("lap"),
                    time=r.get("time"), address=r.get("address") or "motion.mu", before=r.get("before"),
                    value=r.get("value"), lo=lo, hi=hi, explained=bool(r.get("explained")),
                    identifiable=r.get("identifiable"), measured_lap_time_s=r.get("measured_lap_time_s"),
                    message=r.get("message"), reason=r.get("reason"), first_lap=r.get("first_lap", r.get("lap")),
                    estimated=bool(r.get("from_failures")))

    def action(self, c, a: dict, index: int) -> None:
        """One action of the live twin: a gain change's step, or another event."""
        run_id, robot_id = self._run(c, a.get("robot"), a.get("time"))
        kind, seq = a["kind"], a.get("seq")
        key = f"{self.key}#change{seq}"
        if kind == "decide":
            History.put(c, s.gain_changes, key, run_id=run_id, robot_id=robot_id, seq=seq, kind=a.get("change"),
                        decided_lap=a.get("decided_lap"), status="decided", gains=a.get("gains"),
                        previous=a.get("previous"), previous_seq=a.get("previous_seq"), reason=a.get("reason"),
                        predicted_lap_time_s=a.get("predicted_lap_time_s"), outcome=a.get("outcome"),
                        decided_at=a.get("time"))
            return
        if "stored" in a and a.get("change") is not None:  # what the robot boots on: apart from what it runs
            c.execute(s.gain_changes.update().where(s.gain_changes.c.source == key).values(stored=a["stored"]))
        if kind in CHANGE_STATUS and a.get("change") is not None:
            values = {"status": CHANGE_STATUS[kind], "outcome": a.get("outcome")}
            if kind == "send":
                values["sent_at"] = a.get("time")
            elif kind in ("ack", "nak", "silent"):
                values["answered_at"] = a.get("time")
                if kind == "nak":
                    values["nak_reason"] = a.get("reason_code")
            elif kind == "in_force":
                values["first_lap"] = a.get("lap")
            c.execute(s.gain_changes.update().where(s.gain_changes.c.source == key).values(**values))
        History.put(c, s.events, f"{self.key}#j{index}", run_id=run_id, robot_id=robot_id, lap=a.get("lap"),
                    time=a.get("time"), kind=kind, seq=seq, outcome=a.get("outcome"),
                    data={k: v for k, v in a.items() if k not in ("kind", "lap", "time", "seq", "outcome", "robot")})

    def journal_record(self, c, r: dict, index: int) -> None:
        """A journal record other than a lap (laps come with their robot side)."""
        kind = r.get("kind")
        if kind == "session":
            self.session(r, index)
        elif kind == "alignment":
            self.alignment(c, r, index)
        elif kind not in ("lap", "command", None):
            self.action(c, r, index)
